r"""Learned 3-D Poisson bivectors that satisfy the Jacobi identity by construction:
:math:`L = [w]_\times` with :math:`w = \varphi\,\nabla C` (:class:`CasimirPoisson3`) or
:math:`w = \varphi\,\nabla S` (:class:`EntropyCasimirPoisson3`, also exactly degenerate).
"""

from __future__ import annotations

import abc
import functools
from typing import Any, ClassVar, Self

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np

from .._errors import MetriplexError
from .._types import Matrix, Scalar, State
from ._abstract import AbstractPoisson
from ._mlp import ACTIVATION, DEPTH, WIDTH, Hidden, network_spec
from ._registry import network_kwargs, register
from .scaling import Scaling, scaling_spec, standardise_state


def _cross_matrix(w) -> Matrix:
    r""":math:`L_{ij} = \varepsilon_{ijk} w_k`, i.e. :math:`Lv = v\times w`."""
    z = jnp.zeros((), w.dtype)
    return jnp.stack(
        [
            jnp.stack([z, w[2], -w[1]]),
            jnp.stack([-w[2], z, w[0]]),
            jnp.stack([w[1], -w[0], z]),
        ]
    )


class _Scalar(eqx.Module):
    """A scalar MLP on standardised 3-vectors (a bare hidden stack + linear read-out)."""

    hidden: Hidden
    out: eqx.nn.Linear

    def __init__(self, width: int, depth: int, activation: str, *, key: jax.Array) -> None:
        hkey, okey = jr.split(key)
        self.hidden = Hidden(3, width, depth, activation, key=hkey)
        self.out = eqx.nn.Linear(width, "scalar", key=okey)

    def __call__(self, z: State) -> Scalar:
        return self.out(self.hidden(z))


def _check_three(n: int, name: str) -> None:
    if n != 3:
        raise MetriplexError(
            f"{name} is the Jacobi-exact bivector of a 3-variable system and needs n = 3; got "
            f"n={n}. For other sizes use SkewMLPPoisson with JacobiPenalty, or CanonicalPoisson."
        )


_SOFTPLUS_ONE = float(np.log(np.e - 1.0))  # softplus(_SOFTPLUS_ONE) = 1


class _AbstractCasimir3(AbstractPoisson):
    r"""Shared code of the 3-D bivectors :math:`L = D\,[\tilde w]_\times D`,
    :math:`\tilde w = \varphi(z)\,\tilde c(z)` on standardised :math:`z = D^{-1}(x - c)`: the
    constructor (the scalar networks are the subclass's), the assembly and the spec."""

    phi: _Scalar
    n: int = eqx.field(static=True)
    scaling: Scaling | None = eqx.field(static=True)

    def __init__(
        self, n: int = 3, *,
        width: int = WIDTH, depth: int = DEPTH, activation: str = ACTIVATION,
        scaling: Scaling | None = None,
        key: jax.Array,
    ) -> None:
        _check_three(n, type(self).__name__)
        self._init_scalars(functools.partial(_Scalar, width, depth, activation), key)
        self.n = n
        self.scaling = scaling

    @abc.abstractmethod
    def _init_scalars(self, scalar, key) -> None:
        """Set the scalar networks, each made by ``scalar(key=...)``."""

    def _z(self, x: State) -> State:
        return standardise_state(x, self.scaling)

    @abc.abstractmethod
    def _factor(self, z: State):
        """The positive (or signed) factor :math:`\varphi(z)`."""

    def _assemble(self, z: State, c: State) -> Matrix:
        w = self._factor(z) * c
        L = _cross_matrix(w)
        s = self.scaling
        if s is None:
            return L
        # f d_i d_j as one symmetric factor keeps L exactly antisymmetric.
        return L * jnp.asarray(s.congruence(), L.dtype)

    def spec(self) -> dict[str, Any]:
        return network_spec(self.kind, self.phi.hidden, scaling=scaling_spec(self.scaling))

    @classmethod
    def from_spec(cls, spec: dict[str, Any], n: int, *, key: jax.Array) -> Self:
        return cls(n, **network_kwargs(spec), key=key)


