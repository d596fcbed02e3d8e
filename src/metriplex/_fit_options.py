"""The option objects of :func:`~metriplex.fit` that group settings belonging together:
:class:`Checkpoint` (where training saves its state, how often, and whether it resumes) and
:class:`LBFGSFinish` (an L-BFGS stage after Adam). Like :class:`~metriplex.train.Plateau` and
:class:`~metriplex.train.RolloutCheck`, each is a frozen dataclass checked when it is made.
"""

from __future__ import annotations

import dataclasses
import os

from ._errors import MetriplexError


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
        if isinstance(self.every, bool) or not isinstance(self.every, int) or self.every < 1:
            raise MetriplexError(
                f"Checkpoint(every=...) counts evaluations between checkpoints and must be an "
                f"integer >= 1; got {self.every!r}. Example: Checkpoint(path, every=10)."
            )


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
        for name, least in (("steps", 0), ("pairs", 1)):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < least:
                raise MetriplexError(
                    f"LBFGSFinish needs steps >= 0 and pairs >= 1 (integers); got "
                    f"steps={self.steps!r}, pairs={self.pairs!r}. Example: "
                    "LBFGSFinish(steps=1000)."
                )
