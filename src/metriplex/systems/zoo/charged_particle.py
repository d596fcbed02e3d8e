r"""A charged particle in a harmonic trap and an inhomogeneous magnetic (mirror) field, with drag.

State :math:`x = (x, y, z, p_x, p_y, p_z, s)`: position, *kinetic* momentum :math:`p = m v` and
the entropy of the medium the drag heats. Positions are measured from the origin, the trap
sits at :math:`r_0 = (0, 0, z_0)` (:math:`z_0 = 10^4` by default, a large offset), and with
:math:`\xi = r - r_0`:

.. math::
    E = \frac{|p|^2}{2m} + \frac k2|\xi|^2 + c\,\theta_0\big(e^{s/c}-1\big),\qquad S = s,

.. math::
    B(\xi) = B_0\Big(-\frac{\xi_x\xi_z}{\ell^2},\ -\frac{\xi_y\xi_z}{\ell^2},\
             1 + \frac{\xi_z^2 - (\xi_x^2+\xi_y^2)/2}{\ell^2}\Big),

a magnetic mirror that is divergence-free (and curl-free). The Poisson bivector is the
non-canonical, state-dependent

.. math::
    L = \begin{pmatrix} 0 & I_3 & 0\\ -I_3 & -e\hat B(x) & 0\\ 0 & 0 & 0\end{pmatrix},
    \qquad \hat B v = B\times v,

which satisfies the Jacobi identity because :math:`\nabla\cdot B = 0`. Drag with
coefficient :math:`\gamma` uses :math:`M = \frac\gamma\theta W W^\top`,
:math:`W = (0;\ \theta I_3;\ -v^\top)` (:math:`7\times3`), so

.. math::
    \dot\xi = v,\qquad \dot p = e\,v\times B - k\xi - \gamma v,\qquad
    \dot s = \gamma|v|^2/\theta \ge 0,\qquad \theta = \theta_0 e^{s/c}.
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np
from jaxtyping import Float

from ..._errors import MetriplexError
from ..._model import GenericModel
from ..._types import Matrix, Scalar, State
from ...structure import SumOf
from .._base import System, _sample_box, analytic_model
from ._case import ZooCase, case_settings
from ._parts import bath_energy, bath_heating


@dataclasses.dataclass(frozen=True)
class ChargedParticleConfig:
    r"""Parameters of the trapped charged particle (consistent, nondimensional units).

    ``mass`` :math:`m` = 1, ``charge`` :math:`e` = 1, field strength ``b0`` :math:`B_0` = 0.5
    (cyclotron frequency 0.5), ``mirror_length`` :math:`\ell` = 12, trap ``stiffness``
    :math:`k` = 1, ``drag`` :math:`\gamma` = 0.04, medium ``heat_capacity`` :math:`c` = 10 at
    ``theta0`` :math:`\theta_0` = 5, trap centre ``z0`` = 1e4. Initial states: position
    :math:`r_0 + U(-1,1)\cdot` ``position_halfwidth`` (5) per axis, momentum
    :math:`U(-1,1)\cdot` ``momentum_halfwidth`` (5), :math:`s \sim U(-1,1)\cdot`
    ``entropy_halfwidth`` (0.5).
    """

    mass: float = 1.0
    charge: float = 1.0
    b0: float = 0.5
    mirror_length: float = 12.0
    stiffness: float = 1.0
    drag: float = 0.04
    heat_capacity: float = 10.0
    theta0: float = 5.0
    z0: float = 1.0e4
    position_halfwidth: float = 5.0
    momentum_halfwidth: float = 5.0
    entropy_halfwidth: float = 0.5

    def __post_init__(self):
        positive = {
            "mass": self.mass,
            "mirror_length": self.mirror_length,
            "stiffness": self.stiffness,
            "heat_capacity": self.heat_capacity,
            "theta0": self.theta0,
        }
        bad = {k: v for k, v in positive.items() if not v > 0.0}
        if bad:
            raise MetriplexError(
                f"charged-particle parameters {sorted(bad)} must be positive; got "
                + ", ".join(f"{k}={v}" for k, v in bad.items())
                + ". Example: mass=1, mirror_length=12."
            )
        if not self.drag >= 0.0:
            raise MetriplexError(
                f"the drag coefficient must be >= 0; got drag={self.drag}. Example: drag=0.04."
            )
        halfwidths = (self.position_halfwidth, self.momentum_halfwidth, self.entropy_halfwidth)
        if min(halfwidths) < 0.0:
            raise MetriplexError(
                f"sampling half-widths must be >= 0; got position_halfwidth="
                f"{self.position_halfwidth}, momentum_halfwidth={self.momentum_halfwidth}, "
                f"entropy_halfwidth={self.entropy_halfwidth}."
            )


def magnetic_field(c: ChargedParticleConfig, x: State) -> State:
    """The mirror field :math:`B` at the position ``x[:3]`` (divergence- and curl-free)."""
    xi_x, xi_y, xi_z = x[0], x[1], x[2] - c.z0
    inv = 1.0 / c.mirror_length**2
    return c.b0 * jnp.stack(
        [-xi_x * xi_z * inv, -xi_y * xi_z * inv,
         1.0 + (xi_z**2 - 0.5 * (xi_x**2 + xi_y**2)) * inv]
    )


def _energy(c: ChargedParticleConfig, x: State) -> Scalar:
    xi = x[:3] - jnp.asarray([0.0, 0.0, c.z0], x.dtype)
    kinetic = jnp.sum(x[3:6] ** 2) / (2.0 * c.mass)
    trap = 0.5 * c.stiffness * jnp.sum(xi**2)
    return kinetic + trap + bath_energy(x[6], c.heat_capacity, c.theta0)


def _poisson(c: ChargedParticleConfig, x: State) -> Matrix:
    bx, by, bz = c.charge * magnetic_field(c, x)
    z = jnp.zeros((), x.dtype)
    # -e B^ with B^ v = B x v.
    gyro = jnp.stack([jnp.stack([z, bz, -by]), jnp.stack([-bz, z, bx]),
                      jnp.stack([by, -bx, z])])
    eye = jnp.eye(3, dtype=x.dtype)
    out = jnp.zeros((7, 7), x.dtype)
    return out.at[0:3, 3:6].set(eye).at[3:6, 0:3].set(-eye).at[3:6, 3:6].set(gyro)


def _friction(c: ChargedParticleConfig, x: State) -> Matrix:
    return bath_heating(c, c.drag, x[6], x[3:6] / c.mass)


@dataclasses.dataclass(frozen=True)
class ChargedParticle(System):
    """A charged particle in a harmonic trap inside a magnetic mirror, with drag (n = 7)."""

    name = "charged-particle"
    description = (
        "Charged particle in a harmonic trap (centre z0 = 1e4) and a divergence-free mirror "
        "field, with drag heating the medium: non-canonical L with -e B^(x), S = s."
    )
    names = ("x", "y", "z", "px", "py", "pz", "s")
    max_substep = 0.005
    defaults = case_settings(dt=0.035, steps=300, trajectories=32)
    config: ChargedParticleConfig = ChargedParticleConfig()

    def _build_model(self) -> GenericModel:
        return analytic_model(self.config, energy=_energy, entropy=SumOf((6,)),
                              poisson=_poisson, friction=_friction)

    def sample_initial(self, num: int, *, seed: int) -> Float[np.ndarray, "num 7"]:
        """Uniform in a box around the trap centre (see :class:`ChargedParticleConfig`)."""
        self._check_num(num)
        c = self.config
        half = [c.position_halfwidth] * 3 + [c.momentum_halfwidth] * 3 + [c.entropy_halfwidth]
        return _sample_box((0.0, 0.0, c.z0, 0.0, 0.0, 0.0, 0.0), half, num, seed)


CASE = ZooCase.of(
    ChargedParticle(),
    {"entropy": "sum:6"},
    held_out=False,
    note="Non-canonical state-dependent L (Jacobi via div B = 0) learned, with a 1e4 offset in z.",
)
