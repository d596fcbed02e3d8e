r"""What the Poisson and friction blocks with a fixed matrix share: zero, a given function of
the state, or given numbers.

Each final block (:class:`~metriplex.ZeroPoisson`, :class:`~metriplex.ZeroFriction`,
:class:`~metriplex.KnownPoisson`, ...) combines one of these with its family's abstract base,
states its own ``uses_gradient`` (always ``False``: a fixed matrix ignores the gradient) and,
for the constant ones, checks its numbers (antisymmetric :math:`L`, symmetric PSD :math:`M`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Callable, Self

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._errors import MetriplexError
from .._types import Matrix, State

if TYPE_CHECKING:
    import jax
    from numpy.typing import ArrayLike


class AbstractZeroMatrix(eqx.Module):
    """The matrix 0 of size ``n``."""

    n: int = eqx.field(static=True)

    def __call__(self, x: State, gradient: State | None = None) -> Matrix:
        """The ``(n, n)`` zero matrix, whatever ``x`` and ``gradient``."""
        return jnp.zeros((self.n, self.n), x.dtype)

    def spec(self) -> dict[str, Any]:
        return {"kind": "zero"}

    @classmethod
    def from_spec(cls, spec: dict[str, Any], n: int, *, key: jax.Array) -> Self:
        """The zero matrix of size ``n`` (``spec`` and ``key`` are not needed)."""
        return cls(n)


class AbstractFunctionMatrix(eqx.Module):
    """The matrix ``fn(x)`` of a given function (ground-truth systems; not saved in files),
    of size ``n`` where its maker states it."""

    fn: Callable = eqx.field(static=True)
    n: int | None = eqx.field(static=True, default=None)

    def __call__(self, x: State, gradient: State | None = None) -> Matrix:
        """``fn(x)``; the gradient is not used."""
        return self.fn(x)


class AbstractConstantMatrix(eqx.Module):
    """Given numbers, stored in the model file's header (a saved model needs only its file)."""

    matrix: tuple[tuple[float, ...], ...] = eqx.field(static=True)
    n: int = eqx.field(static=True)

    def __call__(self, x: State, gradient: State | None = None) -> Matrix:
        """The given matrix in ``x``'s dtype; the state and the gradient are not used."""
        return jnp.asarray(self.matrix, x.dtype)

    def spec(self) -> dict[str, Any]:
        return {"kind": "constant", "matrix": [list(r) for r in self.matrix]}

    @classmethod
    def from_spec(cls, spec: dict[str, Any], n: int, *, key: jax.Array) -> Self:
        """The constant matrix saved in ``spec`` (``n`` and ``key`` are not needed)."""
        return cls(spec["matrix"])


def square_matrix(matrix: ArrayLike, what: str) -> np.ndarray:
    """``matrix`` as a finite square float64 array, or an error naming ``what``."""
    a = np.asarray(matrix, dtype=np.float64)
    if a.ndim != 2 or a.shape[0] != a.shape[1] or a.shape[0] < 1:
        raise MetriplexError(f"{what} must be a square n x n matrix; got shape {a.shape}.")
    if not np.all(np.isfinite(a)):
        raise MetriplexError(f"{what} holds NaN or inf; every entry must be finite.")
    return a


def frozen(a: np.ndarray) -> tuple[tuple[float, ...], ...]:
    """A hashable copy of a matrix (static fields must be hashable)."""
    return tuple(tuple(float(v) for v in row) for row in a)
