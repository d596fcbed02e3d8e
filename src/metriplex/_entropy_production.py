"""Where a model's own flow decreases its entropy: part of :func:`metriplex.evaluate`'s report
(``entropy_production_negative_fraction``)."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._model import GenericModel, float_dtype
from ._precision import in_full_precision


@eqx.filter_jit
def _rates(model, xs):
    """Per state: the field f, grad S, and the size |grad S|^T (|L| |grad E| + |M| |grad S|)
    of the products that dS/dt = grad S . f sums, on which its rounding is bounded."""

    def one(x):
        t = model.terms(x)
        a = jnp.abs(t.grad_entropy)
        size = a @ (jnp.abs(t.poisson) @ jnp.abs(t.grad_energy) + jnp.abs(t.friction) @ a)
        return t.vector_field, t.grad_entropy, size

    return jax.vmap(one)(xs)


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
    depend on the units of time, state or :math:`S`, and below the rounding of its sums in
    the model's dtype, :math:`(2n + 4)\,\varepsilon\,|\nabla S|^\top(|L||\nabla E| +
    |M||\nabla S|)`: where a stiff friction conducts heat between cells at nearly equal
    temperatures, the rates that :math:`\dot S` sums cancel, and their float32 rounding is
    not a decrease. ``states`` are the model's own rollout (up to any failure), subsampled
    evenly to ``max_states``; 0.0 for a model whose entropy is constant.
    """
    x = np.asarray(states, dtype=np.float64)
    x = x[np.all(np.isfinite(x), axis=1)]
    if len(x) == 0:
        return 0.0
    if len(x) > max_states:
        x = x[np.linspace(0, len(x) - 1, max_states).astype(int)]
    dtype = float_dtype(model)
    f, gS, products = (np.asarray(a, dtype=np.float64)
                       for a in _rates(model, jnp.asarray(x, dtype)))
    d = np.asarray(scale, dtype=np.float64)
    rate = np.sum(gS * f, axis=1)
    size = np.linalg.norm(gS * d[None, :], axis=1) * np.linalg.norm(f / d[None, :], axis=1)
    rounding = (2 * x.shape[1] + 4) * float(np.finfo(dtype).eps) * products
    return float(np.mean(rate < -np.maximum(PRODUCTION_TOLERANCE * size, rounding)))
