r"""Poisson bivectors :math:`L(x)`: antisymmetric, ideally satisfying the Jacobi identity.

Every Poisson block is called as ``poisson(x, grad_entropy)``; the gradient of the entropy is
passed so that exactly degenerate variants (:math:`L\nabla S = 0` by construction) can use it.
"""

from __future__ import annotations

import abc
from typing import Any, Callable, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np

from .._errors import MetriplexError
from .._types import Matrix, State
from ._mlp import FoldedHead, Hidden, standardise
from ._registry import network_kwargs, not_serialisable, register
from .scaling import Scaling


class AbstractPoisson(eqx.Module):
    """An antisymmetric matrix field ``L(x)``."""

    #: Whether the matrix depends on the ``grad_entropy`` argument (exactly degenerate
    #: blocks); if not, a matrix computed with another gradient can be reused.
    uses_gradient: ClassVar[bool] = True

    @abc.abstractmethod
    def __call__(self, x: State, grad_entropy: State) -> Matrix: ...

    def spec(self) -> dict[str, Any]:
        raise not_serialisable(self)


def _scaling_spec(scaling: Scaling | None):
    return None if scaling is None else scaling.to_json()


@register("poisson", "mlp")
class SkewMLPPoisson(AbstractPoisson):
    r"""Learned :math:`L(x)` from exactly :math:`n(n-1)/2` network outputs.

    The outputs fill the strict upper triangle; the lower triangle is their negative and the
    diagonal is zero, so :math:`L^\top = -L` holds exactly for any weights. With a
    :class:`~metriplex.structure.scaling.Scaling`, the network works on standardised states and
    :math:`L = D\tilde L D^\top` (folded into the last layer).
    """

    hidden: Hidden
    head: FoldedHead
    n: int = eqx.field(static=True)
    scaling: Scaling | None = eqx.field(static=True)

    def __init__(
        self,
        n: int,
        *,
        width: int = 64,
        depth: int = 2,
        activation: str = "softplus",
        scaling: Scaling | None = None,
        key,
    ):
        if n < 2:
            raise MetriplexError(f"a learned Poisson bivector needs n >= 2 variables; got {n}.")
        self.n = n
        self.scaling = scaling
        hkey, okey = jr.split(key)
        self.hidden = Hidden(n, width, depth, activation, key=hkey)
        rs = None if scaling is None else scaling.row_scale("skew")
        self.head = FoldedHead(width, n, "skew", rs, 1.0, key=okey)

    uses_gradient: ClassVar[bool] = False

    def __call__(self, x: State, grad_entropy: State | None = None) -> Matrix:
        s = self.scaling
        z = x if s is None else standardise(x, s.shift, s.scale)
        return self.head(self.hidden(z))

    def spec(self):
        return {
            "kind": "mlp",
            "width": self.head.weight.shape[1],
            "depth": len(self.hidden.layers),
            "activation": self.hidden.activation,
            "scaling": _scaling_spec(self.scaling),
        }

    @classmethod
    def from_spec(cls, spec, n, *, key):
        return cls(
            n,
            **network_kwargs(spec),
            key=key,
        )


@register("poisson", "canonical")
class CanonicalPoisson(AbstractPoisson):
    r"""Canonical :math:`L = \begin{pmatrix}0 & I & 0\\ -I & 0 & 0\\ 0&0&0\end{pmatrix}`.

    The first ``pairs`` components are positions, the next ``pairs`` their momenta; the
    remaining ``n - 2*pairs`` components (e.g. entropies) have zero rows and columns.
    """

    n: int = eqx.field(static=True)
    pairs: int = eqx.field(static=True)

    def __init__(self, n: int, pairs: int):
        if pairs < 1 or 2 * pairs > n:
            raise MetriplexError(
                f"canonical:K needs 1 <= K and 2K <= n (K positions then K momenta); got "
                f"K={pairs} with n={n} variables. Choose K <= {n // 2}."
            )
        self.n = n
        self.pairs = pairs

    def matrix(self) -> np.ndarray:
        K = self.pairs
        J = np.zeros((self.n, self.n))
        J[:K, K : 2 * K] = np.eye(K)
        J[K : 2 * K, :K] = -np.eye(K)
        return J

    uses_gradient: ClassVar[bool] = False

    def __call__(self, x: State, grad_entropy: State | None = None) -> Matrix:
        return jnp.asarray(self.matrix(), x.dtype)

    def spec(self):
        return {"kind": "canonical", "pairs": self.pairs}

    @classmethod
    def from_spec(cls, spec, n, *, key):
        return cls(n, spec["pairs"])


