r"""A rigid planar double pendulum under gravity whose joint friction heats one reservoir.

State :math:`x = (\varphi_1, \varphi_2, p_1, p_2, s)`: absolute angles from the downward
vertical, their conjugate momenta and the reservoir's entropy. With the mass matrix

.. math::
    \mathsf M(\varphi) = \begin{pmatrix} (m_1+m_2)l_1^2 & m_2 l_1 l_2\cos(\varphi_1-\varphi_2)\\
    m_2 l_1 l_2\cos(\varphi_1-\varphi_2) & m_2 l_2^2\end{pmatrix},\qquad
    \omega = \mathsf M(\varphi)^{-1} p,

.. math::
    E = \tfrac12 p^\top\mathsf M^{-1}p + (m_1+m_2)g l_1(1-\cos\varphi_1)
        + m_2 g l_2 (1-\cos\varphi_2) + c\,\theta_0\big(e^{s/c}-1\big),\qquad S = s,

canonical :math:`L` in :math:`(\varphi, p)`, and joint friction on the pivot rate
:math:`\omega_1` and the elbow's relative rate :math:`\omega_2-\omega_1`,
:math:`\Gamma = A^\top \mathrm{diag}(\gamma_1, \gamma_2) A` with
:math:`A = \begin{pmatrix}1&0\\-1&1\end{pmatrix}`:

.. math::
    M = \frac1\theta\,W\Gamma W^\top,\qquad W = \begin{pmatrix}0\\ \theta I_2\\ -\omega^\top
    \end{pmatrix}\ (5\times 2),

so :math:`\dot p = -\partial_\varphi E - \Gamma\omega` and
:math:`\dot s = \omega^\top\Gamma\omega/\theta \ge 0`, :math:`\theta = \theta_0 e^{s/c}`.
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np

from ..._model import GenericModel
from ..._types import Matrix, Scalar, State
from ...structure import CanonicalPoisson, SumOf
from .._base import BoxSampling, System, analytic_model
from ._case import ZooCase, case_settings
from ._parts import bath_energy, bath_temperature, check_signs, heating_factor


@dataclasses.dataclass(frozen=True)
class DoublePendulumFrictionConfig:
    r"""Parameters of the double pendulum with joint friction (SI units).

    ``masses`` (1, 0.5) kg and ``lengths`` (1, 1) m (normal-mode periods 2.52 s and 1.30 s),
    ``gravity`` 9.81 m/s², joint ``friction`` :math:`(\gamma_1, \gamma_2)` = (0.1, 0.05) N m s,
    reservoir ``heat_capacity`` :math:`c` = 0.05 J/K at ``theta0`` = 300 K. Initial states
    ``x0_center + U(-1, 1) * x0_halfwidth``, by default angles within ±0.6 rad, momenta within
    (±0.6, ±0.3) kg m²/s and :math:`s` within ±0.001 J/K: a regular (non-chaotic) regime.
    """

    masses: tuple[float, float] = (1.0, 0.5)
    lengths: tuple[float, float] = (1.0, 1.0)
    gravity: float = 9.81
    friction: tuple[float, float] = (0.1, 0.05)
    heat_capacity: float = 0.05
    theta0: float = 300.0
    x0_center: tuple[float, float, float, float, float] = (0.0, 0.0, 0.0, 0.0, 0.0)
    x0_halfwidth: tuple[float, float, float, float, float] = (0.6, 0.6, 0.6, 0.3, 0.001)

    def __post_init__(self):
        check_signs(self, "double-pendulum-friction", positive=("masses", "lengths"),
                    example="masses=(1, 0.5)")
        check_signs(self, "double-pendulum-friction", nonnegative=("gravity", "friction"),
                    example="friction=(0.1, 0.05)")
        check_signs(self, "double-pendulum-friction", positive=("heat_capacity", "theta0"),
                    example="heat_capacity=0.05, theta0=300")


def _inverse_mass(c: DoublePendulumFrictionConfig, x: State):
    """The entries ``(a, b, d)`` of the mass matrix and its determinant."""
    (m1, m2), (l1, l2) = c.masses, c.lengths
    a = jnp.asarray((m1 + m2) * l1**2, x.dtype)
    b = m2 * l1 * l2 * jnp.cos(x[0] - x[1])
    d = jnp.asarray(m2 * l2**2, x.dtype)
    return a, b, d, a * d - b**2


def _velocities(c: DoublePendulumFrictionConfig, x: State) -> State:
    a, b, d, det = _inverse_mass(c, x)
    return jnp.stack([d * x[2] - b * x[3], a * x[3] - b * x[2]]) / det


def _energy(c: DoublePendulumFrictionConfig, x: State) -> Scalar:
    (m1, m2), (l1, l2) = c.masses, c.lengths
    a, b, d, det = _inverse_mass(c, x)
    p1, p2 = x[2], x[3]
    kinetic = (d * p1**2 - 2.0 * b * p1 * p2 + a * p2**2) / (2.0 * det)
    potential = c.gravity * (
        (m1 + m2) * l1 * (1.0 - jnp.cos(x[0])) + m2 * l2 * (1.0 - jnp.cos(x[1]))
    )
    return kinetic + potential + bath_energy(x[4], c.heat_capacity, c.theta0)


def _friction(c: DoublePendulumFrictionConfig, x: State) -> Matrix:
    # Gamma = B B^T with B = A^T diag(sqrt(gamma)): one column per joint, so that
    # M = G G^T / theta with G = W B is a Gram matrix (exactly symmetric, PSD).
    r1, r2 = np.sqrt(c.friction)
    B = jnp.asarray([[r1, -r2], [0.0, r2]], x.dtype)
    theta = bath_temperature(x[4], c.heat_capacity, c.theta0)
    G = heating_factor(theta, _velocities(c, x)) @ B
    return (G @ G.T) / theta


@dataclasses.dataclass(frozen=True)
class DoublePendulumFriction(BoxSampling, System):
    """A rigid double pendulum under gravity; friction at both joints heats one reservoir."""

    name = "double-pendulum-friction"
    description = (
        "Rigid planar double pendulum under gravity with joint friction heating one reservoir: "
        "canonical L in (phi, p), S = s, M = W Gamma W^T / theta."
    )
    names = ("phi1", "phi2", "p1", "p2", "s")
    max_substep = 0.002
    defaults = case_settings(dt=0.012, steps=300, trajectories=32)
    config: DoublePendulumFrictionConfig = DoublePendulumFrictionConfig()

    def _build_model(self) -> GenericModel:
        return analytic_model(self.config, energy=_energy, entropy=SumOf((4,)),
                              poisson=CanonicalPoisson(5, 2), friction=_friction)


CASE = ZooCase.of(
    DoublePendulumFriction(),
    {"poisson": "canonical:2", "entropy": "sum:4"},
    held_out=True,
    note="Position-dependent mass matrix, two coupled modes and a state-dependent friction matrix.",
)
