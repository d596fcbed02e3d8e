r"""What several zoo systems share: a heat bath of constant heat capacity :math:`c`, the
friction by which a motion heats it, and the energy and frequency of a hardening oscillator.

A bath of entropy :math:`s` holds the energy :math:`U(s) = c\,\theta_0(e^{s/c} - 1)` at the
temperature :math:`\theta = U'(s) = \theta_0 e^{s/c}`. Friction of coefficient :math:`\gamma`
on the velocities :math:`v` of :math:`k` canonical pairs heats it through
:math:`M = \frac{\gamma}{\theta} W W^\top`, :math:`W = (0;\ \theta I_k;\ -v^\top)`, so that
:math:`\dot p = -\gamma v` and :math:`\dot s = \gamma|v|^2/\theta`.
"""

from __future__ import annotations

from typing import Any, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from ..._types import Matrix, Scalar


def bath_energy(s: jax.Array, heat_capacity: float | jax.Array, theta0: float) -> jax.Array:
    r""":math:`U(s) = c\,\theta_0(e^{s/c} - 1)`, whose derivative is :math:`\theta_0 e^{s/c}`."""
    return heat_capacity * theta0 * jnp.expm1(s / heat_capacity)


def bath_temperature(s: jax.Array, heat_capacity: float | jax.Array,
                     theta0: float) -> jax.Array:
    r""":math:`\theta = U'(s) = \theta_0 e^{s/c}`."""
    return theta0 * jnp.exp(s / heat_capacity)


def heating_factor(theta: Scalar, v: jax.Array) -> Matrix:
    r""":math:`W = (0;\ \theta I_k;\ -v^\top)`, shape :math:`(2k + 1, k)`, for the state
    :math:`(q_1..q_k, p_1..p_k, s)` with velocities ``v`` of shape ``(k,)``: :math:`W^\top\nabla E
    = \theta v - v\theta = 0`."""
    k = v.shape[0]
    return jnp.concatenate(
        [jnp.zeros((k, k), v.dtype), theta * jnp.eye(k, dtype=v.dtype), -v[None, :]]
    )


def heating_friction(coefficient: float, theta: Scalar, v: jax.Array) -> Matrix:
    r""":math:`M = \frac{\gamma}{\theta} W W^\top` with :math:`W` of :func:`heating_factor`."""
    W = heating_factor(theta, v)
    return (coefficient / theta) * (W @ W.T)


def oscillator_energy(c: Any, q: Scalar, p: Scalar) -> Scalar:
    r""":math:`p^2/2m + kq^2/2 + aq^4/4` of a config with ``mass``, ``stiffness`` and
    ``quartic``."""
    return p**2 / (2.0 * c.mass) + 0.5 * c.stiffness * q**2 + 0.25 * c.quartic * q**4


def hardening_frequency(
    stiffness: float, quartic: float, inertia: float, x0_center: Sequence[float],
    x0_halfwidth: Sequence[float]
) -> float:
    r"""Largest angular frequency :math:`\sqrt{(k + 3aq^2)/m}` of the oscillator
    :math:`m\ddot q = -kq - aq^3` over the initial box of its first variable :math:`q`,
    :math:`|q| \le |{\rm center}_0| + |{\rm halfwidth}_0|`."""
    q = abs(x0_center[0]) + abs(x0_halfwidth[0])
    return float(np.sqrt((stiffness + 3.0 * quartic * q**2) / inertia))
