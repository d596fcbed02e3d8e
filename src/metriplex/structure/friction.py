r"""Friction matrices :math:`M(x)`: symmetric positive semi-definite.

Every friction block is called as ``friction(x, grad_energy)``, so that exactly degenerate
variants (:math:`M\nabla E = 0` by construction) can use the energy gradient.
"""

from __future__ import annotations

import abc
from typing import Any, Callable

import equinox as eqx
import jax.numpy as jnp
import jax.random as jr

from .._errors import MetriplexError
from .._types import Matrix, State
from ._mlp import FoldedHead, Hidden, standardise
from ._registry import not_serialisable, register
from .scaling import Scaling


class AbstractFriction(eqx.Module):
    """A symmetric positive semi-definite matrix field ``M(x)``."""

    @abc.abstractmethod
    def __call__(self, x: State, grad_energy: State) -> Matrix: ...

    def spec(self) -> dict[str, Any]:
        raise not_serialisable(self)


@register("friction", "mlp")
class CholeskyFriction(AbstractFriction):
    r"""Learned :math:`M(x) = B(x)B(x)^\top` with :math:`B` lower-triangular.

    :math:`B` has :math:`n(n+1)/2` network outputs; :math:`M` is symmetric and positive
    semi-definite for any weights. With a scaling, :math:`M = D\tilde B\tilde B^\top D^\top`.
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
        if n < 1:
            raise MetriplexError(f"a friction matrix needs n >= 1 variables; got {n}.")
        self.n = n
        self.scaling = scaling
        hkey, okey = jr.split(key)
        self.hidden = Hidden(n, width, depth, activation, key=hkey)
        rs = None if scaling is None else scaling.row_scale("lower")
        # Small initial B: training starts close to reversible dynamics.
        self.head = FoldedHead(width, n, "lower", rs, 0.1, key=okey)

    def factor(self, x: State) -> Matrix:
        s = self.scaling
        z = x if s is None else standardise(x, s.shift, s.scale)
        return self.head(self.hidden(z))

    def __call__(self, x: State, grad_energy: State | None = None) -> Matrix:
        B = self.factor(x)
        return B @ B.T

    def spec(self):
        return {
            "kind": "mlp",
            "width": self.head.weight.shape[1],
            "depth": len(self.hidden.layers),
            "activation": self.hidden.activation,
            "scaling": None if self.scaling is None else self.scaling.to_json(),
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


@register("friction", "zero")
class ZeroFriction(AbstractFriction):
    """No dissipation: ``M = 0``."""

    n: int = eqx.field(static=True)

    def __call__(self, x: State, grad_energy: State | None = None) -> Matrix:
        return jnp.zeros((self.n, self.n), x.dtype)

    def spec(self):
        return {"kind": "zero"}

    @classmethod
    def from_spec(cls, spec, n, *, key):
        return cls(n)


class KnownFriction(AbstractFriction):
    """A friction matrix given by a function ``fn(x) -> (n, n)`` (ground-truth systems)."""

    fn: Callable = eqx.field(static=True)

    def __call__(self, x: State, grad_energy: State | None = None) -> Matrix:
        return self.fn(x)
