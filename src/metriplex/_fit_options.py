"""The option objects of :func:`~metriplex.fit` that group settings belonging together:
:class:`Checkpoint` (where training saves its state, how often, and whether it resumes) and
:class:`LBFGSFinish` (an L-BFGS stage after Adam). Like :class:`~metriplex.train.Plateau` and
:class:`~metriplex.train.RolloutCheck`, each is a frozen dataclass checked when it is made.
"""

from __future__ import annotations

import dataclasses
import os

from ._errors import expect_integer


@dataclasses.dataclass(frozen=True)
class Checkpoint:
    """Where :func:`~metriplex.fit` keeps its state, so an interrupted run can continue.

    The file at ``path`` is written atomically every ``every`` evaluations, on Ctrl-C and at the
    end: parameters, optimiser state, step, PRNG key, best model and history. With
    ``resume=True`` training continues from it and reaches the same result as an uninterrupted
    run with the same arguments.

    ```python
    model, history = fit(model, data, checkpoint=Checkpoint("run/checkpoint.ckpt"), key=key)
    ```
    """

    path: str | os.PathLike
    every: int = 10
    resume: bool = False

    def __post_init__(self):
        object.__setattr__(self, "every", expect_integer(
            self.every, least=1, what="Checkpoint's every (evaluations between checkpoints)",
            fix="Example: Checkpoint(path, every=10)."))


@dataclasses.dataclass(frozen=True)
class LBFGSFinish:
    """An L-BFGS stage (:func:`optax.lbfgs`) after :func:`~metriplex.fit`'s Adam stage.

    ``steps`` iterations from the best Adam model on the loss of up to ``pairs`` fixed training
    pairs (evenly spread), evaluated every ``eval_every`` iterations of ``fit``; its model is
    kept only where the validation score improves.

    ```python
    model, history = fit(model, data, finish=LBFGSFinish(steps=1000), key=key)
    ```
    """

    steps: int = 1000
    pairs: int = 8192

    def __post_init__(self):
        example = "Example: LBFGSFinish(steps=1000)."
        object.__setattr__(self, "steps", expect_integer(
            self.steps, what="LBFGSFinish's steps", least=0, fix=example))
        object.__setattr__(self, "pairs", expect_integer(
            self.pairs, what="LBFGSFinish's pairs", least=1, fix=example))
