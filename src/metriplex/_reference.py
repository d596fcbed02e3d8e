"""The evidence that :mod:`metriplex.verdict` weighs, measured: the black-box reference (an
unconstrained model of the same capacity, trained in the data's own units) and what a model
does on the held-out pairs (its Crank–Nicolson residuals; the learned E and S along the observed
flow). The judgement itself, its checks and their limits are in :mod:`metriplex.verdict`.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np

from ._errors import TrainingDiverged
from ._model import AbstractModel, Terms, with_dtype
from ._types import Matrix, State
from .data import Trajectories, state_noise, state_scale, time_scale
from .losses import CrankNicolsonResidual
from .structure._mlp import Hidden, standardise
from .structure.potential import ZeroPotential

if TYPE_CHECKING:
    from jax.typing import DTypeLike
    from numpy.typing import ArrayLike


class BlackBoxModel(AbstractModel):
    r"""An unconstrained vector field :math:`\dot x = f_\theta(x)` (an MLP), trainable with
    :func:`metriplex.fit` and the same pair losses. It is not GENERIC: it measures the residual
    floor of the data.

    Its network sees standardised states and its output is in the data's rate units ``rate``
    (:math:`d_i/\tau`, :attr:`metriplex.Units.rate`), so it trains the same on data in any
    units of time or state."""

    hidden: Hidden
    out: eqx.nn.Linear
    n: int = eqx.field(static=True)
    shift: tuple[float, ...] = eqx.field(static=True)
    scale: tuple[float, ...] = eqx.field(static=True)
    rate: tuple[float, ...] = eqx.field(static=True)
    energy: ZeroPotential
    entropy: ZeroPotential

    def __init__(self, n: int, *, width: int = 64, depth: int = 2, data: ArrayLike,
                 rate: ArrayLike | None = None, key: jax.Array) -> None:
        from .structure._mlp import data_statistics

        k1, k2 = jr.split(key)
        self.n = n
        self.shift, self.scale = data_statistics(np.asarray(data))
        self.rate = tuple(float(r) for r in (self.scale if rate is None else rate))
        self.hidden = Hidden(n, width, depth, "softplus", key=k1)
        self.out = eqx.nn.Linear(width, n, key=k2)
        self.energy = ZeroPotential()
        self.entropy = ZeroPotential()

    def vector_field(self, x: State) -> State:
        """The network's field at the state ``x``, in the data's units."""
        z = standardise(x, self.shift, self.scale)
        return self.out(self.hidden(z)) * jnp.asarray(self.rate, x.dtype)

    def terms(self, x: State) -> Terms:
        # Expressed as Terms with L = I and grad E = f, so every pair loss applies unchanged.
        r"""The field as :class:`~metriplex.Terms` with :math:`L = I`, :math:`\nabla E = f` and the
        rest zero, so that every pair loss applies unchanged."""
        zero = jnp.zeros((), x.dtype)
        eye = jnp.eye(self.n, dtype=x.dtype)
        return Terms(zero, zero, self.vector_field(x), jnp.zeros_like(x), eye, 0.0 * eye)

    def poisson_matrix(self, x: State) -> Matrix:
        """The zero matrix: the black box has no bracket to check."""
        return jnp.zeros((self.n, self.n), x.dtype)

    def size(self) -> int:
        """The number of state variables."""
        return self.n


def _residuals(model, pairs, rate, dtype) -> np.ndarray:
    """Per-pair, per-variable Crank–Nicolson residual in the data's rate units."""
    x0, x1, dt = (jnp.asarray(a, dtype) for a in pairs)
    return np.asarray(_cn_residual(model, x0, x1, dt), dtype=np.float64) / rate[None, :]


@eqx.filter_jit
def _cn_residual(model, x0, x1, dt):
    f0 = jax.vmap(model.vector_field)(x0)
    f1 = jax.vmap(model.vector_field)(x1)
    return (x1 - x0) / dt[:, None] - 0.5 * (f0 + f1)


@eqx.filter_jit
def _potential_gradients(model, x):
    return jax.vmap(jax.grad(model.energy))(x), jax.vmap(jax.grad(model.entropy))(x)


