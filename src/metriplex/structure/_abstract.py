r"""The abstract bases of the four GENERIC blocks; every concrete block is a final class.

- :class:`AbstractPotential`: a scalar :math:`E(x)` or :math:`S(x)`;
- :class:`AbstractPoisson`: an antisymmetric :math:`L(x)`, called as ``poisson(x, grad_entropy)``;
- :class:`AbstractFriction`: a symmetric PSD :math:`M(x)`, called as ``friction(x, grad_energy)``.

The gradient is passed so that exactly degenerate blocks (:math:`L\nabla S = 0` or
:math:`M\nabla E = 0` by construction) can use it; each final class states in ``uses_gradient``
whether it does (an abstract class variable, as Equinox's abstract/final rule asks: declared
here, given once by every concrete class, never overridden).

(No ``from __future__ import annotations`` here: Equinox reads ``AbstractClassVar`` from the
evaluated annotation.)
"""

import abc
from typing import Any

import equinox as eqx

from .._types import Matrix, Scalar, State
from ._registry import not_serialisable


class _AbstractBlock(eqx.Module):
    """What every block offers: its spec for a model file (none by default: a block that wraps
    code cannot be written)."""

    def spec(self) -> dict[str, Any]:
        """A JSON-able description of the block (its registered ``kind`` and options) that
        ``from_spec`` turns back into the same architecture; raises for a block that wraps code."""
        raise not_serialisable(self)


class AbstractPotential(_AbstractBlock):
    """A scalar function of the state."""

    @abc.abstractmethod
    def __call__(self, x: State) -> Scalar:
        """The potential's value at the state ``x``: a scalar."""


class _AbstractMatrix(_AbstractBlock):
    """A matrix field called with the state and a potential's gradient."""

    #: Whether the matrix depends on the gradient argument (exactly degenerate blocks); if not,
    #: a matrix computed with another gradient can be reused.
    uses_gradient: eqx.AbstractClassVar[bool]
    #: The number of state variables; ``None`` only for a given function whose maker did not
    #: state it (``KnownPoisson(fn)``).
    n: eqx.AbstractVar[int | None]


class AbstractPoisson(_AbstractMatrix):
    """An antisymmetric matrix field ``L(x)``."""

    @abc.abstractmethod
    def __call__(self, x: State, grad_entropy: State) -> Matrix:
        r"""The antisymmetric :math:`L(x)`, shape ``(n, n)``, given :math:`\nabla S(x)` (which only
        an exactly degenerate block reads; see ``uses_gradient``)."""


class AbstractFriction(_AbstractMatrix):
    """A symmetric positive semi-definite matrix field ``M(x)``."""

    @abc.abstractmethod
    def __call__(self, x: State, grad_energy: State) -> Matrix:
        r"""The symmetric positive semi-definite :math:`M(x)`, shape ``(n, n)``, given
        :math:`\nabla E(x)` (which only an exactly degenerate block reads; see
        ``uses_gradient``)."""
