r"""A wall around the training data for a learned energy, so that its level sets are bounded.

With :math:`M\nabla E = 0` exact, a GENERIC flow conserves :math:`E`; if every level set
:math:`\{E = c\}` is bounded, no trajectory of the model can run away, whatever the networks
learned. A network alone does not give that: off the data its :math:`E` can stay constant along
a direction in which the entropy grows, and rollouts then leave the data and blow up. Adding

.. math:: W(x) = \sum_i \mathrm{relu}\!\left(\frac{x_i - h_i}{s_i}\right)^4
                + \mathrm{relu}\!\left(\frac{l_i - x_i}{s_i}\right)^4,

zero on a box :math:`[l, h]` a little wider than the training states and quartic outside it
(:math:`s_i` the variable's standard deviation over the data), makes :math:`E` coercive: a
softplus network grows at most linearly, so :math:`E + W \to \infty` in every direction. Inside
the box :math:`W` and its gradient vanish, so it changes no residual of the training pairs;
only rollouts that leave the box see it (the held-out ones during training included, which
choose the model kept).

Why quartic: a trained network can fall off the data with a slope :math:`G` (in units of
:math:`E` per standard deviation) far above its slopes on the data, and a wall of power
:math:`k` only overcomes it at a distance of about :math:`G^{1/(k-1)}` standard deviations.
With the quadratic wall of the first version, learned pendulum energies fell fast enough that
their level sets reached 20 standard deviations beyond the data, where the learned
temperatures are 50× their size on the data and the implicit steps stop converging; with the
quartic one they stay within about 7. Its Hessian is also continuous across the box's faces
(the quadratic wall's jumps there), which the Newton steps of the implicit schemes use. Files
written before record no power and keep the quadratic wall they were trained with.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._errors import MetriplexError, expect_integer
from ..data import state_statistics
from .._types import Scalar, State

if TYPE_CHECKING:
    from numpy.typing import ArrayLike


#: How far beyond the training states the wall begins, in standard deviations of each variable.
MARGIN = 1.0

#: The wall's power: ``relu(d) ** POWER`` at ``d`` standard deviations beyond its box.
POWER = 4


class Confinement(eqx.Module):
    """The wall :math:`W(x)` around the box ``[low, high]``, in units of ``scale`` per variable,
    on the variables ``indices`` (those that vary in the data), of power ``power`` outside it
    (:data:`POWER`; 2 in files written before the power was recorded)."""

    indices: tuple[int, ...] = eqx.field(static=True)
    low: tuple[float, ...] = eqx.field(static=True)
    high: tuple[float, ...] = eqx.field(static=True)
    scale: tuple[float, ...] = eqx.field(static=True)
    power: int = eqx.field(static=True)

    def __init__(self, indices: tuple[int, ...], low: tuple[float, ...],
                 high: tuple[float, ...], scale: tuple[float, ...], power: int = POWER) -> None:
        if not len(indices) == len(low) == len(high) == len(scale):
            raise MetriplexError(
                f"Confinement needs one bound and one scale per variable; got {len(indices)} "
                f"indices, {len(low)} low, {len(high)} high and {len(scale)} scales.")
        if not all(s > 0 for s in scale) or not all(lo <= hi for lo, hi in zip(low, high)):
            raise MetriplexError(
                f"Confinement needs low <= high and scales > 0; got low {low}, high {high}, "
                f"scale {scale}.")
        # >= 2: the wall's gradient must vanish on the box's faces
        self.power = expect_integer(power, what="Confinement's power", least=2,
                                    fix=f"Leave it out for {POWER}.")
        self.indices = tuple(int(i) for i in indices)
        self.low = tuple(float(v) for v in low)
        self.high = tuple(float(v) for v in high)
        self.scale = tuple(float(v) for v in scale)

    @classmethod
    def around(cls, data: ArrayLike, margin: float = MARGIN) -> "Confinement":
        """The wall around the states ``data`` (shape ``(samples, n)``): its box spans each
        varying variable's range widened by ``margin`` standard deviations on each side (new
        initial conditions lead a little beyond the training states, and the wall must not push
        them); variables constant in ``data`` are left free (the model holds them constant, or
        nothing can be said of them)."""
        if not (np.isfinite(margin) and margin >= 0):
            raise MetriplexError(f"the wall's margin must be finite and >= 0; got {margin}.")
        x = np.asarray(data, dtype=np.float64)
        low, high = x.min(axis=0), x.max(axis=0)
        _, std, varying = state_statistics(x)
        keep = list(np.nonzero(varying)[0])
        return cls(tuple(int(i) for i in keep), tuple(low[keep] - margin * std[keep]),
                   tuple(high[keep] + margin * std[keep]), tuple(std[keep]))

    def __call__(self, x: State) -> Scalar:
        """The wall's height at the state ``x``: 0 inside the box."""
        if not self.indices:
            return jnp.zeros((), x.dtype)
        z = x[jnp.array(self.indices)]
        low, high, scale = (jnp.asarray(v, x.dtype) for v in (self.low, self.high, self.scale))
        above = jnp.maximum((z - high) / scale, 0.0)
        below = jnp.maximum((low - z) / scale, 0.0)
        return jnp.sum(above**self.power + below**self.power)

    def to_json(self) -> dict[str, Any]:
        """The constructor's arguments as JSON lists: ``Confinement(**to_json())`` rebuilds it."""
        return {"indices": list(self.indices), "low": list(self.low), "high": list(self.high),
                "scale": list(self.scale), "power": self.power}

    @classmethod
    def from_json(cls, spec: dict[str, Any]) -> "Confinement":
        """The wall that :meth:`to_json` wrote (quadratic where it records no power: files
        written before the wall became quartic)."""
        return cls(tuple(spec["indices"]), tuple(spec["low"]), tuple(spec["high"]),
                   tuple(spec["scale"]), power=spec.get("power", 2))
