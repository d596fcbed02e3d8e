r"""A chain of particles with nonlinear springs, each heating its own reservoir, with heat
conduction between neighbouring reservoirs.

State :math:`x = (q_1..q_N, p_1..p_N, s_1..s_N)` (:math:`N` = 10 by default, :math:`n = 3N`):
displacements from the equilibrium sites, momenta and the reservoirs' entropies. Springs join
neighbours and the two end particles to fixed walls (:math:`q_0 = q_{N+1} = 0`); with
extensions :math:`r_j = q_{j} - q_{j-1}`, :math:`j = 1..N+1`, velocities :math:`v_i = p_i/m`
and temperatures :math:`\theta_i = U'(s_i) = \theta_0 e^{s_i/c}`:

.. math::
    E = \sum_i \frac{p_i^2}{2m} + \sum_{j=1}^{N+1}\Big(\frac k2 r_j^2 + \frac b4 r_j^4\Big)
        + \sum_i c\,\theta_0\big(e^{s_i/c}-1\big),\qquad S = \sum_i s_i,

canonical :math:`L` in :math:`(q, p)`, and :math:`M = M_{\rm fric} + M_{\rm cond}`:

.. math::
    M_{\rm fric} = \sum_i \frac{\gamma}{\theta_i} w_i w_i^\top,\quad
    w_i = \theta_i e_{p_i} - v_i e_{s_i};\qquad
    M_{\rm cond} = \sum_{i=1}^{N-1}\kappa\,\theta_i\theta_{i+1}\,u_i u_i^\top,\quad
    u_i = \frac{e_{s_i}}{\theta_i} - \frac{e_{s_{i+1}}}{\theta_{i+1}}.

Both annihilate :math:`\nabla E = (\partial_q E, v, \theta)`, so :math:`\dot q = v`,
:math:`\dot p_i = -\partial_{q_i}E - \gamma v_i` and
:math:`\theta_i\dot s_i = \gamma v_i^2 + \kappa\sum_{j\sim i}(\theta_j - \theta_i)`, with entropy
production :math:`\sum_i\gamma v_i^2/\theta_i + \kappa\sum_{i}\theta_i\theta_{i+1}
(1/\theta_i - 1/\theta_{i+1})^2 \ge 0`.
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np
from jaxtyping import Float

from ..._errors import expect_integer
from ..._model import GenericModel
from ..._types import Matrix, Scalar, State
from ...structure import CanonicalPoisson, SumOf
from .._base import System, _sample_box, analytic_model
from ._case import ZooCase, case_settings
from ._parts import bath_temperature, check_signs


@dataclasses.dataclass(frozen=True)
class ThermoelasticChainConfig:
    r"""Parameters of the chain (consistent nondimensional units).

    ``particles`` :math:`N` = 10 of ``mass`` 1, springs of ``stiffness`` :math:`k` = 1 with
    ``quartic`` :math:`b` = 1 (normal-mode periods of the linear chain 3.2 to 22 time units),
    on-site ``friction`` :math:`\gamma` = 0.05, ``conductivity`` :math:`\kappa` = 0.1,
    reservoir ``heat_capacity`` :math:`c` = 1 at ``theta0`` = 1. Initial states:
    :math:`q_i, p_i, s_i` independent, uniform within ± ``displacement_halfwidth`` (0.5),
    ± ``momentum_halfwidth`` (0.5), ± ``entropy_halfwidth`` (0.2).
    """

    particles: int = 10
    mass: float = 1.0
    stiffness: float = 1.0
    quartic: float = 1.0
    friction: float = 0.05
    conductivity: float = 0.1
    heat_capacity: float = 1.0
    theta0: float = 1.0
    displacement_halfwidth: float = 0.5
    momentum_halfwidth: float = 0.5
    entropy_halfwidth: float = 0.2

    def __post_init__(self):
        expect_integer(self.particles, what="the thermoelastic chain's particles", least=2,
                       fix="Example: particles=10.")
        check_signs(self, "thermoelastic-chain",
                    positive=("mass", "stiffness", "heat_capacity", "theta0"),
                    nonnegative=("quartic", "friction", "conductivity", "displacement_halfwidth",
                                 "momentum_halfwidth", "entropy_halfwidth"),
                    example="friction=0.05")


def _extensions(q: State) -> State:
    """The :math:`N+1` spring extensions, walls at zero displacement."""
    z = jnp.zeros((1,), q.dtype)
    return jnp.diff(jnp.concatenate([z, q, z]))


def _energy(c: ThermoelasticChainConfig, x: State) -> Scalar:
    N = c.particles
    q, p, s = x[:N], x[N : 2 * N], x[2 * N :]
    r = _extensions(q)
    springs = jnp.sum(0.5 * c.stiffness * r**2 + 0.25 * c.quartic * r**4)
    heat = c.heat_capacity * c.theta0 * jnp.sum(jnp.expm1(s / c.heat_capacity))
    return jnp.sum(p**2) / (2.0 * c.mass) + springs + heat


def _friction(c: ThermoelasticChainConfig, x: State) -> Matrix:
    N = c.particles
    v = x[N : 2 * N] / c.mass
    theta = bath_temperature(x[2 * N :], c.heat_capacity, c.theta0)
    # Friction: pp = diag(gamma theta), ps = diag(-gamma v), ss = diag(gamma v^2 / theta).
    pp = jnp.diag(c.friction * theta)
    ps = jnp.diag(-c.friction * v)
    # Conduction: ss = kappa (diag(sum_{j~i} theta_j / theta_i) - adjacency).
    adjacency = jnp.eye(N, k=1, dtype=x.dtype) + jnp.eye(N, k=-1, dtype=x.dtype)
    ss = jnp.diag(c.friction * v**2 / theta + c.conductivity * (adjacency @ theta) / theta)
    ss = ss - c.conductivity * adjacency
    out = jnp.zeros((3 * N, 3 * N), x.dtype)
    out = out.at[N : 2 * N, N : 2 * N].set(pp)
    out = out.at[N : 2 * N, 2 * N :].set(ps).at[2 * N :, N : 2 * N].set(ps)
    return out.at[2 * N :, 2 * N :].set(ss)


@dataclasses.dataclass(frozen=True)
class ThermoelasticChain(System):
    """A nonlinear chain with one heat reservoir per particle and conduction between them."""

    name = "thermoelastic-chain"
    description = (
        "Chain of N particles with quartic-corrected springs to neighbours and walls; on-site "
        "friction heats each particle's reservoir, neighbouring reservoirs conduct heat: "
        "canonical L, S = sum s_i."
    )
    max_substep = 0.005
    defaults = case_settings(dt=0.025, steps=300, trajectories=24)
    config: ThermoelasticChainConfig = ThermoelasticChainConfig()

    @property
    def names(self) -> tuple[str, ...]:
        N = range(1, self.config.particles + 1)
        return tuple(f"q{i}" for i in N) + tuple(f"p{i}" for i in N) + tuple(f"s{i}" for i in N)

    def _build_model(self) -> GenericModel:
        N = self.config.particles
        return analytic_model(self.config, energy=_energy, entropy=SumOf(range(2 * N, 3 * N)),
                              poisson=CanonicalPoisson(3 * N, N), friction=_friction)

    def sample_initial(self, num: int, *, seed: int) -> Float[np.ndarray, "num n"]:
        """Independent uniform :math:`q_i, p_i, s_i` (see :class:`ThermoelasticChainConfig`)."""
        self._check_num(num)
        c = self.config
        N = c.particles
        half = np.repeat(
            [c.displacement_halfwidth, c.momentum_halfwidth, c.entropy_halfwidth], N
        )
        return _sample_box(np.zeros(3 * N), half, num, seed)


CASE = ZooCase.of(
    ThermoelasticChain(),
    # What a user with a chain knows: canonical (q, p), S the sum of the reservoirs' entropies,
    # and that its cells are alike and interact only with their neighbours. Without the last
    # (E and M networks of all 30 variables), 24 trajectories teach no model the chain, an
    # unconstrained field neither (docs/zoo.md, *A local energy and friction*).
    {"poisson": "canonical:10", "entropy": "sum:20,21,22,23,24,25,26,27,28,29",
     "energy": "local:10,shared", "friction": "local:10,shared"},
    time_unit="1 (nondimensional)",
    held_out=False,
    note="High dimension (n = 30): ten coupled modes, ten reservoirs, friction plus conduction, "
         "all between neighbours.",
)