def _serial_correlation(residuals: np.ndarray, trajectory: np.ndarray) -> float | None:
    r"""The lag-one correlation of per-pair ``residuals`` ``(P, n)`` along their trajectories
    (``trajectory``: the id of each pair, pairs of one trajectory consecutive):
    :math:`\sum_k r_k\cdot r_{k+1} / \sum_k |r_k|^2` over neighbouring pairs, not centred (a
    steady bias counts as correlated). Noise on the recorded states gives about -0.5 (the
    residual differences it); what a field leaves of smooth dynamics gives nearly 1. ``None``
    with fewer than 10 neighbouring pairs."""
    follows = trajectory[1:] == trajectory[:-1]
    if int(follows.sum()) < 10:
        return None
    a, b = residuals[:-1][follows], residuals[1:][follows]
    power = 0.5 * float(np.sum(a * a) + np.sum(b * b))
    return _finite(float(np.sum(a * b)) / power) if power > 0 else None


def _finite(v) -> float | None:
    return float(v) if v is not None and np.isfinite(v) else None


@dataclasses.dataclass(frozen=True)
class Reference:
    """The trained black-box reference of :func:`metriplex.verdict.verdict`, reusable for
    several models judged on the same data (:func:`train_reference`)."""

    model: BlackBoxModel | None
    validation: float
    seed: int
    rows: int
    n: int
    note: str = ""


def train_reference(data: Trajectories, *, width: int = 64, depth: int = 2, steps: int = 3000,
                    learning_rate: float = 1e-2, batch_size: int = 256,
                    validation: float = 0.2, seed: int = 0,
                    dtype: DTypeLike | None = None,
                    progress: bool = False) -> Reference:
    """Train the black-box reference of :func:`metriplex.verdict.verdict` on
    ``1 - validation`` of the trajectories of ``data`` (split by ``seed``), in the data's own
    units. A training that diverges gives a reference without a model (the verdict then cannot
    tell)."""
    from .train import fit

    train, _ = data.split(validation, seed=seed)
    d = state_scale(train.x)
    rate = d / time_scale(train, d)
    dtype = jnp.zeros(()).dtype if dtype is None else dtype
    box = BlackBoxModel(data.n, width=width, depth=depth, data=train.x, rate=rate,
                        key=jr.key(seed))
    box = with_dtype(box, dtype)
    note = ""
    try:
        box, _ = fit(box, train, loss=CrankNicolsonResidual(), steps=steps,
                     batch_size=batch_size, learning_rate=learning_rate, validation=None,
                     scale=rate, dtype=dtype, progress=progress, key=jr.key(seed + 1))
    except TrainingDiverged as e:
        box, note = e.model, "; its training diverged"
    return Reference(box, validation, seed, len(data.t), data.n, note)


def _observed_laws(model, held: Trajectories, d: np.ndarray, dtype) -> dict[str, float | None]:
    """The learned E and S along the observed pairs: the median of |dE| relative to the
    largest change the step allows, and the fraction of pairs whose learned S decreases (by
    more than 1% of the largest change the step allows). Standardised, so unit-free. Only
    what lies beyond three standard deviations of the change that noise on the states would
    give (:func:`~metriplex.data.state_noise`) counts: with 1-5 % noise, the noise alone made
    the learned S of a GENERIC fit "decrease" on 32-44 % of the pairs."""
    pairs = held.pairs()
    dx = np.asarray(pairs.x1 - pairs.x0, dtype=np.float64)
    mid = jnp.asarray(0.5 * (pairs.x0 + pairs.x1), dtype)
    gE, gS = (np.asarray(g, dtype=np.float64) for g in _potential_gradients(model, mid))
    step = np.linalg.norm(dx / d[None, :], axis=1)
    sE = np.linalg.norm(gE * d[None, :], axis=1) * step
    sS = np.linalg.norm(gS * d[None, :], axis=1) * step
    noise = np.sqrt(2.0) * state_noise(held)[None, :]  # of a pair's difference
    nE, nS = (3.0 * np.linalg.norm(g * noise, axis=1) for g in (gE, gS))
    dE = np.maximum(np.abs(np.sum(gE * dx, axis=1)) - nE, 0.0)
    dS = np.sum(gS * dx, axis=1)
    okE, okS = sE > 0, sS > 0
    return {
        "energy_rate_relative_median":
            _finite(np.median(dE[okE] / sE[okE])) if np.any(okE) else None,
        "entropy_decreasing_fraction":
            _finite(np.mean(dS[okS] < -np.maximum(0.01 * sS[okS], nS[okS])))
            if np.any(okS) else None,
        # The noise floor subtracted from |dE| above, in the same units: where it is not far
        # below the first law's limit, a small figure says nothing (verdict's weigh_misfit).
        "energy_noise_floor_median":
            _finite(np.median(nE[okE] / sE[okE])) if np.any(okE) else None,
    }
