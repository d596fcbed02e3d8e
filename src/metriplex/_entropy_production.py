"""Where a model's own flow decreases its entropy: part of :func:`metriplex.evaluate`'s report
(``entropy_production_negative_fraction``)."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._model import GenericModel, float_dtype, with_dtype
from ._precision import in_full_precision


@eqx.filter_jit
def _field_and_entropy_gradient(model, xs):
    return jax.vmap(model.vector_field)(xs), jax.vmap(jax.grad(model.entropy))(xs)


#: A state "decreases the entropy" when dS/dt < -PRODUCTION_TOLERANCE * |D grad S| |D^-1 dx/dt|:
#: more than 1% of the fastest change that the state's speed allows, so rounding at states
#: where the production vanishes (equilibria, turning points) does not count.
PRODUCTION_TOLERANCE = 1e-2


@in_full_precision
def entropy_production_negative_fraction(model: GenericModel, states: np.ndarray,
                                         scale: np.ndarray, *, max_states: int = 2048) -> float:
    r"""The fraction of ``states`` at which the model's own flow decreases its entropy.

    :math:`\dot S = \nabla S\cdot f(x)` with :math:`f = L\nabla E + M\nabla S` is
    :math:`\nabla S\cdot M\nabla S \ge 0` for a GENERIC model (:math:`L\nabla S = 0`,
    :math:`M` PSD). A state counts when :math:`\dot S < -` :data:`PRODUCTION_TOLERANCE`
    :math:`|D\nabla S|\,|D^{-1}f|` (``D`` = diag(``scale``)), a measure that does not
    depend on the units of time, state or :math:`S`. ``states`` are the model's own rollout
    (up to any failure), subsampled evenly to ``max_states``; 0.0 for a model whose entropy
    is constant. The rates are computed in the model's dtype, and a state that a float32
    model counts is counted only where the model in float64 decreases its entropy too
    (float32 rounding of rates that cancel, such as heat conducted between two cells, is not
    a decrease).
    """
    x = np.asarray(states, dtype=np.float64)
    x = x[np.all(np.isfinite(x), axis=1)]
    if len(x) == 0:
        return 0.0
    if len(x) > max_states:
        x = x[np.linspace(0, len(x) - 1, max_states).astype(int)]
    d = np.asarray(scale, dtype=np.float64)
    decreases = _entropy_decreases(model, x, d)
    if np.any(decreases) and float_dtype(model) != np.float64:
        # A float32 model's dS/dt is a sum of rates that cancel (heat leaving one cell and
        # entering another), rounded at a float32 ulp of each: a state counts only where the
        # same model in float64 decreases its entropy too.
        again = _entropy_decreases(with_dtype(model, jnp.float64), x[decreases], d)
        decreases[np.flatnonzero(decreases)] = again
    return float(np.mean(decreases))


def _entropy_decreases(model: GenericModel, x: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Where ``model``'s flow decreases its entropy beyond :data:`PRODUCTION_TOLERANCE`, in
    the model's own dtype (a bool per state of ``x``)."""
    f, gS = _field_and_entropy_gradient(model, jnp.asarray(x, float_dtype(model)))
    f, gS = np.asarray(f, dtype=np.float64), np.asarray(gS, dtype=np.float64)
    rate = np.sum(gS * f, axis=1)
    size = np.linalg.norm(gS * d[None, :], axis=1) * np.linalg.norm(f / d[None, :], axis=1)
    return rate < -PRODUCTION_TOLERANCE * size
