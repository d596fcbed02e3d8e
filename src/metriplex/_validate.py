r"""What an evaluation judges and when training stops: the held-out rollout check that keeps
the best model (:class:`RolloutCheck`, :func:`rollout_score`) and the plateau schedule
(:class:`Plateau`) that cuts the learning rate and ends training.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import jax.numpy as jnp
import numpy as np

from ._errors import MetriplexError
from .data import Trajectories
from .losses import Loss

if TYPE_CHECKING:
    import jax
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
        return jnp.asarray(ts, dtype), jnp.asarray(xs, dtype), mask


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
