r"""The free rigid body: Euler's equations as a Lie–Poisson system on :math:`\mathfrak{so}(3)^*`.

State :math:`m = (m_1, m_2, m_3)`, the angular momentum in the body frame, and

.. math::
    E(m) = \tfrac12 \sum_i \frac{m_i^2}{I_i},\qquad L(m)_{ij} = -\varepsilon_{ijk} m_k,
    \qquad S = 0,\quad M = 0,

so :math:`\dot m = L\nabla E = m \times I^{-1} m`. The bracket satisfies the Jacobi identity
exactly; :math:`E` and the Casimir :math:`|m|^2` are conserved.
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np

from .._errors import MetriplexError
from .._model import GenericModel
from .._types import Matrix, Scalar, State
from ..structure import KnownPoisson, ZeroFriction, ZeroPotential
from ._base import BallSampling, Settings, System, analytic_model


@dataclasses.dataclass(frozen=True)
class RigidBodyConfig:
    r"""Parameters of the free rigid body.

    - ``inertia``: principal moments :math:`(I_1, I_2, I_3)`, all positive. Default
      ``(10, 20, 40)``, as in the seed authors' rigid-body code.
    - ``radius``: initial states are drawn uniformly (by volume) from the ball
      :math:`|m - c| \le` ``radius`` (default 1).
    - ``center``: the ball's centre :math:`c` (default the origin).
    """

    inertia: tuple[float, float, float] = (10.0, 20.0, 40.0)
    radius: float = 1.0
    center: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self):
        if len(self.inertia) != 3 or min(self.inertia) <= 0.0:
            raise MetriplexError(
                f"rigid-body inertia must be three positive moments (I1, I2, I3); got "
                f"{self.inertia}. Example: inertia=(10, 20, 40)."
            )
        if not self.radius > 0.0:
            raise MetriplexError(
                f"the sampling radius must be positive; got radius={self.radius}."
            )


def _rotational_energy(c: RigidBodyConfig, m: State) -> Scalar:
    r""":math:`\tfrac12\sum_i m_i^2/I_i` with the config's ``inertia`` (also of the zoo's
    rotating bodies)."""
    inv = 1.0 / jnp.asarray(c.inertia, dtype=m.dtype)
    return 0.5 * jnp.sum(m**2 * inv)


def _lie_poisson(x: State) -> Matrix:
    m1, m2, m3 = x[0], x[1], x[2]
    z = jnp.zeros((), x.dtype)
    return jnp.stack(
        [jnp.stack([z, -m3, m2]), jnp.stack([m3, z, -m1]), jnp.stack([-m2, m1, z])]
    )


@dataclasses.dataclass(frozen=True)
class RigidBody(BallSampling, System):
    r"""The free rigid body (learn :math:`L` and :math:`E`).

    ```python
    rb = RigidBody()                                  # I = (10, 20, 40)
    rb.model.vector_field(jnp.array([1.0, 0.5, 0.2])) # m x (I^-1 m)
    x0 = rb.sample_initial(5, seed=0)                 # uniform in the unit ball
    ```

    Published settings: 5 trajectories of 10 000 steps with :math:`\Delta t = 2\pi/100`.
    """

    name = "rigid-body"
    description = (
        "Free rigid body (Euler's equations): Lie-Poisson L(m) = -eps m, "
        "E = sum m_i^2/(2 I_i), S = 0, M = 0."
    )
    names = ("m1", "m2", "m3")
    defaults = Settings(
        2.0 * np.pi / 100.0, 10_000, 5, "5 trajectories x 10 000 steps (seed paper)"
    )
    config: RigidBodyConfig = RigidBodyConfig()

    @property
    def max_substep(self) -> float:
        # Angular speeds scale like |m| / min(I); keep RK4's h * speed below ~0.001.
        speed = (self.config.radius + max(abs(c) for c in self.config.center)) / min(
            self.config.inertia
        )
        return min(0.02, 0.001 / speed)

    def _build_model(self) -> GenericModel:
        return analytic_model(self.config, energy=_rotational_energy, entropy=ZeroPotential(),
                              poisson=KnownPoisson(_lie_poisson), friction=ZeroFriction(3))
