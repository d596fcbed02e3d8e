r"""A satellite spinning about its major axis whose nutation damper turns wobble into heat.

State :math:`x = (m_1, m_2, m_3, s)`: body angular momentum and damper entropy; time in
hours. With :math:`\Omega = \partial E/\partial m = I^{-1}m`, damper temperature
:math:`\theta = U'(s) = \theta_0 e^{s/c}` and :math:`A(m)v = m\times v`,

.. math::
    E = \tfrac12\sum_i \frac{m_i^2}{I_i} + c\,\theta_0\big(e^{s/c} - 1\big),\qquad S = s,
    \qquad L = \begin{pmatrix} -\varepsilon m & 0\\ 0 & 0\end{pmatrix}\ \text{(Lie–Poisson on } m),

.. math::
    M = \frac{\gamma}{\theta} K K^\top,\qquad
    K = \begin{pmatrix} \theta A^\top \\ -\Omega^\top A^\top\end{pmatrix}\ (4\times 3),\qquad
    M = \gamma\begin{pmatrix} \theta A^\top A & -A^\top A\,\Omega\\
        -\Omega^\top A^\top A & \Omega^\top A^\top A\,\Omega/\theta\end{pmatrix},

so :math:`K^\top\nabla E = \theta A\Omega - A\Omega\,\theta = 0` gives :math:`M\nabla E = 0`,
:math:`M` is PSD for :math:`\theta > 0`, and :math:`L\nabla S = 0`. With
:math:`A^\top A = -A^2` the equations of motion are

.. math::
    \dot m = m\times\Omega + \gamma\, m\times(m\times\Omega),\qquad
    \dot s = \frac{\gamma}{\theta}\,|m\times\Omega|^2 \ge 0 .

The double bracket keeps :math:`|m|^2` (:math:`m\cdot\dot m = 0`) and lowers the kinetic
energy at the rate :math:`\gamma|m\times\Omega|^2`, which the damper absorbs as heat: the
total energy is conserved, and the spin settles onto the major axis :math:`m_3`.
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np

from ..._errors import MetriplexError
from ..._model import GenericModel
from ..._types import Matrix, Scalar, State
from ...structure import KnownPoisson, SumOf
from .._base import BoxSampling, System, analytic_model
from ..rigid_body import _lie_poisson, _rotational_energy
from ._case import ZooCase, case_settings
from ._parts import bath_energy, bath_temperature, check_signs


@dataclasses.dataclass(frozen=True)
class SpinningSatelliteConfig:
    r"""Parameters of the damped spinning satellite (kg m², hours).

    - ``inertia`` :math:`(I_1, I_2, I_3)` = (800, 900, 1000) kg m², :math:`I_3` the largest
      (spin about the major axis is the stable end state);
    - ``damping`` :math:`\gamma` = 1e-5 (per kg m² per hour): with :math:`m_3 \approx 10^4`
      the wobble decays at about :math:`\gamma m_3^2 (1/I_{1,2} - 1/I_3)`, 0.1–0.25 per hour;
    - damper ``heat_capacity`` :math:`c` = 1 and ``theta0`` :math:`\theta_0` = 1 (energy in
      kg m²/h², entropy in the matching unit);
    - initial states ``x0_center + U(-1, 1) * x0_halfwidth``, by default
      :math:`(0, 0, 10^4, 0) + U(-1,1)\cdot(80, 80, 100, 0.25)`: a spin of about 10 rad/h
      with a wobble of up to 0.6°, whose nutation period is about 3.8 h.
    """

    inertia: tuple[float, float, float] = (800.0, 900.0, 1000.0)
    damping: float = 1e-5
    heat_capacity: float = 1.0
    theta0: float = 1.0
    x0_center: tuple[float, float, float, float] = (0.0, 0.0, 1e4, 0.0)
    x0_halfwidth: tuple[float, float, float, float] = (80.0, 80.0, 100.0, 0.25)

    def __post_init__(self):
        I1, I2, I3 = self.inertia
        if not (min(self.inertia) > 0.0 and I3 > max(I1, I2)):
            raise MetriplexError(
                "spinning-satellite inertia must be positive with I3 the strictly largest "
                f"(the spin axis is the major axis); got inertia={self.inertia}. "
                "Example: inertia=(800, 900, 1000)."
            )
        check_signs(self, "spinning-satellite", positive=("heat_capacity", "theta0"),
                    nonnegative=("damping",),
                    example="damping=1e-5, heat_capacity=1, theta0=1")

    @property
    def nutation_frequency(self) -> float:
        r"""Small-wobble nutation frequency :math:`|m_3|\sqrt{(1/I_1 - 1/I_3)(1/I_2 - 1/I_3)}`
        at the centre's :math:`m_3` (rad per hour)."""
        I1, I2, I3 = self.inertia
        m3 = abs(self.x0_center[2]) + abs(self.x0_halfwidth[2])
        return float(m3 * np.sqrt((1.0 / I1 - 1.0 / I3) * (1.0 / I2 - 1.0 / I3)))