@register("poisson", "zero")
class ZeroPoisson(AbstractPoisson):
    """No reversible dynamics: ``L = 0``."""

    n: int = eqx.field(static=True)

    uses_gradient: ClassVar[bool] = False

    def __call__(self, x: State, grad_entropy: State | None = None) -> Matrix:
        return jnp.zeros((self.n, self.n), x.dtype)

    def spec(self):
        return {"kind": "zero"}

    @classmethod
    def from_spec(cls, spec, n, *, key):
        return cls(n)


class KnownPoisson(AbstractPoisson):
    """A Poisson bivector given by a function ``fn(x) -> (n, n)`` (ground-truth systems)."""

    fn: Callable = eqx.field(static=True)

    uses_gradient: ClassVar[bool] = False

    def __call__(self, x: State, grad_entropy: State | None = None) -> Matrix:
        return self.fn(x)


# -- exactly degenerate and Jacobi-exact variants ----------------------------------------------


def _default_eps(eps: float | None, dtype) -> float:
    """The regulariser of the projectors: machine epsilon of the working dtype by default."""
    return float(jnp.finfo(dtype).eps) if eps is None else float(eps)


def _check_eps(eps: float | None) -> None:
    if eps is not None and not (np.isfinite(eps) and eps > 0.0):
        raise MetriplexError(
            f"`eps` (the projector's regulariser) must be finite and > 0, or None for machine "
            f"epsilon; got {eps}."
        )


def _projector_vectors(g: State, scale: tuple[float, ...] | None, eps: float):
    r"""The two vectors of the projector :math:`Q = I - \hat u\,\hat g^\top` in physical
    coordinates, for the covector :math:`g` (a gradient):

    .. math:: \hat g = g/\sqrt{s},\quad \hat u = D^2 g/\sqrt{s},\quad
              s = |Dg|^2 + \varepsilon^2,

    where :math:`Dg` is the gradient in standardised coordinates. :math:`Q^\top g =
    g\,\varepsilon^2/s`: zero to rounding once :math:`|Dg| \gg \varepsilon`, and :math:`Q \to I`
    smoothly (no 0/0) where :math:`g \to 0`. Both vectors are bounded (:math:`|D\hat g| < 1`).
    """
    if scale is None:
        h = g
        d2g = g
    else:
        d = jnp.asarray(scale, g.dtype)
        h = d * g
        d2g = d * h
    # eps**2 must not underflow, or s = 0 at g = 0 and g * rsqrt(s) = 0 * inf.
    e2 = max(eps * eps, float(jnp.finfo(g.dtype).tiny))
    r = jax.lax.rsqrt(jnp.sum(h * h) + jnp.asarray(e2, g.dtype))
    return g * r, d2g * r


