r"""Two bodies exchanging heat by Fourier conduction: the purely dissipative GENERIC system.

State :math:`x = (s_1, s_2)`, the bodies' entropies (J/K), time in hours. Each body has a
constant heat capacity :math:`C_i`, so with temperature :math:`T_i = U_i'(s_i)`,

.. math::
    U_i(s_i) = C_i T_0\, e^{(s_i - s_{0i})/C_i},\qquad T_i = T_0\, e^{(s_i - s_{0i})/C_i},
    \qquad E = U_1 + U_2,\qquad S = s_1 + s_2,\qquad L = 0,

.. math::
    M = \kappa\, T_1 T_2\, w w^\top,\qquad w = (1/T_1,\ -1/T_2),

so :math:`M\nabla E = \kappa T_1T_2\, w\,(T_1/T_1 - T_2/T_2) = 0` and

.. math::
    \dot s_1 = \kappa\Big(\frac{T_2}{T_1} - 1\Big),\qquad
    \dot s_2 = \kappa\Big(\frac{T_1}{T_2} - 1\Big),\qquad
    \dot S = \kappa\frac{(T_1 - T_2)^2}{T_1T_2} \ge 0 .

The heat flow :math:`\kappa (T_2 - T_1)` (J/h) makes the temperature difference decay
exactly exponentially, :math:`\frac{d}{dt}(T_1 - T_2) = -\kappa(1/C_1 + 1/C_2)(T_1 - T_2)`,
with relaxation time :math:`\tau = 1/(\kappa(1/C_1 + 1/C_2))`; the entropies, logarithms of
the temperatures, relax non-exponentially.
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp

from ..._errors import MetriplexError
from ..._model import GenericModel
from ..._types import Matrix, Scalar, State
from ...structure import SumOf, ZeroPoisson
from .._base import BoxSampling, System, analytic_model
from ._case import ZooCase, case_settings


@dataclasses.dataclass(frozen=True)
class HeatExchangeConfig:
    r"""Parameters of the two heat-exchanging bodies (J, K, hours).

    ``heat_capacity`` :math:`(C_1, C_2)` = (4000, 2000) J/K (about 1 kg and 0.5 kg of water),
    reference temperature ``temperature`` :math:`T_0` = 300 K, ``entropy_offset``
    :math:`(s_{01}, s_{02})` = (12000, 8000) J/K (the entropies at :math:`T_0`), conductance
    ``kappa`` :math:`\kappa` = 600 J/(K h), so :math:`\tau \approx 2.2` h. Initial states
    ``x0_center + U(-1, 1) * x0_halfwidth``, by default the offsets ± 60 J/K (temperatures
    within about ±4.5 K and ±9 K of :math:`T_0`).
    """

    heat_capacity: tuple[float, float] = (4000.0, 2000.0)
    temperature: float = 300.0
    entropy_offset: tuple[float, float] = (12000.0, 8000.0)
    kappa: float = 600.0
    x0_center: tuple[float, float] = (12000.0, 8000.0)
    x0_halfwidth: tuple[float, float] = (60.0, 60.0)

    def __post_init__(self):
        if not (min(self.heat_capacity) > 0.0 and self.temperature > 0.0 and self.kappa > 0.0):
            raise MetriplexError(
                "heat-exchange needs positive heat capacities, reference temperature and "
                f"conductance; got heat_capacity={self.heat_capacity}, "
                f"temperature={self.temperature}, kappa={self.kappa}. "
                "Example: heat_capacity=(4000, 2000), temperature=300, kappa=600."
            )
        spread = max(abs(h) / c for h, c in zip(self.x0_halfwidth, self.heat_capacity))
        if spread > 2.0:
            raise MetriplexError(
                "heat-exchange initial entropies must stay within 2 heat capacities of the "
                f"centre (temperatures within a factor e^2); got x0_halfwidth={self.x0_halfwidth} "
                f"with heat_capacity={self.heat_capacity}. Narrow x0_halfwidth."
            )

    @property
    def relaxation_time(self) -> float:
        r""":math:`\tau = 1/(\kappa(1/C_1 + 1/C_2))` in hours."""
        return 1.0 / (self.kappa * (1.0 / self.heat_capacity[0] + 1.0 / self.heat_capacity[1]))


def temperatures(config: HeatExchangeConfig, x: State) -> State:
    r""":math:`T_i = T_0 e^{(s_i - s_{0i})/C_i}`."""
    C = jnp.asarray(config.heat_capacity, dtype=x.dtype)
    s0 = jnp.asarray(config.entropy_offset, dtype=x.dtype)
    return config.temperature * jnp.exp((x - s0) / C)


def _energy(c: HeatExchangeConfig, x: State) -> Scalar:
    C = jnp.asarray(c.heat_capacity, dtype=x.dtype)
    return jnp.sum(C * temperatures(c, x))


def _friction(c: HeatExchangeConfig, x: State) -> Matrix:
    T = temperatures(c, x)
    # kappa T1 T2 w w^T with w = (1/T1, -1/T2), written without the divisions.
    u = jnp.stack([T[1], -T[0]])
    return (c.kappa / (T[0] * T[1])) * (u[:, None] * u[None, :])


@dataclasses.dataclass(frozen=True)
class HeatExchange(BoxSampling, System):
    """Two bodies exchanging heat (n = 2): no reversible part, large entropy offsets, hours."""

    name = "heat-exchange"
    description = (
        "Two bodies with constant heat capacities exchanging heat (hours, J/K): L = 0, "
        "E = sum C_i T0 exp((s_i - s0_i)/C_i), S = s1 + s2, M = kappa T1 T2 w w^T, "
        "w = (1/T1, -1/T2)."
    )
    names = ("s1", "s2")
    defaults = case_settings(dt=0.05, steps=200, trajectories=24)
    config: HeatExchangeConfig = HeatExchangeConfig()

    @property
    def max_substep(self) -> float:
        # The fastest rate is ~ 1/tau (times the temperature ratio, within e^±4 by validation).
        return min(0.01, 0.005 * self.config.relaxation_time)

    def _build_model(self) -> GenericModel:
        return analytic_model(self.config, energy=_energy, entropy=SumOf((0, 1)),
                              poisson=ZeroPoisson(2), friction=_friction)


CASE = ZooCase.of(
    HeatExchange(),
    {"poisson": "zero", "entropy": "sum:0,1"},
    time_unit="h",
    held_out=True,
    note="Pure dissipation with L = 0 on states ~1e4 that move by tens: offsets and scaling.",
)