def damper_temperature(config: SpinningSatelliteConfig, s: Scalar) -> Scalar:
    r""":math:`\theta = \theta_0 e^{s/c}`."""
    return bath_temperature(s, config.heat_capacity, config.theta0)


def _energy(c: SpinningSatelliteConfig, x: State) -> Scalar:
    return _rotational_energy(c, x[:3]) + bath_energy(x[3], c.heat_capacity, c.theta0)


def _poisson(x: State) -> Matrix:
    return jnp.zeros((4, 4), x.dtype).at[:3, :3].set(_lie_poisson(x[:3]))


def _friction(c: SpinningSatelliteConfig, x: State) -> Matrix:
    m = x[:3]
    omega = m / jnp.asarray(c.inertia, dtype=x.dtype)
    theta = damper_temperature(c, x[3])
    # A v = m x v. Form A^T A, A^T A Omega = A^T (m x Omega) and |m x Omega|^2 from A and
    # m x Omega rather than from |m|^2 1 - m m^T: with |m| ~ 1e4 that form cancels ~1e8-sized
    # terms and loses ~1e-11 of the (small) wobble dissipation.
    A = _lie_poisson(m)
    a = A @ omega
    G = A.T @ A
    g = A.T @ a
    top = jnp.concatenate([theta * G, -g[:, None]], axis=1)
    bottom = jnp.concatenate([-g, (jnp.dot(a, a) / theta)[None]])[None, :]
    return c.damping * jnp.concatenate([top, bottom], axis=0)


@dataclasses.dataclass(frozen=True)
class SpinningSatellite(BoxSampling, System):
    """A major-axis spinner with a nutation damper (n = 4): offset m3 ~ 1e4, hours."""

    name = "spinning-satellite"
    description = (
        "Rigid body spinning about its major axis with a nutation damper (hours): Lie-Poisson "
        "L on m, E = sum m_i^2/(2 I_i) + U(s), S = s, double-bracket M that keeps |m|^2 and "
        "turns the wobble's energy into damper heat."
    )
    names = ("m1", "m2", "m3", "s")
    defaults = case_settings(dt=0.03, steps=300, trajectories=32)
    config: SpinningSatelliteConfig = SpinningSatelliteConfig()

    @property
    def max_substep(self) -> float:
        return min(0.01, 0.005 / self.config.nutation_frequency)

    def _build_model(self) -> GenericModel:
        return analytic_model(self.config, energy=_energy, entropy=SumOf((3,)),
                              poisson=KnownPoisson(_poisson), friction=_friction)


CASE = ZooCase.of(
    SpinningSatellite(),
    {"entropy": "sum:3"},
    time_unit="h",
    held_out=False,
    note="Lie-Poisson L and a double-bracket M to learn on a state with a 1e4 offset whose "
    "wobble (1e1-1e2) decays into heat.",
)