@register("poisson", "casimir3")
class CasimirPoisson3(_AbstractCasimir3):
    r"""A learned 3-D Poisson bivector that satisfies the Jacobi identity by construction.

    .. math:: L_{ij} = \varepsilon_{ijk} w_k,\qquad w = \varphi(x)\,\nabla C(x),

    with two scalar MLPs, :math:`\varphi > 0` (stored as
    :math:`\operatorname{softplus}(\text{MLP} + \log(e-1))`, so :math:`\varphi = 1` for a zero
    network) and the Casimir :math:`C`. In three dimensions the Jacobi identity of :math:`[w]_\times` is
    :math:`w\cdot(\nabla\times w) = 0`, and :math:`\nabla\times(\varphi\nabla C) =
    \nabla\varphi\times\nabla C \perp \nabla C`; :math:`C` is a Casimir
    (:math:`L\nabla C = 0`). Every Poisson bivector on a 3-D domain is locally of this form
    near a point where :math:`L\ne 0`, with a :math:`\varphi` of one sign (the sign goes into
    :math:`C`). The rigid body is :math:`\varphi = 1`, :math:`C = -\tfrac12|m|^2`.

    Why :math:`\varphi > 0`: with a signed :math:`\varphi` (:math:`1 + \text{MLP}`) training on
    the rigid body got stuck in 2 of 4 seeds; in the one examined :math:`\varphi` changed sign
    inside the data (from -2.6 to 2.5), so :math:`L = 0` on a surface there, a spurious set of
    equilibria that gradient descent does not remove. A positive :math:`\varphi` leaves zeros of :math:`w` only at critical points of
    :math:`C`.

    With a scaling the networks see :math:`z = D^{-1}(x-c)` and :math:`L = D[\tilde w]_\times D`
    with :math:`\tilde w = \varphi\nabla_z C` (a linear change of variables keeps Jacobi).

    Degeneracy: :math:`L\nabla S = \nabla S\times w`, zero iff :math:`w\parallel\nabla S`, i.e.
    iff :math:`S` is a function of the Casimir. This class does **not** enforce it (the
    entropy gradient is ignored); use :class:`EntropyCasimirPoisson3` to get both Jacobi and
    :math:`L\nabla S = 0` exactly, or a degeneracy penalty.
    """

    casimir: _Scalar

    def _init_scalars(self, scalar, key) -> None:
        k1, k2 = jr.split(key)
        self.phi = scalar(key=k1)
        self.casimir = scalar(key=k2)

    def _factor(self, z: State):
        return jax.nn.softplus(self.phi(z) + _SOFTPLUS_ONE)

    uses_gradient: ClassVar[bool] = False

    def __call__(self, x: State, grad_entropy: State | None = None) -> Matrix:
        z = self._z(x)
        return self._assemble(z, jax.grad(self.casimir)(z))


@register("poisson", "casimir3-entropy")
class EntropyCasimirPoisson3(_AbstractCasimir3):
    r"""A learned 3-D bivector with the Jacobi identity **and** :math:`L\nabla S = 0` exact:

    .. math:: L_{ij} = \varepsilon_{ijk} w_k,\qquad w = \varphi(x)\,\nabla S(x),

    i.e. :class:`CasimirPoisson3` with the entropy as the Casimir. In 3-D this is the general
    exactly degenerate Poisson bivector near points where :math:`\nabla S \ne 0` (the kernel of
    a rank-2 :math:`[w]_\times` is :math:`w`). Where :math:`\nabla S = 0` it gives :math:`L=0`,
    so with an entropy that is zero (a conservative system) there are no reversible dynamics:
    use :class:`CasimirPoisson3` there. Here :math:`\varphi = 1 + \text{MLP}` is signed: the
    orientation of :math:`w` relative to the given :math:`\nabla S` must be learnable.
    """

    def _init_scalars(self, scalar, key) -> None:
        self.phi = scalar(key=key)

    def _factor(self, z: State):
        # 1 + network: at initialisation L ~ [grad S]_x rather than ~0.
        return 1.0 + self.phi(z)

    uses_gradient: ClassVar[bool] = True

    def __call__(self, x: State, grad_entropy: State) -> Matrix:
        s = self.scaling
        h = grad_entropy if s is None else jnp.asarray(s.scale, x.dtype) * grad_entropy
        return self._assemble(self._z(x), h)
