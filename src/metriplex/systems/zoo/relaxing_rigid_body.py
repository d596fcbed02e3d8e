r"""Morrison's relaxing rigid body: a metriplectic flow that keeps the energy and relaxes the
Casimir.

State :math:`m = (m_1, m_2, m_3)`, the body angular momentum. With
:math:`\Omega = \nabla E = I^{-1} m`,

.. math::
    E = \tfrac12\sum_i \frac{m_i^2}{I_i},\qquad L(m)_{ij} = -\varepsilon_{ijk} m_k,\qquad
    S = -\tfrac{\gamma}{2}|m|^2,\qquad
    M = \kappa\big(|\Omega|^2\,\mathbb 1 - \Omega\Omega^\top\big).

:math:`|m|^2` is a Casimir of the Lie–Poisson bracket (:math:`Lm = m\times m = 0`), so
:math:`L\nabla S = 0`; :math:`M` is :math:`\kappa|\Omega|^2` times the projector orthogonal to
:math:`\Omega`, so it is symmetric PSD with :math:`M\nabla E = 0`. The equations of motion are

.. math::
    \dot m = m\times\Omega \;-\; \kappa\gamma\big(|\Omega|^2 m - (\Omega\cdot m)\,\Omega\big),
    \qquad \frac{d}{dt}|m|^2 = -2\kappa\gamma\,|m\times\Omega|^2 \le 0 .

:math:`E` is conserved while :math:`|m|^2` decreases towards its minimum on the energy
ellipsoid, :math:`2EI_1`: steady rotation about the axis of least inertia. Initial states lie in
a ball around :math:`(4, 0, 0)` inside that axis's basin (the trajectories circulate around
the :math:`m_1` axis and spiral in; none crosses the separatrix of the middle axis).
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np

from ..._errors import MetriplexError
from ..._model import GenericModel
from ..._types import Matrix, Scalar, State
from ...structure import KnownPoisson
from .._base import BallSampling, System, analytic_model
from ..rigid_body import _lie_poisson, _rotational_energy
from ._case import ZooCase, case_settings
from ._parts import check_signs


@dataclasses.dataclass(frozen=True)
class RelaxingRigidBodyConfig:
    r"""Parameters of the relaxing rigid body.

    - ``inertia`` :math:`(I_1, I_2, I_3)` = (2, 3, 5), strictly increasing;
    - ``gamma`` :math:`\gamma` = 1 (entropy :math:`-\gamma|m|^2/2`) and ``kappa``
      :math:`\kappa` = 0.08 (friction strength); the flow depends on their product;
    - initial states uniform (by volume) in the ball :math:`|m - c| \le` ``radius`` = 1 around
      ``center`` :math:`c` = (4, 0, 0). The ball must lie in the basin of the
      :math:`m_1` axis, :math:`m_1^2 (I_2/I_1 - 1) > m_3^2 (1 - I_2/I_3)`, checked for the
      ball's extreme points.
    """

    inertia: tuple[float, float, float] = (2.0, 3.0, 5.0)
    gamma: float = 1.0
    kappa: float = 0.08
    radius: float = 1.0
    center: tuple[float, float, float] = (4.0, 0.0, 0.0)

    def __post_init__(self):
        I1, I2, I3 = self.inertia
        if not 0.0 < I1 < I2 < I3:
            raise MetriplexError(
                "relaxing-rigid-body inertia must be strictly increasing positive moments "
                f"I1 < I2 < I3; got inertia={self.inertia}. Example: inertia=(2, 3, 5)."
            )
        check_signs(self, "relaxing-rigid-body", positive=("gamma", "radius"),
                    nonnegative=("kappa",), example="gamma=1, kappa=0.08, radius=1")
        # Smallest |m1| and largest |m3| over the ball (conservative for the basin test).
        c1, c2, c3 = self.center
        m1 = abs(c1) - self.radius
        m3 = abs(c3) + self.radius
        if not (m1 > 0.0 and m1**2 * (I2 / I1 - 1.0) > m3**2 * (1.0 - I2 / I3)):
            raise MetriplexError(
                "relaxing-rigid-body initial states must lie in the basin of the m1 axis "
                "(m1^2 (I2/I1 - 1) > m3^2 (1 - I2/I3)) so that no trajectory crosses the "
                f"separatrix; the ball around center={self.center} with radius={self.radius} "
                "does not. Move the centre out along m1 or shrink the radius."
            )


def _entropy(c: RelaxingRigidBodyConfig, x: State) -> Scalar:
    return -0.5 * c.gamma * jnp.sum(x**2)


def _friction(c: RelaxingRigidBodyConfig, x: State) -> Matrix:
    omega = x / jnp.asarray(c.inertia, dtype=x.dtype)
    norm2 = jnp.sum(omega**2)
    eye = jnp.eye(3, dtype=x.dtype)
    return c.kappa * (norm2 * eye - omega[:, None] * omega[None, :])


@dataclasses.dataclass(frozen=True)
class RelaxingRigidBody(BallSampling, System):
    """Morrison's relaxing rigid body (n = 3): energy kept, Casimir relaxed, nothing known."""

    name = "relaxing-rigid-body"
    description = (
        "Morrison's metriplectic relaxing rigid body: Lie-Poisson L(m) = -eps m, "
        "E = sum m_i^2/(2 I_i), S = -gamma |m|^2/2, M = kappa (|Omega|^2 1 - Omega Omega^T), "
        "Omega = I^-1 m."
    )
    names = ("m1", "m2", "m3")
    defaults = case_settings(dt=0.05, steps=300, trajectories=32)
    config: RelaxingRigidBodyConfig = RelaxingRigidBodyConfig()

    @property
    def max_substep(self) -> float:
        # Angular speeds scale like |m| / min(I) (as for the free rigid body).
        c = self.config
        speed = (c.radius + float(np.linalg.norm(c.center))) / min(c.inertia)
        return min(0.02, 0.002 / speed)

    def _build_model(self) -> GenericModel:
        return analytic_model(self.config, energy=_rotational_energy, entropy=_entropy,
                              poisson=KnownPoisson(_lie_poisson), friction=_friction)


CASE = ZooCase.of(
    RelaxingRigidBody(),
    {},
    held_out=False,
    note="Nothing known: a non-canonical Lie-Poisson L, a nonlinear entropy and a state-"
    "dependent M that conserves E while the Casimir |m|^2 decays.",
)
