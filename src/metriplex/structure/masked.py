r"""Blocks that hold some variables constant: :class:`MaskedPoisson` and :class:`MaskedFriction`
wrap a block and zero the rows and columns of the ``constant`` variables,

.. math:: L' = P L P,\qquad M' = P M P,\qquad P = \operatorname{diag}(p),\
          p_i = 0 \text{ for a constant variable, 1 otherwise,}

so those variables have rate zero whatever the weights, while the potentials may still depend on
them (a parameter recorded with the data: a shear rate, a stiffness, a set temperature). The
wrapped block is called with the masked gradient :math:`P\nabla S` (:math:`P\nabla E`), so an
exactly degenerate block stays exactly degenerate: :math:`L'\nabla S = P L (P\nabla S) = 0`.
:math:`L'` is antisymmetric and :math:`M'` symmetric positive semi-definite when the wrapped
matrices are. The Jacobi identity of :math:`L'` is that of :math:`L` restricted to the other
variables, with the constant ones as parameters; a Jacobi penalty evaluates :math:`L'`.
"""

from __future__ import annotations

from typing import Any, ClassVar, Self, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._errors import MetriplexError, expect_instance
from .._types import Matrix, State
from ._abstract import AbstractFriction, AbstractPoisson, _AbstractMatrix
from ._registry import from_spec, register


def check_constant(constant: Sequence[Any], n: int) -> tuple[int, ...]:
    """The sorted indices of the variables held constant: integers in ``[0, n)``, not all of
    them."""
    idx = [int(i) for i in constant]
    if any(not 0 <= i < n for i in idx) or len(set(idx)) != len(idx) or len(idx) >= n:
        raise MetriplexError(
            f"the variables held constant must be distinct indices in [0, {n - 1}], fewer than "
            f"the n={n} variables; got {list(constant)}. Count state columns from 0."
        )
    return tuple(sorted(idx))


class _AbstractMasked(eqx.Module):
    """A wrapped block (``base``) whose matrix has zero rows and columns at ``constant``."""

    base: _AbstractMatrix
    constant: tuple[int, ...] = eqx.field(static=True)
    n: int = eqx.field(static=True)

    def __init__(self, base: _AbstractMatrix, constant: Sequence[int]) -> None:
        expect_instance(base, _AbstractMatrix, what=f"{type(self).__name__}'s base",
                        expected="a Poisson or friction block (e.g. SkewMLPPoisson(n, key=k))")
        n = base.n
        if n is None:
            raise MetriplexError(
                f"{type(self).__name__} wraps a block that states its size n (a learned or "
                f"constant block); {type(base).__name__} does not. Wrap the learned block, or "
                "give the known matrix with the rows and columns of the constant variables "
                "already zero."
            )
        self.base = base
        self.constant = check_constant(constant, n)
        self.n = n

    def _keep(self, dtype: Any) -> jax.Array:
        keep = np.ones(self.n)
        keep[list(self.constant)] = 0.0
        return jnp.asarray(keep, dtype)

    def __call__(self, x: State, gradient: State | None = None) -> Matrix:
        """The wrapped matrix at ``x`` (given the masked gradient) with the rows and columns of
        the constant variables zero."""
        keep = self._keep(x.dtype)
        a = self.base(x, None if gradient is None else keep * gradient)
        return keep[:, None] * a * keep[None, :]

    def spec(self) -> dict[str, Any]:
        return {"kind": "masked", "constant": list(self.constant), "base": self.base.spec()}

    @classmethod
    def from_spec(cls, spec: dict[str, Any], n: int, *, key: jax.Array) -> Self:
        """The masked block of the saved spec: its wrapped block rebuilt from ``spec["base"]``."""
        family = "poisson" if issubclass(cls, AbstractPoisson) else "friction"
        return cls(from_spec(family, spec["base"], n, key=key), spec["constant"])


@register("poisson", "masked")
class MaskedPoisson(_AbstractMasked, AbstractPoisson):
    r""":math:`L' = PLP`: the Poisson block ``base`` with the rows and columns of the
    ``constant`` variables zero, so they are Casimirs (rate zero) of the reversible part.

    ```python
    L = MaskedPoisson(SkewMLPPoisson(4, key=key), constant=(3,))  # x[3] is a parameter
    ```
    """

    # The wrapped block may read the gradient (an exactly degenerate one), so a matrix
    # computed with another gradient is never reused.
    uses_gradient: ClassVar[bool] = True


@register("friction", "masked")
class MaskedFriction(_AbstractMasked, AbstractFriction):
    r""":math:`M' = PMP`: the friction block ``base`` with the rows and columns of the
    ``constant`` variables zero, so friction never moves them.

    ```python
    M = MaskedFriction(CholeskyFriction(4, key=key), constant=(3,))
    ```
    """

    # The wrapped block may read the gradient (an exactly degenerate one), so a matrix
    # computed with another gradient is never reused.
    uses_gradient: ClassVar[bool] = True
