r"""The double thermoelastic pendulum in :math:`(q, p, \theta)`: the system of
:mod:`~metriplex.systems.pendulum` after the change of variables :math:`s \to \theta`, with
:math:`E' = E`, :math:`S' = S`, :math:`L' = JLJ^\top` and :math:`M' = JMJ^\top` in closed form.
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .._model import GenericModel
from .._types import Matrix, Scalar, State
from ._base import Settings, analytic_model
from .pendulum import (
    _Q_P_NAMES,
    PendulumConfig,
    PendulumEnergetic,
    _arr,
    _energy,
    _entropies,
    _Pendulum,
    _strain_gradient,
    _strains,
    entropy_to_temperature,
    temperature_to_entropy,
)


def _energy_t(c: PendulumConfig, x: State) -> Scalar:
    return _energy(c, x, _strains(c, x[0:4]), _arr(c.heat_capacity, x) * (x[8:10] - c.theta_ref))


def _entropy_t(c: PendulumConfig, x: State) -> Scalar:
    return jnp.sum(_entropies(c, x))


def _poisson_t(c: PendulumConfig, x: State) -> Matrix:
    beta, c0 = _arr(c.beta, x), _arr(c.heat_capacity, x)
    # G = d theta / d q at fixed s, written in the observed theta.
    G = -(beta * x[8:10] / c0)[:, None] * _strain_gradient(x[0:4])
    eye = jnp.eye(4, dtype=x.dtype)
    L = jnp.zeros((10, 10), x.dtype)
    L = L.at[0:4, 4:8].set(eye).at[4:8, 0:4].set(-eye)
    return L.at[4:8, 8:10].set(-G.T).at[8:10, 4:8].set(G)


def _friction_t(c: PendulumConfig, x: State) -> Matrix:
    c0 = _arr(c.heat_capacity, x)
    v = jnp.stack([1.0 / c0[0], -1.0 / c0[1]])
    block = (c.kappa * x[8] * x[9]) * (v[:, None] * v[None, :])
    return jnp.zeros((10, 10), x.dtype).at[8:, 8:].set(block)


@dataclasses.dataclass(frozen=True)
class PendulumTemperature(_Pendulum):
    r"""The same pendulum observed in :math:`x' = (q, p, \theta)` (learn all four).

    .. math::
        E' = \sum_i\frac{|p_i|^2}{2m_i} + \sum_i\Big[\tfrac12C_ia_i^2 + \beta_i\theta_{\rm ref}a_i
            + c_{0i}(\theta_i - \theta_{\rm ref})\Big],\qquad
        S' = \sum_i\Big[\beta_ia_i + c_{0i}\log\frac{\theta_i}{\theta_{\rm ref}}\Big],

    .. math::
        L' = \begin{pmatrix}0 & I & 0\\ -I & 0 & -G^\top\\ 0 & G & 0\end{pmatrix},\quad
        G = \frac{\partial\theta}{\partial q} = -\operatorname{diag}\Big(\frac{\beta\theta}{c_0}
        \Big)\frac{\partial a}{\partial q},\qquad
        M'_{\theta\theta} = \kappa\,\theta_1\theta_2\, v v^\top,\ v = (1/c_{01}, -1/c_{02}).

    These are :math:`JLJ^\top` and :math:`JMJ^\top` with :math:`J = \partial x'/\partial x`,
    so the Jacobi identity, :math:`L'\nabla S' = 0` and :math:`M'\nabla E' = 0` carry over.
    Initial states are drawn in :math:`(q, p, s)` as for :class:`PendulumEnergetic` and mapped
    by :func:`entropy_to_temperature`.
    """

    name = "pendulum-temperature"
    description = (
        "Double thermoelastic pendulum observed in (q, p, theta): state-dependent L' = J L J^T, "
        "M' = J M J^T, E' linear in theta; x0_* are given in (q, p, s)."
    )

    names = _Q_P_NAMES + ("theta1", "theta2")

    @property
    def defaults(self) -> Settings:
        if self.config.parameter_set == "spnn":
            return self.config.settings
        return Settings(
            0.04, 1000, 40, "40 trajectories x 1000 steps (paper); dt = 0.04 is our choice"
        )

    def _build_model(self) -> GenericModel:
        return analytic_model(self.config, energy=_energy_t, entropy=_entropy_t,
                              poisson=_poisson_t, friction=_friction_t)

    @property
    def energetic(self) -> PendulumEnergetic:
        """The same pendulum in :math:`(q, p, s)`."""
        return PendulumEnergetic(self.config)

    def sample_initial(self, num: int, *, seed: int) -> Float[np.ndarray, "num 10"]:
        r"""Drawn in :math:`(q, p, s)` like :class:`PendulumEnergetic`, then mapped to
        :math:`(q, p, \theta)`."""
        x = self.energetic.sample_initial(num, seed=seed)
        c = self.config
        q1, d = x[:, 0:2], x[:, 2:4] - x[:, 0:2]
        lengths = np.stack([np.linalg.norm(q1, axis=1), np.linalg.norm(d, axis=1)], axis=1)
        a = np.log(lengths / np.asarray(c.rest_lengths)[None, :])
        beta, c0 = np.asarray(c.beta)[None, :], np.asarray(c.heat_capacity)[None, :]
        theta = c.theta_ref * np.exp((x[:, 8:10] - beta * a) / c0)
        return np.concatenate([x[:, 0:8], theta], axis=1)

    def to_entropy(self, x: Float[ArrayLike, "*batch 10"]) -> Float[Array, "*batch 10"]:
        r"""States :math:`(q, p, \theta) \mapsto (q, p, s)` (:func:`temperature_to_entropy`)."""
        return temperature_to_entropy(x, self.config)

    def from_entropy(self, x: Float[ArrayLike, "*batch 10"]) -> Float[Array, "*batch 10"]:
        r"""States :math:`(q, p, s) \mapsto (q, p, \theta)` (:func:`entropy_to_temperature`)."""
        return entropy_to_temperature(x, self.config)

    def temperatures(self, x: Float[ArrayLike, "*batch 10"]) -> Float[Array, "*batch 2"]:
        r"""The observed :math:`\theta_1, \theta_2` of states ``x``."""
        return jnp.asarray(x)[..., 8:10]