@register("poisson", "projected-mlp")
class ProjectedSkewMLPPoisson(AbstractPoisson):
    r"""Learned :math:`L` with :math:`L\nabla S = 0` by construction: :math:`L = Q A Q^\top`.

    :math:`A(x)` is a :class:`SkewMLPPoisson` (same network, same normalisation congruence
    :math:`A = D\tilde A D^\top`) and :math:`Q` projects out the entropy gradient
    :math:`g = \nabla S` in physical coordinates:

    .. math:: Q = I - \frac{D^2 g\,g^\top}{|Dg|^2 + \varepsilon^2},\qquad
              L = Q A Q^\top = A - (b\,\hat u^\top - \hat u\,b^\top),\quad
              b = A\hat g,

    with :math:`\hat g, \hat u` from :func:`_projector_vectors` (the term
    :math:`\hat g^\top A\hat g` vanishes by antisymmetry). Equivalently
    :math:`L = D\tilde P\tilde A\tilde P D` with :math:`\tilde P` the orthogonal projector
    against the standardised gradient :math:`Dg`, so the family does not depend on the units
    of ``x``. :math:`L` is exactly antisymmetric for any weights (it is assembled as
    :math:`K - K^\top`, :math:`K = \tfrac12 A - b\hat u^\top`).

    Exactness: :math:`L\nabla S = A\nabla S\,\varepsilon^2/(|D\nabla S|^2+\varepsilon^2)`,
    so :math:`|D^{-1}L\nabla S| \le \tfrac12\varepsilon\|\tilde A\|` everywhere and the relative
    leak :math:`\varepsilon^2/|D\nabla S|^2` is below rounding wherever
    :math:`|D\nabla S| > \sqrt{\text{machine eps}}\,`\ (1.5e-8 in float64, 3.5e-4 in float32,
    with the default :math:`\varepsilon` = machine epsilon). Where :math:`\nabla S \to 0`
    (``ZeroPotential`` entropy, a critical point) :math:`L \to A` smoothly: no NaN, and with
    no entropy gradient there is nothing to project. Derivatives of :math:`L` grow like
    :math:`1/|D\nabla S|` near a critical point of :math:`S` (any continuous exactly
    degenerate :math:`L` must vanish at a non-degenerate critical point) and are capped at
    :math:`\sim 1/\varepsilon`.

    ```python
    L = ProjectedSkewMLPPoisson(10, key=jr.key(0))
    L(x, grad_entropy) @ grad_entropy  # ~ 0
    ```
    """

    base: SkewMLPPoisson
    n: int = eqx.field(static=True)
    eps: float | None = eqx.field(static=True)

    def __init__(
        self,
        n: int,
        *,
        width: int = 64,
        depth: int = 2,
        activation: str = "softplus",
        scaling: Scaling | None = None,
        eps: float | None = None,
        key,
    ):
        _check_eps(eps)
        self.base = SkewMLPPoisson(
            n, width=width, depth=depth, activation=activation, scaling=scaling, key=key
        )
        self.n = n
        self.eps = None if eps is None else float(eps)

    @property
    def scaling(self) -> Scaling | None:
        return self.base.scaling

    def __call__(self, x: State, grad_entropy: State) -> Matrix:
        A = self.base(x)
        s = self.base.scaling
        g_hat, u_hat = _projector_vectors(
            grad_entropy, None if s is None else s.scale, _default_eps(self.eps, x.dtype)
        )
        # L = K - K^T with K = A/2 - b u^T. Not A - (W - W^T): the compiler may fuse one of the
        # two products of W - W^T into an FMA and break exact antisymmetry; each K_ij is one
        # deterministic expression, so K_ij - K_ji = -(K_ji - K_ij) exactly.
        K = 0.5 * A - jnp.outer(A @ g_hat, u_hat)
        return K - K.T

    def spec(self):
        return {**self.base.spec(), "kind": "projected-mlp", "eps": self.eps}

    @classmethod
    def from_spec(cls, spec, n, *, key):
        return cls(
            n,
            **network_kwargs(spec),
            eps=spec.get("eps"),
            key=key,
        )


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

    def __init__(self, width: int, depth: int, activation: str, *, key):
        hkey, okey = jr.split(key)
        self.hidden = Hidden(3, width, depth, activation, key=hkey)
        self.out = eqx.nn.Linear(width, "scalar", key=okey)

    def __call__(self, z):
        return self.out(self.hidden(z))


def _check_three(n: int, name: str) -> None:
    if n != 3:
        raise MetriplexError(
            f"{name} is the Jacobi-exact bivector of a 3-variable system and needs n = 3; got "
            f"n={n}. For other sizes use SkewMLPPoisson with JacobiPenalty, or CanonicalPoisson."
        )


_SOFTPLUS_ONE = float(np.log(np.e - 1.0))  # softplus(_SOFTPLUS_ONE) = 1


