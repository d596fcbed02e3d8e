r"""What several zoo systems share: a heat bath of constant heat capacity :math:`c`, the
friction by which a motion heats it, the energy and frequency of a hardening oscillator, and the
check that a config's parameters have their signs (:func:`check_signs`).

A bath of entropy :math:`s` holds the energy :math:`U(s) = c\,\theta_0(e^{s/c} - 1)` at the
temperature :math:`\theta = U'(s) = \theta_0 e^{s/c}`. Friction of coefficient :math:`\gamma`
on the velocities :math:`v` of :math:`k` canonical pairs heats it through
:math:`M = \frac{\gamma}{\theta} W W^\top`, :math:`W = (0;\ \theta I_k;\ -v^\top)`, so that
:math:`\dot p = -\gamma v` and :math:`\dot s = \gamma|v|^2/\theta`.
"""

from __future__ import annotations

import dataclasses
from typing import Any, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from ..._errors import MetriplexError
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


def bath_heating(c: Any, coefficient: float, s: Scalar, v: jax.Array) -> Matrix:
    r""":func:`heating_friction` of the bath of a config with ``heat_capacity`` and ``theta0``
    at entropy ``s``: friction of ``coefficient`` on the velocities ``v`` heats it."""
    return heating_friction(coefficient, bath_temperature(s, c.heat_capacity, c.theta0), v)


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


def oscillator_frequency(c: Any) -> float:
    r""":func:`hardening_frequency` of the oscillator of :func:`oscillator_energy`, for a config
    with ``mass``, ``stiffness``, ``quartic``, ``x0_center`` and ``x0_halfwidth``."""
    return hardening_frequency(c.stiffness, c.quartic, c.mass, c.x0_center, c.x0_halfwidth)


def check_signs(config: Any, system: str, *, positive: Sequence[str] = (),
                nonnegative: Sequence[str] = (), example: str) -> None:
    """Raise unless the fields of ``config`` named in ``positive`` are > 0 and those named in
    ``nonnegative`` are >= 0 (each entry of a tuple field; NaN is neither). The message names
    ``system``, the rule, every value it checks (in the config's field order) and ``example``,
    a valid setting."""

    def holds(name: str, strict: bool) -> bool:
        value = getattr(config, name)
        entries = value if isinstance(value, tuple) else (value,)
        return all(v > 0.0 if strict else v >= 0.0 for v in entries)

    if all(holds(k, True) for k in positive) and all(holds(k, False) for k in nonnegative):
        return
    rule = " and ".join(f"{sign} {_listing(names)}" for sign, names in
                        (("positive", positive), ("non-negative", nonnegative)) if names)
    checked = set(positive) | set(nonnegative)
    got = ", ".join(f"{f.name}={getattr(config, f.name)}" for f in dataclasses.fields(config)
                    if f.name in checked)
    raise MetriplexError(f"{system} needs {rule}; got {got}. Example: {example}.")


def _listing(names: Sequence[str]) -> str:
    """``a``, ``a and b``, ``a, b and c``."""
    return names[0] if len(names) == 1 else f"{', '.join(names[:-1])} and {names[-1]}"
