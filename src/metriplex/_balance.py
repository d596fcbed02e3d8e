r"""Temperatures from the energy balance of the data: the slope that a learned energy must have
along the entropy variables for the energy to stay constant where the data record heat.

Where L and S are given and E is learned, the reversible first stage (README, *Friction that
carries the motion*) fits E's mechanical part, while its slope along the entropy variables
:math:`s_i` (the temperatures :math:`T_i = \partial E/\partial s_i`) moves nothing there
(:math:`L\nabla S = 0`). A brake that stores 50x the mechanical energy across the data has, in
the networks' units, a temperature 150x the gradients that drive the motion, which the main
stage would have to grow from order one. Along GENERIC data the energy is constant, so that
slope can be read off the first stage's energy: :math:`\Delta E_1 + \sum_i T_i\Delta s_i
\approx 0` over the data's pairs.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from scipy.optimize import nnls

from ._errors import MetriplexError

if TYPE_CHECKING:
    from .data import Trajectories
    from .structure.potential import MLPPotential

#: States per evaluation of the energy (bounds the memory of large data).
CHUNK = 1 << 15


def balance_temperatures(energy: "MLPPotential", data: "Trajectories",
                         indices: Sequence[int]) -> np.ndarray:
    r"""The temperatures :math:`T_i` (one per entropy variable ``indices``, in the data's
    units) that keep :math:`E + \sum_i T_i s_i` most nearly constant along ``data``: the least
    squares solution of :math:`\Delta E_n + \sum_i T_i\Delta s_{i,n} = 0` over the pairs of
    consecutive samples of each trajectory, with every :math:`T_i \ge 0` (a negative
    temperature is no start for training; the hinge on negative temperatures would undo it).
    Zero where the entropies do not move."""
    idx = list(indices)
    dtype = energy.out.weight.dtype
    values = np.concatenate([
        np.asarray(jax.vmap(energy)(jnp.asarray(data.x[s:s + CHUNK], dtype)), np.float64)
        for s in range(0, len(data.x), CHUNK)])
    same = data.trajectory[1:] == data.trajectory[:-1]
    rise = np.diff(np.asarray(data.x, np.float64)[:, idx], axis=0)[same]
    change = np.diff(values)[same]
    ok = np.all(np.isfinite(rise), axis=1) & np.isfinite(change)
    if not np.any(ok) or not np.any(rise[ok]):
        return np.zeros(len(idx))
    # non-negative least squares, on columns scaled to one (entropies of very different sizes)
    size = np.sqrt(np.mean(rise[ok] ** 2, axis=0))
    size = np.where(size > 0, size, 1.0)
    scaled, _ = nnls(rise[ok] / size, -change[ok])
    temperatures = scaled / size
    return np.where(np.isfinite(temperatures), temperatures, 0.0)


def with_temperatures(energy: "MLPPotential", indices: Sequence[int],
                      temperatures: np.ndarray) -> "MLPPotential":
    r"""``energy`` with ``temperatures`` (the data's units) added to its slope along the
    variables ``indices``, through its linear term (``MLPPotential(..., linear=True)``, in
    standardised inputs: :math:`\partial E/\partial s_i = \sigma a_i/d_i`; one is added
    where the energy has none). The energy must read the state itself, not features of it."""
    if energy.features is not None:
        raise MetriplexError(
            "with_temperatures sets the slope of an energy along state variables, so the "
            "energy must read the state, not features of it; got an MLPPotential with "
            "features. Leave the temperatures to training (--no-temperature-init).")
    idx = np.asarray(list(indices))
    scale = np.ones(energy.n) if energy.scale is None else np.asarray(energy.scale)
    dtype = energy.out.weight.dtype
    slope = np.zeros(energy.n) if energy.linear is None else np.asarray(energy.linear,
                                                                        np.float64).copy()
    slope[idx] += np.asarray(temperatures, np.float64) * scale[idx] / energy.output_scale
    return eqx.tree_at(lambda e: e.linear, energy, jnp.asarray(slope, dtype),
                       is_leaf=lambda leaf: leaf is None)
