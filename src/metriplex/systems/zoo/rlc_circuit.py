r"""A nonlinear LC circuit whose resistor heats a small thermal mass.

State :math:`x = (Q, \Phi, s)`: capacitor charge (C), inductor flux linkage (Wb) and the
resistor's entropy (J/K), in SI units with time in seconds (periods of a few ms). With current
:math:`I = \Phi/L_{\rm ind}` and temperature :math:`\theta = U'(s) = \theta_0 e^{s/c}`,

.. math::
    E = \frac{Q^2}{2C} + \frac{bQ^4}{4} + \frac{\Phi^2}{2L_{\rm ind}}
        + c\,\theta_0\big(e^{s/c}-1\big),\qquad S = s,

canonical :math:`L` in the pair :math:`(Q, \Phi)` and the resistor through
:math:`M = \frac R\theta w w^\top`, :math:`w = (0,\ \theta,\ -I)`, so

.. math::
    \dot Q = \partial_\Phi E = I,\qquad
    \dot\Phi = -\partial_Q E - RI = -V_C(Q) - RI,\qquad \dot s = RI^2/\theta \ge 0,

i.e. Kirchhoff's voltage law :math:`L_{\rm ind}\dot I + RI + V_C = 0` with the nonlinear
capacitor :math:`V_C = Q/C + bQ^3`, and Joule heating of the thermal mass.
"""

from __future__ import annotations

import dataclasses

from ..._model import GenericModel
from ..._types import Matrix, Scalar, State
from ...structure import CanonicalPoisson, SumOf
from .._base import BoxSampling, System, analytic_model
from ._case import ZooCase, case_settings
from ._parts import bath_energy, bath_heating, check_signs, hardening_frequency


@dataclasses.dataclass(frozen=True)
class RLCCircuitConfig:
    r"""Parameters of the circuit (SI units).

    ``capacitance`` :math:`C` = 1 mF, ``inductance`` :math:`L_{\rm ind}` = 0.625 mH (linear
    period 4.97 ms), capacitor ``nonlinearity`` :math:`b` = 5e8 V/C³ (stiffening: at 1 mC the
    cubic term is half the linear one), ``resistance`` :math:`R` = 0.025 Ω, thermal mass of
    ``heat_capacity`` :math:`c` = 1e-4 J/K at ``theta0`` = 300 K. Initial states
    ``x0_center + U(-1, 1) * x0_halfwidth``, by default charge within ±1 mC, flux within
    ±0.8 mWb and :math:`s` within ±2e-7 J/K.
    """

    capacitance: float = 1.0e-3
    inductance: float = 6.25e-4
    nonlinearity: float = 5.0e8
    resistance: float = 0.025
    heat_capacity: float = 1.0e-4
    theta0: float = 300.0
    x0_center: tuple[float, float, float] = (0.0, 0.0, 0.0)
    x0_halfwidth: tuple[float, float, float] = (1.0e-3, 8.0e-4, 2.0e-7)

    def __post_init__(self):
        check_signs(self, "rlc-circuit",
                    positive=("capacitance", "inductance", "heat_capacity", "theta0"),
                    nonnegative=("nonlinearity", "resistance"), example="resistance=0.025")


def _energy(c: RLCCircuitConfig, x: State) -> Scalar:
    Q, Phi, s = x[0], x[1], x[2]
    capacitor = Q**2 / (2.0 * c.capacitance) + 0.25 * c.nonlinearity * Q**4
    inductor = Phi**2 / (2.0 * c.inductance)
    return capacitor + inductor + bath_energy(s, c.heat_capacity, c.theta0)


def _friction(c: RLCCircuitConfig, x: State) -> Matrix:
    return bath_heating(c, c.resistance, x[2], x[1:2] / c.inductance)


@dataclasses.dataclass(frozen=True)
class RLCCircuit(BoxSampling, System):
    """A series RLC circuit with a stiffening capacitor; the resistor heats a thermal mass."""

    name = "rlc-circuit"
    description = (
        "Series RLC circuit, capacitor energy Q^2/2C + b Q^4/4, inductor Phi^2/2L; the "
        "resistor heats a thermal mass: canonical L in (Q, Phi), S = s (SI units, ms periods)."
    )
    names = ("Q", "Phi", "s")
    defaults = case_settings(dt=3.5e-5, steps=300, trajectories=32)
    config: RLCCircuitConfig = RLCCircuitConfig()

    @property
    def max_substep(self) -> float:
        c = self.config
        omega = hardening_frequency(1.0 / c.capacitance, c.nonlinearity, c.inductance,
                                    c.x0_center, c.x0_halfwidth)
        return float(0.01 / omega)

    def _build_model(self) -> GenericModel:
        return analytic_model(self.config, energy=_energy, entropy=SumOf((2,)),
                              poisson=CanonicalPoisson(3, 1), friction=_friction)


CASE = ZooCase.of(
    RLCCircuit(),
    {"poisson": "canonical:1", "entropy": "sum:2"},
    time_unit="s (period ~ms)",
    held_out=True,
    note="Tiny SI scales (Q ~ 1e-3 C, s ~ 1e-6 J/K, t ~ 1e-2 s, theta ~ 300 K) in one model.",
)
