r"""What an evaluation judges and when training stops: the held-out rollout check that keeps
the best model (:class:`RolloutCheck`, :func:`rollout_score`), the parameters it judges
(:class:`Average`), and the plateau schedule (:class:`Plateau`) that cuts the learning rate and
ends training.
"""

from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING, Any

import jax
import jax.numpy as jnp
import numpy as np

from ._errors import MetriplexError, expect_integer
from .data import Trajectories
from .losses import Loss

if TYPE_CHECKING:
    from jax.typing import DTypeLike
    from numpy.typing import ArrayLike

    from ._model import GenericModel
    from .integrate import AbstractScheme

@dataclasses.dataclass(frozen=True)
class Plateau:
    r"""When :func:`fit` cuts the learning rate and when it stops: the default schedule.

    Every evaluation compares the validation score (the held-out rollout error when validation
    trajectories are rolled out, else the validation loss) with the best so far. After
    ``patience`` evaluations without a relative improvement of ``min_delta``, the learning rate
    is multiplied by ``factor`` and training goes on from the best model; after ``cuts`` such
    plateaus training stops (*converged*). ``fit``'s ``steps`` stays a cap.

    ```python
    model, history = fit(model, data, steps=50_000, stopping=Plateau(patience=5), key=key)
    ```
    """

    patience: int = 20
    factor: float = 0.3
    cuts: int = 3
    min_delta: float = 1e-3

    def __post_init__(self):
        if self.patience < 1 or not 0.0 < self.factor < 1.0 or self.cuts < 0:
            raise MetriplexError(
                f"Plateau needs patience >= 1, 0 < factor < 1 and cuts >= 0; got "
                f"patience={self.patience}, factor={self.factor}, cuts={self.cuts}."
            )
        if not 0.0 <= self.min_delta < 1.0:
            raise MetriplexError(
                f"Plateau.min_delta is a relative improvement in [0, 1); got {self.min_delta}."
            )


@dataclasses.dataclass(frozen=True)
class Average:
    r"""Judge each evaluation by a running average of the parameters, and keep that average.

    After every chunk of :math:`k` optimiser steps (``fit``'s ``eval_every``), the average
    :math:`\bar\theta \leftarrow \beta\bar\theta + (1-\beta)\theta` with
    :math:`\beta = e^{-k/h}`: an exponential average of the chunks' end parameters over about
    :math:`h` optimiser steps, :math:`h` = ``steps`` but at most a twentieth of ``fit``'s step
    budget (so that a short run is not judged by its first steps). The validation loss, the
    held-out rollouts and the model kept are the average's; the optimiser goes on from its own
    parameters. A learning-rate cut restarts both from the model of the best validation loss.
    The average smooths the step-to-step noise of Adam at a high rate, which otherwise decides
    which model the held-out rollouts keep (docs/zoo.md, *Parameter averaging*).

    ```python
    model, history = fit(model, data, average=Average(steps=1000), key=key)
    ```
    """

    steps: int = 500

    def __post_init__(self):
        expect_integer(self.steps, what="Average's steps", least=1,
                       fix="Example: Average(steps=500); average=None for none.")

    def weight(self, length: int, budget: int) -> float:
        r""":math:`\beta`, the weight of the old average after a chunk of ``length`` steps in
        a run of at most ``budget`` steps."""
        return math.exp(-length / max(min(self.steps, budget // 20), 1))

    def update(self, average: Any, params: Any, length: int, budget: int) -> Any:
        """The average after a chunk of ``length`` steps that ended at ``params``."""
        beta = self.weight(length, budget)
        return jax.tree_util.tree_map(lambda a, p: beta * a + (1.0 - beta) * p, average, params)


@dataclasses.dataclass(frozen=True)
class RolloutCheck:
    r"""Judge each evaluation by rolling the model out on held-out trajectories.

    From the first state of up to ``trajectories`` validation trajectories, for at most
    ``steps`` steps of their own time grid, with the training scheme. The score is the mean
    over trajectories of the RMS error in units of each variable's standard deviation; a
    rollout that fails scores :math:`10^3` plus the fraction of steps it missed, so any
    complete rollout beats any failed one. :func:`fit` keeps the model with the best score.
    """

    steps: int = 200
    trajectories: int = 16

    def __post_init__(self):
        if self.steps < 1 or self.trajectories < 1:
            raise MetriplexError(
                f"RolloutCheck needs steps >= 1 and trajectories >= 1; got steps={self.steps}, "
                f"trajectories={self.trajectories}."
            )

    def prepare(self, valid: Trajectories,
                dtype: DTypeLike) -> tuple[jax.Array, jax.Array, np.ndarray]:
        """The padded windows ``(ts, xs, mask)`` that every check rolls out."""
        ids = valid.ids[: self.trajectories]
        ts, xs, lengths = valid.select(ids).padded()
        T = min(self.steps + 1, ts.shape[1])
        ts, xs = ts[:, :T], xs[:, :T]
        mask = np.arange(T)[None, :] < np.minimum(lengths, T)[:, None]
        # times from each window's start, shifted in float64: only the steps matter, and
        # times far from 0 lose them in float32
        return jnp.asarray(ts - ts[:, :1], dtype), jnp.asarray(xs, dtype), mask


FAILED_ROLLOUT_SCORE = 1e3


def rollout_score(model: GenericModel, scheme: AbstractScheme,
                  windows: tuple[jax.Array, jax.Array, np.ndarray],
                  scale: ArrayLike) -> tuple[float, int]:
    """``(score, failures)`` of :class:`RolloutCheck` for prepared ``windows``."""
    from .integrate import solve

    ts, xs, mask = windows
    out = solve(model, xs[:, 0], ts, scheme=scheme)
    pred = np.asarray(out.xs, np.float64)
    obs = np.asarray(xs, np.float64)
    err = np.sum(((pred - obs) / np.asarray(scale)[None, None, :]) ** 2, axis=-1) / obs.shape[-1]
    failed = np.asarray(out.failed_step) >= 0
    scores = []
    for k in range(obs.shape[0]):
        m = mask[k]
        if failed[k] or not np.all(np.isfinite(err[k][m])):
            first = int(out.failed_step[k]) if failed[k] else 0
            scores.append(FAILED_ROLLOUT_SCORE + 1.0 - first / max(int(m.sum()), 1))
        else:
            scores.append(float(np.sqrt(np.mean(err[k][m]))))
    return float(np.mean(scores)), int(np.sum(failed))


def scheme_of(loss: Loss) -> AbstractScheme:
    """The scheme of the loss's residual term (Crank–Nicolson if it has none)."""
    from .integrate import CrankNicolson
    from .losses import SchemeResidual

    for term in loss.terms:
        if isinstance(term, SchemeResidual):
            return term.scheme
    return CrankNicolson()
