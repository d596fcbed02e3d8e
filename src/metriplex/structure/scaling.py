r"""State normalisation that keeps the GENERIC structure.

Learned networks see standardised inputs :math:`\tilde x = D^{-1}(x - c)`. Under this change of
variables a scalar potential transforms as :math:`E(x) = \tilde E(\tilde x)`, while the
bivectors transform as contravariant 2-tensors,

.. math:: L(x) = D\,\tilde L(\tilde x)\,D^\top, \qquad M(x) = D\,\tilde M(\tilde x)\,D^\top,

so that :math:`L\nabla E = D\,\tilde L\,\tilde\nabla\tilde E` and the dynamics are the same in
both coordinates. A positive ``factor`` :math:`f` carries the units of time and of the
potential that the bivector pairs with: :math:`L = f\,D\tilde L D^\top`. With
:math:`f = 1/(\tau\sigma)` (:math:`\tau` the data's time scale, :math:`\sigma` the scale of
:math:`E` for :math:`L`, of :math:`S` for :math:`M`) a network of order one gives rates of the
data's order, whatever the units of time (see :class:`metriplex.Units`). Antisymmetry, symmetry, positive semi-definiteness, degeneracy and the Jacobi
identity are all invariant under this congruence. This module is the one place where the rule
lives; the networks fold it into their last layer.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any

import numpy as np

from .._errors import MetriplexError
from .._types import State
from ._mlp import data_statistics, standardise

if TYPE_CHECKING:
    from numpy.typing import ArrayLike


@dataclasses.dataclass(frozen=True)
class Scaling:
    """An affine normalisation ``x = shift + scale * x_tilde`` with a diagonal ``scale``."""

    shift: tuple[float, ...]
    scale: tuple[float, ...]
    factor: float = 1.0

    def __post_init__(self):
        if len(self.shift) != len(self.scale):
            raise MetriplexError(
                f"Scaling needs shift and scale of equal length; got {len(self.shift)} and "
                f"{len(self.scale)}."
            )
        if any(not np.isfinite(s) or s <= 0 for s in self.scale):
            raise MetriplexError(
                f"Scaling.scale must be finite and > 0; got {self.scale}. Constant columns get "
                "scale 1 from `Scaling.from_data`."
            )
        if not (np.isfinite(self.factor) and self.factor > 0):
            raise MetriplexError(
                f"Scaling.factor must be finite and > 0; got {self.factor}. It is 1/(time scale "
                "x potential scale) of the data; leave it at 1 for no time scaling."
            )

    @classmethod
    def identity(cls, n: int) -> "Scaling":
        """No scaling for ``n`` variables: shift 0, scale 1, factor 1."""
        return cls((0.0,) * n, (1.0,) * n)

    @classmethod
    def from_data(cls, x: ArrayLike, factor: float = 1.0) -> "Scaling":
        """Per-component mean and standard deviation of states ``x`` (shape ``(N, n)``)."""
        shift, scale = data_statistics(np.asarray(x))
        return cls(shift, scale, float(factor))

    def congruence(self) -> np.ndarray:
        r"""The ``(n, n)`` factors :math:`f\,d_i d_j` of :math:`L = f D\tilde L D^\top`."""
        d = np.asarray(self.scale)
        return self.factor * np.outer(d, d)

    def row_scale(self, triangle: str) -> tuple[float, ...]:
        r"""Row factors that turn a flat ``n*n`` matrix :math:`A` into :math:`fDAD^\top`
        (skew) or :math:`\sqrt f DB` (lower; then :math:`M = fDBB^\top D^\top`)."""
        d = np.asarray(self.scale)
        if triangle == "skew":
            return tuple(float(v) for v in self.congruence().ravel())
        return tuple(float(v) for v in np.sqrt(self.factor) * np.repeat(d, len(d)))

    def to_json(self) -> dict:
        """The fields as JSON: :meth:`from_json` rebuilds the scaling."""
        return {"shift": list(self.shift), "scale": list(self.scale), "factor": self.factor}

    @classmethod
    def from_json(cls, obj: dict[str, Any] | None) -> "Scaling | None":
        """The scaling that :meth:`to_json` wrote, or ``None`` for ``None`` (no scaling)."""
        if obj is None:
            return None
        return cls(tuple(obj["shift"]), tuple(obj["scale"]), float(obj.get("factor", 1.0)))


def scaling_spec(scaling: Scaling | None) -> dict | None:
    """What a block's ``spec()`` records of its scaling (``None`` for none)."""
    return None if scaling is None else scaling.to_json()


def standardise_state(x: State, scaling: Scaling | None) -> State:
    """What a block's network sees of the state: :math:`D^{-1}(x - c)`, or ``x`` itself without
    a scaling."""
    return x if scaling is None else standardise(x, scaling.shift, scaling.scale)
