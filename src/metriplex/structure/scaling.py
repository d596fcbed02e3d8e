r"""State normalisation that keeps the GENERIC structure.

Learned networks see standardised inputs :math:`\tilde x = D^{-1}(x - c)`. Under this change of
variables a scalar potential transforms as :math:`E(x) = \tilde E(\tilde x)`, while the
bivectors transform as contravariant 2-tensors,

.. math:: L(x) = D\,\tilde L(\tilde x)\,D^\top, \qquad M(x) = D\,\tilde M(\tilde x)\,D^\top,

so that :math:`L\nabla E = D\,\tilde L\,\tilde\nabla\tilde E` and the dynamics are the same in
both coordinates. Antisymmetry, symmetry, positive semi-definiteness, degeneracy and the Jacobi
identity are all invariant under this congruence. This module is the one place where the rule
lives; the networks fold it into their last layer.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .._errors import MetriplexError
from ._mlp import data_statistics


@dataclasses.dataclass(frozen=True)
class Scaling:
    """An affine normalisation ``x = shift + scale * x_tilde`` with a diagonal ``scale``."""

    shift: tuple[float, ...]
    scale: tuple[float, ...]

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

    @classmethod
    def identity(cls, n: int) -> "Scaling":
        return cls((0.0,) * n, (1.0,) * n)

    @classmethod
    def from_data(cls, x) -> "Scaling":
        """Per-component mean and standard deviation of states ``x`` (shape ``(N, n)``)."""
        shift, scale = data_statistics(np.asarray(x))
        return cls(shift, scale)

    def row_scale(self, triangle: str) -> tuple[float, ...]:
        """Row factors that turn a flat ``n*n`` matrix ``A`` into ``D A D^T`` (skew) or
        ``D B`` (lower; then ``M = (D B)(D B)^T = D B B^T D^T``)."""
        d = np.asarray(self.scale)
        if triangle == "skew":
            return tuple(float(v) for v in np.outer(d, d).ravel())
        return tuple(float(v) for v in np.repeat(d, len(d)))

    def to_json(self) -> dict:
        return {"shift": list(self.shift), "scale": list(self.scale)}

    @classmethod
    def from_json(cls, obj) -> "Scaling | None":
        return None if obj is None else cls(tuple(obj["shift"]), tuple(obj["scale"]))
