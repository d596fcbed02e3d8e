r"""A family of Duffing oscillators in a bath, whose stiffness is a state variable: constant
along every trajectory, different between them (a parameter recorded with the data, as a shear
rate or a temperature setting is in many published datasets).

State :math:`x = (q, p, s, k)`. With velocity :math:`v = p/m` and bath temperature
:math:`\theta = \theta_0 e^{s/c}`,

.. math::
    E = \frac{p^2}{2m} + \frac{k q^2}{2} + \frac{a q^4}{4} + c\,\theta_0\big(e^{s/c} - 1\big),
    \qquad S = s,\qquad L\ \text{canonical in}\ (q, p),

.. math::
    M = \frac{\gamma}{\theta}\,w w^\top,\qquad w = (0,\ \theta,\ -v,\ 0).

The rows and columns of :math:`k` in :math:`L` and :math:`M` are zero, so :math:`\dot k = 0`,
while :math:`E` depends on :math:`k`. :math:`M\nabla E = \frac{\gamma}{\theta} w\,(\theta v -
v\theta) = 0`, :math:`\dot q = v`, :math:`\dot p = -kq - aq^3 - \gamma v`,
:math:`\dot s = \gamma v^2/\theta \ge 0`.
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp

from ..._errors import MetriplexError
from ..._model import GenericModel
from ..._types import Matrix, Scalar, State
from ...structure import CanonicalPoisson, SumOf
from .._base import BoxSampling, System, analytic_model
from ._case import ZooCase, case_settings
from ._parts import bath_energy, bath_heating, check_signs, hardening_frequency


@dataclasses.dataclass(frozen=True)
class OscillatorFamilyConfig:
    r"""Parameters of the oscillator family (SI units, seconds).

    ``mass`` :math:`m` = 1 kg, ``quartic`` :math:`a` = 0.5 N/m³, ``damping`` :math:`\gamma` =
    0.15 kg/s, bath ``heat_capacity`` :math:`c` = 1.5 J/K, reference temperature ``theta0``
    :math:`\theta_0` = 1 K. Initial states ``x0_center + U(-1, 1) * x0_halfwidth``, by default
    :math:`(0, 0, 0, 4) + U(-1,1)\cdot(1.2, 2.5, 0.3, 2.5)`: stiffnesses from 1.5 to 6.5 N/m.
    """

    mass: float = 1.0
    quartic: float = 0.5
    damping: float = 0.15
    heat_capacity: float = 1.5
    theta0: float = 1.0
    x0_center: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 4.0)
    x0_halfwidth: tuple[float, float, float, float] = (1.2, 2.5, 0.3, 2.5)

    def __post_init__(self):
        check_signs(self, "oscillator-family",
                    positive=("mass", "heat_capacity", "theta0"),
                    nonnegative=("quartic", "damping"), example="quartic=0.5, damping=0.15")
        k_min = self.x0_center[3] - abs(self.x0_halfwidth[3])
        if not k_min > 0.0:
            raise MetriplexError(
                "oscillator-family needs every initial stiffness > 0, i.e. x0_center[3] > "
                f"|x0_halfwidth[3]|; got x0_center[3]={self.x0_center[3]}, "
                f"x0_halfwidth[3]={self.x0_halfwidth[3]}. Example: x0_center=(0, 0, 0, 4), "
                "x0_halfwidth=(1.2, 2.5, 0.3, 2.5)."
            )


def _energy(c: OscillatorFamilyConfig, x: State) -> Scalar:
    q, p, s, k = x[0], x[1], x[2], x[3]
    return (p**2 / (2.0 * c.mass) + 0.5 * k * q**2 + 0.25 * c.quartic * q**4
            + bath_energy(s, c.heat_capacity, c.theta0))


def _friction(c: OscillatorFamilyConfig, x: State) -> Matrix:
    m = bath_heating(c, c.damping, x[2], x[1:2] / c.mass)
    return jnp.pad(m, ((0, 1), (0, 1)))


@dataclasses.dataclass(frozen=True)
class OscillatorFamily(BoxSampling, System):
    """Duffing oscillators in a bath with the stiffness as a fourth, constant variable (n = 4)."""

    name = "oscillator-family"
    description = (
        "Duffing oscillator in a bath with its stiffness k as a state variable, constant along "
        "each trajectory: canonical L in (q, p), S = s, M = (gamma/theta) w w^T with "
        "w = (0, theta, -v, 0)."
    )
    names = ("q", "p", "s", "k")
    defaults = case_settings(dt=0.02, steps=300, trajectories=32)
    config: OscillatorFamilyConfig = OscillatorFamilyConfig()

    @property
    def max_substep(self) -> float:
        c = self.config
        stiffest = c.x0_center[3] + abs(c.x0_halfwidth[3])
        omega = hardening_frequency(stiffest, c.quartic, c.mass, c.x0_center, c.x0_halfwidth)
        return float(min(0.005, 0.01 / omega))

    def _build_model(self) -> GenericModel:
        return analytic_model(self.config, energy=_energy, entropy=SumOf((2,)),
                              poisson=CanonicalPoisson(4, 1), friction=_friction)


CASE = ZooCase.of(
    OscillatorFamily(),
    {},
    held_out=True,
    note="A parameter recorded as a state variable (constant along each trajectory); nothing "
         "given, as for a published dataset whose structure is unknown.",
)
