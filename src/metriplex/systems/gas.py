r"""Two ideal-gas containers separated by a heat-conducting piston.

State :math:`x = (q, p, S_1, S_2)`: piston position and momentum, entropies of the two gases.
Volumes :math:`V_1 = q`, :math:`V_2 = V - q`; with :math:`Nk_B = 1`:

.. math::
    E_i = \Big(\frac{e^{S_i}}{\hat c\,V_i}\Big)^{2/3},\quad E = \frac{p^2}{2m} + E_1 + E_2,\quad
    S = S_1 + S_2,\quad L\ \text{canonical in}\ (q, p),

.. math::
    M_{SS} = \alpha\begin{pmatrix}1/T_1^2 & -1/(T_1T_2)\\ -1/(T_1T_2) & 1/T_2^2\end{pmatrix},
    \qquad T_i = \partial E/\partial S_i = \tfrac23 E_i,

so :math:`\dot q = p/m`, :math:`\dot p = \tfrac23(E_1/V_1 - E_2/V_2)`,
:math:`\dot S_1 = \tfrac{9\alpha}{4}\tfrac1{E_1}(\tfrac1{E_1}-\tfrac1{E_2})`,
:math:`\dot S_2 = -\tfrac{9\alpha}{4}\tfrac1{E_2}(\tfrac1{E_1}-\tfrac1{E_2})`.
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
from jaxtyping import Array, Float

from .._errors import MetriplexError
from .._model import GenericModel
from .._types import Matrix, Scalar, State
from ..structure import CanonicalPoisson, SumOf
from ._base import BoxSampling, Settings, System, analytic_model


@dataclasses.dataclass(frozen=True)
class GasConfig:
    r"""Parameters of the two gas containers (published settings by default).

    ``alpha`` (conduction) 10, piston ``mass`` 1, ``c_hat`` :math:`\hat c = 1`, total
    ``volume`` 2. Initial states ``x0_center + U(-1, 1) * x0_halfwidth`` per component, by
    default :math:`(1, 0, 2, 2) + U(-1, 1)\cdot(0.8, 1, 1, 1)`.
    """

    alpha: float = 10.0
    mass: float = 1.0
    c_hat: float = 1.0
    volume: float = 2.0
    x0_center: tuple[float, float, float, float] = (1.0, 0.0, 2.0, 2.0)
    x0_halfwidth: tuple[float, float, float, float] = (0.8, 1.0, 1.0, 1.0)

    def __post_init__(self):
        if not (self.alpha >= 0.0 and self.mass > 0.0 and self.c_hat > 0.0 and self.volume > 0.0):
            raise MetriplexError(
                f"gas containers need alpha >= 0 and positive mass, c_hat and volume; got "
                f"alpha={self.alpha}, mass={self.mass}, c_hat={self.c_hat}, volume={self.volume}."
            )
        lo = self.x0_center[0] - abs(self.x0_halfwidth[0])
        hi = self.x0_center[0] + abs(self.x0_halfwidth[0])
        if not 0.0 < lo <= hi < self.volume:
            raise MetriplexError(
                f"initial piston positions must lie strictly inside (0, volume={self.volume}); "
                f"x0_center and x0_halfwidth give q in [{lo}, {hi}]. Narrow the range."
            )


def _gas_energies(c: GasConfig, x: State) -> Float[Array, " 2"]:
    volumes = jnp.stack([x[0], c.volume - x[0]])
    # (e^S / (c V))^(2/3), written as one exponential.
    return jnp.exp((2.0 / 3.0) * (x[2:4] - jnp.log(c.c_hat * volumes)))


def _energy(c: GasConfig, x: State) -> Scalar:
    return x[1] ** 2 / (2.0 * c.mass) + jnp.sum(_gas_energies(c, x))


def _friction(c: GasConfig, x: State) -> Matrix:
    T = (2.0 / 3.0) * _gas_energies(c, x)
    u = jnp.stack([1.0 / T[0], -1.0 / T[1]])
    block = c.alpha * (u[:, None] * u[None, :])
    return jnp.zeros((4, 4), x.dtype).at[2:, 2:].set(block)


@dataclasses.dataclass(frozen=True)
class GasContainers(BoxSampling, System):
    r"""Two gas containers exchanging heat through a moving piston (a shared GENERIC benchmark).

    Published settings: 100 trajectories on :math:`t\in[0, 8]` with :math:`\Delta t = 0.02`
    (400 steps); the first 80 for training.
    """

    name = "gas-containers"
    description = (
        "Piston between two ideal-gas containers exchanging heat: canonical L in (q, p), "
        "S = S1 + S2."
    )
    names = ("q", "p", "S1", "S2")
    max_substep = 0.002
    defaults = Settings(0.02, 400, 100, "100 trajectories on t in [0, 8]; first 80 train")
    config: GasConfig = GasConfig()

    def _build_model(self) -> GenericModel:
        return analytic_model(self.config, energy=_energy, entropy=SumOf((2, 3)),
                              poisson=CanonicalPoisson(4, 1), friction=_friction)
