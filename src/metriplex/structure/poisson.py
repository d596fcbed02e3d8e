r"""Poisson bivectors :math:`L(x)`: antisymmetric, ideally satisfying the Jacobi identity.

Every Poisson block is called as ``poisson(x, grad_entropy)``; the gradient of the entropy is
passed so that exactly degenerate variants (:math:`L\nabla S = 0` by construction) can use it.
"""

from __future__ import annotations

import abc
from typing import Any, Callable

import equinox as eqx
import jax.numpy as jnp
import jax.random as jr
import numpy as np

from .._errors import MetriplexError
from .._types import Matrix, State
from ._mlp import FoldedHead, Hidden, standardise
from ._registry import not_serialisable, register
from .scaling import Scaling


class AbstractPoisson(eqx.Module):
    """An antisymmetric matrix field ``L(x)``."""

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
            width=spec["width"],
            depth=spec["depth"],
            activation=spec.get("activation", "softplus"),
            scaling=Scaling.from_json(spec.get("scaling")),
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

    def __call__(self, x: State, grad_entropy: State | None = None) -> Matrix:
        return self.fn(x)
