r"""The double thermoelastic pendulum, in :math:`(q, p, s)` and in :math:`(q, p, \theta)`.

Two point masses in the plane, no gravity; spring 1 joins the origin to mass 1, spring 2 joins
mass 1 to mass 2. With :math:`\lambda_1 = |q_1|`, :math:`\lambda_2 = |q_2 - q_1|` and log-strains
:math:`a_i = \log(\lambda_i/\lambda_i^0)`:

.. math::
    E = \sum_i \frac{|p_i|^2}{2m_i} + \sum_i \Big[\tfrac12 C_i a_i^2 + \beta_i\theta_{\rm ref} a_i
        + c_{0i}\theta_{\rm ref}\big(e^{(s_i - \beta_i a_i)/c_{0i}} - 1\big)\Big],\qquad
    S = s_1 + s_2,

temperatures :math:`\theta_i = \partial E/\partial s_i = \theta_{\rm ref}
e^{(s_i-\beta_i a_i)/c_{0i}}`, canonical :math:`L` on :math:`(q, p)` and Fourier heat conduction
:math:`M_{ss} = \kappa\begin{pmatrix}\theta_2/\theta_1 & -1\\ -1 & \theta_1/\theta_2\end{pmatrix}`.

In temperature variables :math:`x' = (q, p, \theta)`, with :math:`J = \partial x'/\partial x`,
:math:`E' = E`, :math:`S' = S` expressed in :math:`x'`, :math:`L' = JLJ^\top` and
:math:`M' = JMJ^\top` (closed forms in :class:`~metriplex.systems.pendulum_temperature.PendulumTemperature`).
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Any

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from .._errors import MetriplexError
from .._model import GenericModel
from .._types import Matrix, Scalar, State
from ..structure import CanonicalPoisson, SumOf
from ._base import BoxSampling, Settings, System, analytic_model

_UNIT_X0 = (1.0, 0.0, 2.2, 0.0, 0.0, 2.0, 1.0, 0.0, 1.0, 0.2)
_SPNN_X0 = (2.2, 0.0, 3.3, 0.0, 0.0, 0.5, 0.5, 0.0, 0.01, -0.01)


@dataclasses.dataclass(frozen=True)
class PendulumConfig:
    r"""Parameters of the double thermoelastic pendulum (two named sets: :meth:`named`).

    Pairs are per spring/mass ``(1, 2)``: ``masses`` :math:`m_i`, ``rest_lengths``
    :math:`\lambda_i^0`, ``stiffness`` :math:`C_i`, ``beta`` :math:`\beta_i`,
    ``heat_capacity`` :math:`c_{0i}`; then :math:`\theta_{\rm ref}` and the conductivity
    :math:`\kappa`.

    Initial states are drawn in :math:`(q, p, s)` as ``x0_center + U(-1, 1) * x0_halfwidth``
    per component (order ``q1x, q1y, q2x, q2y, p1x, p1y, p2x, p2y, s1, s2``):

    - ``unit``: centre ``(1, 0, 2.2, 0, 0, 2, 1, 0, 1, 0.2)``, half-width 0.1 everywhere
      (docs/physics.md, 'Initial states and published settings');
    - ``spnn``: our choice, since the published data's initial states are not stated: the
      same layout stretched to the set's rest lengths with gentler momenta, centre
      ``(2.2, 0, 3.3, 0, 0, 0.5, 0.5, 0, 0.01, -0.01)``, half-width 0.1 on :math:`q, p` and
      0.005 on :math:`s`. Initial temperatures lie in about [298, 301] (heat flows from the
      first instant) and stay within [296, 303]; over the published 60 time units
      :math:`\lambda_1` ranges over about [0.4, 7.8] and :math:`\lambda_2` over [0.27, 3.1]
      (50 trajectories, seed 0), so mass 1 swings in towards the pivot, if less closely than
      in the published data (:math:`\lambda_1 \approx 0.07`).

    ``parameter_set`` only labels which published settings (:attr:`Settings`) apply.
    """

    masses: tuple[float, float] = (1.0, 1.0)
    rest_lengths: tuple[float, float] = (1.0, 1.0)
    stiffness: tuple[float, float] = (1.0, 1.0)
    beta: tuple[float, float] = (1.0, 1.0)
    heat_capacity: tuple[float, float] = (1.0, 1.0)
    theta_ref: float = 1.0
    kappa: float = 1.0
    x0_center: tuple[float, ...] = _UNIT_X0
    x0_halfwidth: tuple[float, ...] = (0.1,) * 10
    parameter_set: str = "unit"

    def __post_init__(self):
        for field in ("masses", "rest_lengths", "heat_capacity"):
            value = getattr(self, field)
            if len(value) != 2 or min(value) <= 0.0:
                raise MetriplexError(
                    f"pendulum {field} must be two positive numbers; got {value}."
                )
        for field in ("stiffness", "beta"):
            if len(getattr(self, field)) != 2:
                raise MetriplexError(
                    f"pendulum {field} must be two numbers (one per spring); got "
                    f"{getattr(self, field)}."
                )
        if not self.theta_ref > 0.0 or not self.kappa >= 0.0:
            raise MetriplexError(
                f"need theta_ref > 0 and kappa >= 0; got theta_ref={self.theta_ref}, "
                f"kappa={self.kappa}."
            )
        if len(self.x0_center) != 10 or len(self.x0_halfwidth) != 10:
            raise MetriplexError(
                "x0_center and x0_halfwidth need 10 numbers each (q1x, q1y, q2x, q2y, p1x, p1y, "
                f"p2x, p2y, s1, s2); got {len(self.x0_center)} and {len(self.x0_halfwidth)}."
            )

    @classmethod
    def named(cls, name: str) -> "PendulumConfig":
        """The parameter set ``"unit"`` (all ones) or ``"spnn"`` (docs/physics.md, 'Parameter
        sets')."""
        if name == "unit":
            return cls()
        if name == "spnn":
            return cls(
                masses=(1.0, 2.0),
                rest_lengths=(2.0, 1.0),
                stiffness=(0.01885, 0.18861),
                beta=(0.08686, 0.08686),
                heat_capacity=(5.0, 5.0),
                theta_ref=300.0,
                kappa=300.0,
                x0_center=_SPNN_X0,
                x0_halfwidth=(0.1,) * 8 + (0.005, 0.005),
                parameter_set="spnn",
            )
        raise MetriplexError(
            f"unknown pendulum parameter set {name!r}; choose 'unit' or 'spnn'."
        )

    @property
    def settings(self) -> Settings:
        """The published data settings of this parameter set."""
        if self.parameter_set == "spnn":
            return Settings(0.3, 199, 50, "SPNN dataset: 50 trajectories x 200 snapshots")
        return Settings(0.1, 400, 100, "100 trajectories on t in [0, 40]")


# -- shared kinematics --------------------------------------------------------------------------
def _arr(values, x):
    return jnp.asarray(values, dtype=x.dtype)


def _strains(c: PendulumConfig, q: Float[Array, " 4"]) -> Float[Array, " 2"]:
    r"""Log-strains :math:`a_i = \log(\lambda_i/\lambda_i^0)`, via squared lengths."""
    d = q[2:4] - q[0:2]
    sq = jnp.stack([jnp.sum(q[0:2] ** 2), jnp.sum(d**2)])
    lam0 = _arr(c.rest_lengths, q)
    return 0.5 * jnp.log(sq / lam0**2)


def _kinetic(c: PendulumConfig, p: Float[Array, " 4"]) -> Scalar:
    m = _arr(c.masses, p)
    return jnp.sum(p[0:2] ** 2) / (2.0 * m[0]) + jnp.sum(p[2:4] ** 2) / (2.0 * m[1])


def _temperatures(c: PendulumConfig, x: State) -> Float[Array, " 2"]:
    a = _strains(c, x[0:4])
    beta, c0 = _arr(c.beta, x), _arr(c.heat_capacity, x)
    return c.theta_ref * jnp.exp((x[8:10] - beta * a) / c0)


def _strain_gradient(q: Float[Array, " 4"]) -> Float[Array, "2 4"]:
    r""":math:`\partial a_i/\partial q` (rows: springs; columns q1x, q1y, q2x, q2y)."""
    q1 = q[0:2]
    d = q[2:4] - q[0:2]
    g1 = q1 / jnp.sum(q1**2)
    g2 = d / jnp.sum(d**2)
    z = jnp.zeros((2,), q.dtype)
    return jnp.stack([jnp.concatenate([g1, z]), jnp.concatenate([-g2, g2])])


def _energy(c: PendulumConfig, x: State, a: Float[Array, " 2"], heat) -> Scalar:
    r""":math:`E` of a state with log-strains ``a`` whose springs hold the heat energies
    ``heat`` (relative to :math:`\theta_{\rm ref}`), in either view."""
    C, beta = _arr(c.stiffness, x), _arr(c.beta, x)
    return _kinetic(c, x[4:8]) + jnp.sum(0.5 * C * a**2 + beta * c.theta_ref * a + heat)


# -- (q, p, s) ----------------------------------------------------------------------------------
def _energy_s(c: PendulumConfig, x: State) -> Scalar:
    a = _strains(c, x[0:4])
    beta, c0 = _arr(c.beta, x), _arr(c.heat_capacity, x)
    return _energy(c, x, a, c0 * c.theta_ref * jnp.expm1((x[8:10] - beta * a) / c0))


def _friction_s(c: PendulumConfig, x: State) -> Matrix:
    th = _temperatures(c, x)
    one = jnp.ones((), x.dtype)
    block = c.kappa * jnp.stack(
        [jnp.stack([th[1] / th[0], -one]), jnp.stack([-one, th[0] / th[1]])]
    )
    return jnp.zeros((10, 10), x.dtype).at[8:, 8:].set(block)


def entropy_to_temperature(
    x: Float[ArrayLike, "*batch 10"], config: PendulumConfig = PendulumConfig()
) -> Float[Array, "*batch 10"]:
    r"""Map states :math:`(q, p, s) \mapsto (q, p, \theta)`,
    :math:`\theta_i = \theta_{\rm ref}\exp((s_i - \beta_i a_i)/c_{0i})`. Any leading batch axes."""
    x = jnp.asarray(x)
    return _map_states(_to_temperature, config, x.reshape(-1, 10)).reshape(x.shape)


def temperature_to_entropy(
    x: Float[ArrayLike, "*batch 10"], config: PendulumConfig = PendulumConfig()
) -> Float[Array, "*batch 10"]:
    r"""Map states :math:`(q, p, \theta) \mapsto (q, p, s)`,
    :math:`s_i = \beta_i a_i + c_{0i}\log(\theta_i/\theta_{\rm ref})`. Any leading batch axes."""
    x = jnp.asarray(x)
    return _map_states(_to_entropy, config, x.reshape(-1, 10)).reshape(x.shape)


def _to_temperature(config: PendulumConfig, y: State) -> State:
    return jnp.concatenate([y[0:8], _temperatures(config, y)])


def _to_entropy(config: PendulumConfig, y: State) -> State:
    return jnp.concatenate([y[0:8], _entropies(config, y)])


def _entropies(c: PendulumConfig, y: State) -> Float[Array, " 2"]:
    r""":math:`s_i = \beta_i a_i + c_{0i}\log(\theta_i/\theta_{\rm ref})` of a state
    :math:`(q, p, \theta)`."""
    a = _strains(c, y[0:4])
    beta, c0 = _arr(c.beta, y), _arr(c.heat_capacity, y)
    return beta * a + c0 * jnp.log(y[8:10] / c.theta_ref)


@functools.partial(jax.jit, static_argnums=(0, 1))
def _map_states(fn, config: PendulumConfig, flat: Float[Array, "batch 10"]):
    return jax.vmap(lambda y: fn(config, y))(flat)


_Q_P_NAMES = ("q1x", "q1y", "q2x", "q2y", "p1x", "p1y", "p2x", "p2y")


@dataclasses.dataclass(frozen=True)
class _Pendulum(BoxSampling, System):
    """What both views of the pendulum share: the config, named sets and sampling in s."""

    config: PendulumConfig = PendulumConfig()

    @property
    def defaults(self) -> Settings:
        return self.config.settings

    @property
    def relaxation_rate(self) -> float:
        r"""Rate of temperature equalisation, :math:`\kappa(1/c_{01} + 1/c_{02})` (≈ 120 for
        ``spnn``, 2 for ``unit``)."""
        c0 = self.config.heat_capacity
        return self.config.kappa * (1.0 / c0[0] + 1.0 / c0[1])

    @property
    def max_substep(self) -> float:
        # RK4 on the stiff heat-conduction mode: h * rate <= 0.11 keeps its error ~1e-6.
        return min(0.005, 0.11 / max(self.relaxation_rate, 1e-12))

    def with_params(self, **params: Any) -> "System":
        """Other parameters; ``parameter_set="spnn"`` starts from that named set."""
        base = self
        if "parameter_set" in params:
            base = type(self)(PendulumConfig.named(str(params.pop("parameter_set"))))
        return System.with_params(base, **params)


@dataclasses.dataclass(frozen=True)
class PendulumEnergetic(_Pendulum):
    r"""Double thermoelastic pendulum in :math:`(q, p, s)` (learn :math:`E` and :math:`M`).

    Known :math:`S = s_1 + s_2` and canonical :math:`L`; analytic :math:`E` and
    :math:`M_{ss} = \kappa\begin{pmatrix}\theta_2/\theta_1 & -1\\ -1 & \theta_1/\theta_2
    \end{pmatrix}`, so :math:`\dot s_1 = \kappa(\theta_2/\theta_1 - 1)`,
    :math:`\dot s_2 = \kappa(\theta_1/\theta_2 - 1)` and
    :math:`\dot S = \kappa(\theta_1-\theta_2)^2/(\theta_1\theta_2) \ge 0`.

    ```python
    pend = PendulumEnergetic(PendulumConfig.named("spnn"))
    x0 = pend.sample_initial(50, seed=0)    # (50, 10)
    ```
    """

    name = "pendulum-energetic"
    description = (
        "Double thermoelastic pendulum in (q, p, s): canonical L, S = s1 + s2, "
        "Fourier heat conduction between the springs."
    )

    names = _Q_P_NAMES + ("s1", "s2")

    def _build_model(self) -> GenericModel:
        return analytic_model(self.config, energy=_energy_s, entropy=SumOf((8, 9)),
                              poisson=CanonicalPoisson(10, 4), friction=_friction_s)

    def temperatures(self, x: Float[ArrayLike, "*batch 10"]) -> Float[Array, "*batch 2"]:
        r""":math:`\theta_i = \partial E/\partial s_i` of states ``x``."""
        return entropy_to_temperature(x, self.config)[..., 8:10]


# -- (q, p, theta) ------------------------------------------------------------------------------
