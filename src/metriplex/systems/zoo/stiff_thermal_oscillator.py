r"""A spring–mass oscillator whose friction heats a small reservoir that conducts heat quickly
to a second one: a stiff GENERIC system.

State :math:`x = (q, p, s_1, s_2)`: position, momentum and the two reservoirs' entropies (SI
units, seconds). With velocity :math:`v = p/m` and temperatures
:math:`\theta_i = U_i'(s_i) = \theta_0 e^{s_i/c_i}`,

.. math::
    E = \frac{p^2}{2m} + \frac{k q^2}{2} + \frac{a q^4}{4} + \sum_i c_i\theta_0\big(e^{s_i/c_i}
    - 1\big),\qquad S = s_1 + s_2,\qquad L\ \text{canonical in}\ (q, p),

.. math::
    M = \frac{\Gamma}{\theta_1}\, u u^\top + \kappa\,\theta_1\theta_2\, w w^\top,\qquad
    u = (0,\ \theta_1,\ -v,\ 0),\quad w = (0,\ 0,\ 1/\theta_1,\ -1/\theta_2),

i.e. the block :math:`\begin{pmatrix}\Gamma\theta_1 & -\Gamma v\\ -\Gamma v &
\Gamma v^2/\theta_1\end{pmatrix}` on :math:`(p, s_1)` plus Fourier conduction on
:math:`(s_1, s_2)`. Both parts annihilate :math:`\nabla E = (kq + aq^3,\ v,\ \theta_1,\
\theta_2)`, and

.. math::
    \dot q = v,\quad \dot p = -kq - aq^3 - \Gamma v,\quad
    \dot s_1 = \frac{\Gamma v^2}{\theta_1} + \kappa\Big(\frac{\theta_2}{\theta_1} - 1\Big),\quad
    \dot s_2 = \kappa\Big(\frac{\theta_1}{\theta_2} - 1\Big).

Temperature differences relax at the rate :math:`\lambda = \kappa(1/c_1 + 1/c_2)` (exactly:
:math:`\frac{d}{dt}(\theta_1 - \theta_2) = -\lambda(\theta_1 - \theta_2) + \Gamma v^2/c_1`), by
default 50 times the small-amplitude angular frequency :math:`\sqrt{k/m}`.
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np
from jaxtyping import Float

from ..._errors import MetriplexError
from ..._model import GenericModel
from ..._types import Array, Matrix, Scalar, State
from ...structure import CanonicalPoisson, SumOf
from .._base import System, _uniform_box, analytic_model
from ._case import ZooCase, case_settings
from ._parts import (
    bath_energy,
    bath_temperature,
    check_signs,
    oscillator_energy,
    oscillator_frequency,
)


@dataclasses.dataclass(frozen=True)
class StiffThermalOscillatorConfig:
    r"""Parameters of the stiff thermal oscillator (SI units, seconds).

    - ``mass`` :math:`m` = 1 kg, ``stiffness`` :math:`k` = 1 N/m, ``quartic`` :math:`a` =
      0.25 N/m³ (hardening), ``friction`` :math:`\Gamma` = 0.15 kg/s;
    - reservoir ``heat_capacity`` :math:`(c_1, c_2)` = (0.01, 0.02) J/K at ``theta0``
      :math:`\theta_0` = 300 K (entropies measured from :math:`\theta_0`, so they are of order
      1e-3 J/K), conductance ``kappa`` :math:`\kappa` = 1/3 W/K: relaxation rate
      :math:`\lambda = 50` /s, 50 times :math:`\sqrt{k/m}`;
    - initial :math:`(q, p, s_1)` = ``x0_center + U(-1, 1) * x0_halfwidth``, by default
      :math:`(0, 0, 0) + U(-1,1)\cdot(1.2, 1.2, 10^{-3})` (:math:`\theta_1` within 300 ± 30 K),
      and :math:`s_2` such that :math:`\theta_2 = \theta_1 (1 + \text{imbalance}\cdot U(-1, 1))`,
      ``imbalance`` = 2e-3 (reservoirs start near equilibrium, as the fast conduction keeps
      them; friction heating then warms both by up to about 40 K).
    """

    mass: float = 1.0
    stiffness: float = 1.0
    quartic: float = 0.25
    friction: float = 0.15
    heat_capacity: tuple[float, float] = (0.01, 0.02)
    theta0: float = 300.0
    kappa: float = 1.0 / 3.0
    x0_center: tuple[float, float, float] = (0.0, 0.0, 0.0)
    x0_halfwidth: tuple[float, float, float] = (1.2, 1.2, 1e-3)
    imbalance: float = 2e-3

    def __post_init__(self):
        check_signs(self, "stiff-thermal-oscillator",
                    positive=("mass", "stiffness", "heat_capacity", "theta0", "kappa"),
                    nonnegative=("quartic", "friction"), example="kappa=0.3333, friction=0.15")
        if not 0.0 <= self.imbalance < 0.5:
            raise MetriplexError(
                "stiff-thermal-oscillator's initial temperature imbalance must be in [0, 0.5) "
                f"(a relative difference theta2/theta1 - 1); got imbalance={self.imbalance}. "
                "Example: imbalance=0.002."
            )

    @property
    def conduction_rate(self) -> float:
        r""":math:`\lambda = \kappa(1/c_1 + 1/c_2)`, per second."""
        return self.kappa * (1.0 / self.heat_capacity[0] + 1.0 / self.heat_capacity[1])

    @property
    def stiffness_ratio(self) -> float:
        r""":math:`\lambda / \sqrt{k/m}`."""
        return self.conduction_rate / float(np.sqrt(self.stiffness / self.mass))


def reservoir_temperatures(config: StiffThermalOscillatorConfig,
                           s: Float[Array, "*batch 2"]) -> Float[Array, "*batch 2"]:
    r""":math:`\theta_i = \theta_0 e^{s_i/c_i}` for ``s`` of shape ``(..., 2)``."""
    return bath_temperature(s, jnp.asarray(config.heat_capacity, dtype=s.dtype), config.theta0)


def _energy(c: StiffThermalOscillatorConfig, x: State) -> Scalar:
    C = jnp.asarray(c.heat_capacity, dtype=x.dtype)
    return oscillator_energy(c, x[0], x[1]) + jnp.sum(bath_energy(x[2:4], C, c.theta0))


def _friction(c: StiffThermalOscillatorConfig, x: State) -> Matrix:
    z = jnp.zeros((), x.dtype)
    v = x[1] / c.mass
    th = reservoir_temperatures(c, x[2:4])
    u = jnp.stack([z, th[0], -v, z])
    # kappa th1 th2 w w^T with w = (0, 0, 1/th1, -1/th2), written as (0, 0, th2, -th1).
    w = jnp.stack([z, z, th[1], -th[0]])
    friction = (c.friction / th[0]) * (u[:, None] * u[None, :])
    conduction = (c.kappa / (th[0] * th[1])) * (w[:, None] * w[None, :])
    return friction + conduction


@dataclasses.dataclass(frozen=True)
class StiffThermalOscillator(System):
    """Oscillator, friction into reservoir 1, fast conduction 1 -> 2 (n = 4): stiff."""

    name = "stiff-thermal-oscillator"
    description = (
        "Hardening oscillator whose friction heats reservoir 1, which conducts to reservoir 2 "
        "50x faster than the oscillation: canonical L in (q, p), S = s1 + s2, M = friction "
        "block on (p, s1) + Fourier conduction on (s1, s2)."
    )
    names = ("q", "p", "s1", "s2")
    defaults = case_settings(dt=0.05, steps=300, trajectories=32)
    config: StiffThermalOscillatorConfig = StiffThermalOscillatorConfig()

    @property
    def max_substep(self) -> float:
        # RK4 needs h * lambda well inside its stability region and accurate: h * lambda <= 0.1.
        c = self.config
        return min(0.01 / oscillator_frequency(c), 0.1 / c.conduction_rate)

    def _build_model(self) -> GenericModel:
        return analytic_model(self.config, energy=_energy, entropy=SumOf((2, 3)),
                              poisson=CanonicalPoisson(4, 1), friction=_friction)

    def sample_initial(self, num: int, *, seed: int) -> Float[np.ndarray, "num 4"]:
        r"""``(q, p, s1)`` uniform in the box, then :math:`s_2` from
        :math:`\theta_2 = \theta_1(1 + \text{imbalance}\cdot U(-1, 1))` (see the config)."""
        self._check_num(num)
        c = self.config
        rng = np.random.default_rng(seed)
        qps = _uniform_box(rng, c.x0_center, c.x0_halfwidth, num)
        ratio = 1.0 + c.imbalance * rng.uniform(-1.0, 1.0, size=num)
        c1, c2 = c.heat_capacity
        s2 = c2 * (qps[:, 2] / c1 + np.log(ratio))
        return np.concatenate([qps, s2[:, None]], axis=1)


CASE = ZooCase.of(
    StiffThermalOscillator(),
    {"poisson": "canonical:1", "entropy": "sum:2,3"},
    held_out=True,
    note="Stiff: conduction 50x faster than the oscillation (2.5 per data step), entropies "
    "of order 1e-3 J/K at 300 K.",
)
