r"""A damped Duffing oscillator whose friction heats a bath.

State :math:`x = (q, p, s)`: position, momentum and the bath's entropy. With velocity
:math:`v = p/m` and bath temperature :math:`\theta = U'(s) = \theta_0 e^{s/c}`,

.. math::
    E = \frac{p^2}{2m} + \frac{k q^2}{2} + \frac{a q^4}{4} + c\,\theta_0\big(e^{s/c} - 1\big),
    \qquad S = s,\qquad L\ \text{canonical in}\ (q, p),

.. math::
    M = \frac{\gamma}{\theta}\,w w^\top,\qquad w = (0,\ \theta,\ -v),

so :math:`M\nabla E = \frac{\gamma}{\theta} w\,(\theta v - v\theta) = 0` and
:math:`\dot q = v`, :math:`\dot p = -kq - aq^3 - \gamma v`,
:math:`\dot s = \gamma v^2/\theta \ge 0`.
"""

from __future__ import annotations

import dataclasses

from ..._model import GenericModel
from ..._types import Matrix, Scalar, State
from ...structure import CanonicalPoisson, SumOf
from .._base import BoxSampling, System, analytic_model
from ._case import ZooCase, case_settings
from ._parts import bath_energy, bath_heating, check_signs, oscillator_energy, oscillator_frequency


@dataclasses.dataclass(frozen=True)
class OscillatorBathConfig:
    r"""Parameters of the Duffing oscillator in a bath (SI units, seconds).

    ``mass`` :math:`m` = 1 kg, ``stiffness`` :math:`k` = 4 N/m (small-amplitude period
    :math:`\pi` s), ``quartic`` :math:`a` = 1 N/m³ (hardening), ``damping`` :math:`\gamma` =
    0.1 kg/s, bath ``heat_capacity`` :math:`c` = 2 J/K and reference temperature ``theta0``
    :math:`\theta_0` = 1 K. Initial states ``x0_center + U(-1, 1) * x0_halfwidth``, by default
    :math:`(0, 0, 0) + U(-1,1)\cdot(1.5, 2, 0.2)`.
    """

    mass: float = 1.0
    stiffness: float = 4.0
    quartic: float = 1.0
    damping: float = 0.1
    heat_capacity: float = 2.0
    theta0: float = 1.0
    x0_center: tuple[float, float, float] = (0.0, 0.0, 0.0)
    x0_halfwidth: tuple[float, float, float] = (1.5, 2.0, 0.2)

    def __post_init__(self):
        check_signs(self, "oscillator-bath",
                    positive=("mass", "stiffness", "heat_capacity", "theta0"),
                    nonnegative=("quartic", "damping"), example="stiffness=4, damping=0.1")


def _energy(c: OscillatorBathConfig, x: State) -> Scalar:
    return oscillator_energy(c, x[0], x[1]) + bath_energy(x[2], c.heat_capacity, c.theta0)


def _friction(c: OscillatorBathConfig, x: State) -> Matrix:
    return bath_heating(c, c.damping, x[2], x[1:2] / c.mass)


@dataclasses.dataclass(frozen=True)
class OscillatorBath(BoxSampling, System):
    """A hardening Duffing oscillator with viscous friction that heats one bath (n = 3)."""

    name = "oscillator-bath"
    description = (
        "Duffing oscillator (k q^2/2 + a q^4/4) with friction heating a bath: canonical L in "
        "(q, p), S = s, M = (gamma/theta) w w^T with w = (0, theta, -v)."
    )
    names = ("q", "p", "s")
    defaults = case_settings(dt=0.022, steps=300, trajectories=32)
    config: OscillatorBathConfig = OscillatorBathConfig()

    @property
    def max_substep(self) -> float:
        return float(min(0.005, 0.01 / oscillator_frequency(self.config)))

    def _build_model(self) -> GenericModel:
        return analytic_model(self.config, energy=_energy, entropy=SumOf((2,)),
                              poisson=CanonicalPoisson(3, 1), friction=_friction)


CASE = ZooCase.of(
    OscillatorBath(),
    {"poisson": "canonical:1", "entropy": "sum:2"},
    held_out=False,
    note="Smallest nonlinear dissipative case: amplitude-dependent frequency, one heated bath.",
)
