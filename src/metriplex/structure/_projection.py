r"""The projector that makes a learned matrix exactly degenerate: the vectors of
:math:`Q = I - D^2 g g^\top/(|Dg|^2 + \varepsilon^2)` for a potential's gradient :math:`g`, and
:class:`AbstractProjected`, what the two blocks built with it share:
:class:`~metriplex.ProjectedSkewMLPPoisson` (:math:`L\nabla S = 0`) and
:class:`~metriplex.ProjectedCholeskyFriction` (:math:`M\nabla E = 0`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, ClassVar, Self

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._errors import MetriplexError
from .._types import State

if TYPE_CHECKING:
    from jax.typing import DTypeLike

    from .scaling import Scaling


def default_eps(eps: float | None, dtype: DTypeLike) -> float:
    """The regulariser of the projectors: machine epsilon of the working dtype by default."""
    return float(jnp.finfo(dtype).eps) if eps is None else float(eps)


def eps_squared(eps: float | None, dtype: DTypeLike) -> float:
    r""":math:`\varepsilon^2` of the projectors (:func:`default_eps`), floored at the dtype's
    smallest normal number so that it cannot underflow to zero."""
    return max(default_eps(eps, dtype) ** 2, float(jnp.finfo(dtype).tiny))


def check_eps(eps: float | None) -> None:
    if eps is not None and not (np.isfinite(eps) and eps > 0.0):
        raise MetriplexError(
            f"`eps` (the projector's regulariser) must be finite and > 0, or None for machine "
            f"epsilon; got {eps}."
        )


def projector_vectors(g: State, scale: tuple[float, ...] | None,
                      eps: float) -> tuple[State, State]:
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


class AbstractProjected(eqx.Module):
    """A learned network of its family (``network``, built from the same options) whose matrix
    is projected against a potential's gradient with the regulariser ``eps``; saved as the
    network's spec plus ``eps``."""

    network: ClassVar[type]
    base: eqx.Module
    n: int = eqx.field(static=True)
    eps: float | None = eqx.field(static=True)

    def __init__(self, n: int, *, eps: float | None = None, key: jax.Array,
                 **options: Any) -> None:
        check_eps(eps)
        self.base = self.network(n, key=key, **options)
        self.n = n
        self.eps = None if eps is None else float(eps)

    @property
    def scaling(self) -> Scaling | None:
        return self.base.scaling

    def _projector(self, gradient: State, dtype):
        r""":math:`\hat g, \hat u` of :func:`projector_vectors` in the network's scaling."""
        s = self.base.scaling
        return projector_vectors(
            gradient, None if s is None else s.scale, default_eps(self.eps, dtype)
        )

    def spec(self) -> dict[str, Any]:
        return {**self.base.spec(), "kind": "projected-neural", "eps": self.eps}

    @classmethod
    def from_spec(cls, spec: dict[str, Any], n: int, *, key: jax.Array) -> Self:
        return cls(n, **cls.network.spec_options(spec), eps=spec.get("eps"), key=key)
