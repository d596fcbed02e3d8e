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

import jax.numpy as jnp
import numpy as np
from jaxtyping import Float

from ..._errors import MetriplexError
from ..._model import GenericModel
from ..._types import Matrix, Scalar, State
from ...structure import CanonicalPoisson, Known, KnownFriction, SumOf
from .._base import Settings, System, _sample_box
from ._case import ZooCase


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
        positive = (self.capacitance, self.inductance, self.heat_capacity, self.theta0)
        if not (min(positive) > 0.0 and self.nonlinearity >= 0.0 and self.resistance >= 0.0):
            raise MetriplexError(
                "rlc-circuit needs positive capacitance, inductance, heat_capacity and theta0 "
                f"and non-negative nonlinearity and resistance; got "
                f"capacitance={self.capacitance}, inductance={self.inductance}, "
                f"nonlinearity={self.nonlinearity}, resistance={self.resistance}, "
                f"heat_capacity={self.heat_capacity}, theta0={self.theta0}. "
                "Example: resistance=0.025."
            )


@dataclasses.dataclass(frozen=True)
class _Energy:
    config: RLCCircuitConfig

    def __call__(self, x: State) -> Scalar:
        c = self.config
        Q, Phi, s = x[0], x[1], x[2]
        capacitor = Q**2 / (2.0 * c.capacitance) + 0.25 * c.nonlinearity * Q**4
        inductor = Phi**2 / (2.0 * c.inductance)
        heat = c.heat_capacity * c.theta0 * jnp.expm1(s / c.heat_capacity)
        return capacitor + inductor + heat


@dataclasses.dataclass(frozen=True)
class _Friction:
    config: RLCCircuitConfig

    def __call__(self, x: State) -> Matrix:
        c = self.config
        current = x[1] / c.inductance
        theta = c.theta0 * jnp.exp(x[2] / c.heat_capacity)
        w = jnp.stack([jnp.zeros((), x.dtype), theta, -current])
        return (c.resistance / theta) * (w[:, None] * w[None, :])


@dataclasses.dataclass(frozen=True)
class RLCCircuit(System):
    """A series RLC circuit with a stiffening capacitor; the resistor heats a thermal mass."""

    name = "rlc-circuit"
    description = (
        "Series RLC circuit, capacitor energy Q^2/2C + b Q^4/4, inductor Phi^2/2L; the "
        "resistor heats a thermal mass: canonical L in (Q, Phi), S = s (SI units, ms periods)."
    )
    config: RLCCircuitConfig = RLCCircuitConfig()

    @property
    def max_substep(self) -> float:
        c = self.config
        Q = abs(c.x0_center[0]) + abs(c.x0_halfwidth[0])
        omega = np.sqrt((1.0 / c.capacitance + 3.0 * c.nonlinearity * Q**2) / c.inductance)
        return float(0.01 / omega)

    @property
    def names(self) -> tuple[str, ...]:
        return ("Q", "Phi", "s")

    def _build_model(self) -> GenericModel:
        return GenericModel(
            energy=Known(_Energy(self.config)),
            entropy=SumOf((2,)),
            poisson=CanonicalPoisson(3, 1),
            friction=KnownFriction(_Friction(self.config)),
        )

    @property
    def defaults(self) -> Settings:
        return Settings(CASE_DT, CASE_STEPS, CASE_TRAJECTORIES, "zoo case (our choice)")

    def sample_initial(self, num: int, *, seed: int) -> Float[np.ndarray, "num 3"]:
        """``x0_center + U(-1, 1) * x0_halfwidth`` per component."""
        self._check_num(num)
        return _sample_box(self.config.x0_center, self.config.x0_halfwidth, num, seed)


CASE_DT, CASE_STEPS, CASE_TRAJECTORIES = 3.5e-5, 300, 32

CASE = ZooCase(
    system=RLCCircuit(),
    flags={"poisson": "canonical:1", "entropy": "sum:2"},
    trajectories=CASE_TRAJECTORIES,
    steps=CASE_STEPS,
    dt=CASE_DT,
    time_unit="s (period ~ms)",
    test_trajectories=10,
    held_out=True,
    note="Tiny SI scales (Q ~ 1e-3 C, s ~ 1e-6 J/K, t ~ 1e-2 s, theta ~ 300 K) in one model.",
)
