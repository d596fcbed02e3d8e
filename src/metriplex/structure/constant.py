r"""Constant operators that the user knows: a Poisson matrix :math:`L` or a friction matrix
:math:`M` given as numbers (read from ``.npy``, ``.npz`` or ``.mat`` by the command line).

Both are stored in the model file's header as plain numbers, so a saved model still needs
nothing but its file.
"""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._errors import MetriplexError
from .._types import Matrix, State
from ._registry import register
from .friction import AbstractFriction
from .poisson import AbstractPoisson


def _square(matrix, what: str) -> np.ndarray:
    a = np.asarray(matrix, dtype=np.float64)
    if a.ndim != 2 or a.shape[0] != a.shape[1] or a.shape[0] < 1:
        raise MetriplexError(f"{what} must be a square n x n matrix; got shape {a.shape}.")
    if not np.all(np.isfinite(a)):
        raise MetriplexError(f"{what} holds NaN or inf; every entry must be finite.")
    return a


def _frozen(a: np.ndarray) -> tuple[tuple[float, ...], ...]:
    return tuple(tuple(float(v) for v in row) for row in a)


@register("poisson", "constant")
class ConstantPoisson(AbstractPoisson):
    r"""A known constant Poisson matrix :math:`L` (antisymmetric; a constant bivector always
    satisfies the Jacobi identity).

    An input that is antisymmetric up to rounding (relative ``1e-8``) is made exactly
    antisymmetric, :math:`(L - L^\top)/2`; a larger asymmetry is an error.

    ```python
    L = ConstantPoisson(np.array([[0.0, 1.0], [-1.0, 0.0]]))
    ```
    """

    matrix: tuple[tuple[float, ...], ...] = eqx.field(static=True)
    n: int = eqx.field(static=True)

    def __init__(self, matrix):
        a = _square(matrix, "a constant Poisson matrix L")
        size = max(float(np.abs(a).max()), 1e-300)
        asym = float(np.abs(a + a.T).max())
        if asym > 1e-8 * size:
            raise MetriplexError(
                f"a Poisson matrix must be antisymmetric (L = -L^T); the given L has "
                f"max |L + L^T| = {asym:.3g} (entries up to {size:.3g}). Check that the file "
                "holds L and not M, and its orientation."
            )
        self.matrix = _frozen(0.5 * (a - a.T))
        self.n = a.shape[0]

    uses_gradient: ClassVar[bool] = False

    def __call__(self, x: State, grad_entropy: State | None = None) -> Matrix:
        return jnp.asarray(self.matrix, x.dtype)

    def spec(self):
        return {"kind": "constant", "matrix": [list(r) for r in self.matrix]}

    @classmethod
    def from_spec(cls, spec, n, *, key):
        return cls(spec["matrix"])


@register("friction", "constant")
class ConstantFriction(AbstractFriction):
    r"""A known constant friction matrix :math:`M` (symmetric positive semi-definite).

    An input that is symmetric up to rounding (relative ``1e-8``) is symmetrised; a larger
    asymmetry, or an eigenvalue below :math:`-10^{-8}\max|M|`, is an error.
    """

    matrix: tuple[tuple[float, ...], ...] = eqx.field(static=True)
    n: int = eqx.field(static=True)

    def __init__(self, matrix):
        a = _square(matrix, "a constant friction matrix M")
        size = max(float(np.abs(a).max()), 1e-300)
        asym = float(np.abs(a - a.T).max())
        if asym > 1e-8 * size:
            raise MetriplexError(
                f"a friction matrix must be symmetric (M = M^T); the given M has "
                f"max |M - M^T| = {asym:.3g} (entries up to {size:.3g}). Check that the file "
                "holds M and not L."
            )
        sym = 0.5 * (a + a.T)
        low = float(np.linalg.eigvalsh(sym).min())
        if low < -1e-8 * size:
            raise MetriplexError(
                f"a friction matrix must be positive semi-definite (dissipation >= 0); the given "
                f"M has the eigenvalue {low:.3g}. Check its sign convention (M, not -M)."
            )
        self.matrix = _frozen(sym)
        self.n = a.shape[0]

    uses_gradient: ClassVar[bool] = False

    def __call__(self, x: State, grad_energy: State | None = None) -> Matrix:
        return jnp.asarray(self.matrix, x.dtype)

    def spec(self):
        return {"kind": "constant", "matrix": [list(r) for r in self.matrix]}

    @classmethod
    def from_spec(cls, spec, n, *, key):
        return cls(spec["matrix"])
