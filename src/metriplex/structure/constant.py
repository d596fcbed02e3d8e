r"""Constant operators that the user knows: a Poisson matrix :math:`L` or a friction matrix
:math:`M` given as numbers (read from ``.npy``, ``.npz`` or ``.mat`` by the command line).

Both are stored in the model file's header as plain numbers, so a saved model still needs
nothing but its file.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, ClassVar

import numpy as np

from .._errors import MetriplexError
from ._abstract import AbstractFriction, AbstractPoisson
from ._fixed import AbstractConstantMatrix, frozen, square_matrix
from ._registry import register

if TYPE_CHECKING:
    from numpy.typing import ArrayLike


#: The relative rounding a given constant L or M may carry: entries typed to six significant
#: digits (5e-7 relative at worst) or stored in float32 (6e-8).
ROUNDING = 1e-6


@register("poisson", "constant")
class ConstantPoisson(AbstractConstantMatrix, AbstractPoisson):
    r"""A known constant Poisson matrix :math:`L` (antisymmetric; a constant bivector always
    satisfies the Jacobi identity).

    An input that is antisymmetric up to rounding (relative :data:`ROUNDING`) is made exactly
    antisymmetric, :math:`(L - L^\top)/2`; a larger asymmetry is an error.

    ```python
    L = ConstantPoisson(np.array([[0.0, 1.0], [-1.0, 0.0]]))
    ```
    """

    def __init__(self, matrix: ArrayLike) -> None:
        a = square_matrix(matrix, "a constant Poisson matrix L")
        size = max(float(np.abs(a).max()), 1e-300)
        asym = float(np.abs(a + a.T).max())
        if asym > ROUNDING * size:
            raise MetriplexError(
                f"a Poisson matrix must be antisymmetric (L = -L^T); the given L has "
                f"max |L + L^T| = {asym:.3g} (entries up to {size:.3g}). Check that the file "
                "holds L and not M, and its orientation."
            )
        self.matrix = frozen(0.5 * (a - a.T))
        self.n = a.shape[0]

    uses_gradient: ClassVar[bool] = False


@register("friction", "constant")
class ConstantFriction(AbstractConstantMatrix, AbstractFriction):
    r"""A known constant friction matrix :math:`M` (symmetric positive semi-definite).

    An input that is symmetric up to rounding (relative :data:`ROUNDING`) is symmetrised, and
    its eigenvalues below zero by no more than the rounding of its entries (:data:`ROUNDING`
    :math:`\cdot\, n \max|M|`: a matrix typed to six digits, or stored in float32, that has
    the null space M grad E = 0 asks for) are set to zero; a larger asymmetry or negative
    eigenvalue is an error.
    """

    def __init__(self, matrix: ArrayLike) -> None:
        a = square_matrix(matrix, "a constant friction matrix M")
        size = max(float(np.abs(a).max()), 1e-300)
        asym = float(np.abs(a - a.T).max())
        if asym > ROUNDING * size:
            raise MetriplexError(
                f"a friction matrix must be symmetric (M = M^T); the given M has "
                f"max |M - M^T| = {asym:.3g} (entries up to {size:.3g}). Check that the file "
                "holds M and not L."
            )
        values, vectors = np.linalg.eigh(0.5 * (a + a.T))
        if values.min() < -ROUNDING * a.shape[0] * size:
            raise MetriplexError(
                f"a friction matrix must be positive semi-definite (dissipation >= 0); the given "
                f"M has the eigenvalue {values.min():.3g} (entries up to {size:.3g}), beyond "
                f"the rounding of its entries. Check its sign convention (M, not -M)."
            )
        self.matrix = frozen((vectors * np.maximum(values, 0.0)) @ vectors.T)
        self.n = a.shape[0]

    uses_gradient: ClassVar[bool] = False