class _Casimir3Base(AbstractPoisson):
    r"""Shared code of the 3-D bivectors :math:`L = D\,[\tilde w]_\times D`,
    :math:`\tilde w = \varphi(z)\,\tilde c(z)` on standardised :math:`z = D^{-1}(x - c)`."""

    phi: _Scalar
    n: int = eqx.field(static=True)
    scaling: Scaling | None = eqx.field(static=True)

    def _z(self, x: State) -> State:
        s = self.scaling
        return x if s is None else standardise(x, s.shift, s.scale)

    def _factor(self, z: State):
        raise NotImplementedError

    def _assemble(self, z: State, c: State) -> Matrix:
        w = self._factor(z) * c
        L = _cross_matrix(w)
        s = self.scaling
        if s is None:
            return L
        # f d_i d_j as one symmetric factor keeps L exactly antisymmetric.
        return L * jnp.asarray(s.congruence(), L.dtype)

    def _spec_common(self) -> dict[str, Any]:
        return {
            "width": self.phi.out.in_features,
            "depth": len(self.phi.hidden.layers),
            "activation": self.phi.hidden.activation,
            "scaling": _scaling_spec(self.scaling),
        }


@register("poisson", "casimir3")
class CasimirPoisson3(_Casimir3Base):
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

    def __init__(
        self,
        n: int = 3,
        *,
        width: int = 64,
        depth: int = 2,
        activation: str = "softplus",
        scaling: Scaling | None = None,
        key,
    ):
        _check_three(n, "CasimirPoisson3")
        k1, k2 = jr.split(key)
        self.phi = _Scalar(width, depth, activation, key=k1)
        self.casimir = _Scalar(width, depth, activation, key=k2)
        self.n = n
        self.scaling = scaling

    def _factor(self, z: State):
        return jax.nn.softplus(self.phi(z) + _SOFTPLUS_ONE)

    uses_gradient: ClassVar[bool] = False

    def __call__(self, x: State, grad_entropy: State | None = None) -> Matrix:
        z = self._z(x)
        return self._assemble(z, jax.grad(self.casimir)(z))

    def spec(self):
        return {"kind": "casimir3", **self._spec_common()}

    @classmethod
    def from_spec(cls, spec, n, *, key):
        return cls(
            n,
            **network_kwargs(spec),
            key=key,
        )


@register("poisson", "casimir3-entropy")
class EntropyCasimirPoisson3(_Casimir3Base):
    r"""A learned 3-D bivector with the Jacobi identity **and** :math:`L\nabla S = 0` exact:

    .. math:: L_{ij} = \varepsilon_{ijk} w_k,\qquad w = \varphi(x)\,\nabla S(x),

    i.e. :class:`CasimirPoisson3` with the entropy as the Casimir. In 3-D this is the general
    exactly degenerate Poisson bivector near points where :math:`\nabla S \ne 0` (the kernel of
    a rank-2 :math:`[w]_\times` is :math:`w`). Where :math:`\nabla S = 0` it gives :math:`L=0`,
    so with an entropy that is zero (a conservative system) there are no reversible dynamics:
    use :class:`CasimirPoisson3` there. Here :math:`\varphi = 1 + \text{MLP}` is signed: the
    orientation of :math:`w` relative to the given :math:`\nabla S` must be learnable.
    """

    def __init__(
        self,
        n: int = 3,
        *,
        width: int = 64,
        depth: int = 2,
        activation: str = "softplus",
        scaling: Scaling | None = None,
        key,
    ):
        _check_three(n, "EntropyCasimirPoisson3")
        self.phi = _Scalar(width, depth, activation, key=key)
        self.n = n
        self.scaling = scaling

    def _factor(self, z: State):
        # 1 + network: at initialisation L ~ [grad S]_x rather than ~0.
        return 1.0 + self.phi(z)

    def __call__(self, x: State, grad_entropy: State) -> Matrix:
        s = self.scaling
        h = grad_entropy if s is None else jnp.asarray(s.scale, x.dtype) * grad_entropy
        return self._assemble(self._z(x), h)

    def spec(self):
        return {"kind": "casimir3-entropy", **self._spec_common()}

    @classmethod
    def from_spec(cls, spec, n, *, key):
        return cls(
            n,
            **network_kwargs(spec),
            key=key,
        )
