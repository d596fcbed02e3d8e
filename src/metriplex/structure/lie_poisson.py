r"""A learned Lie–Poisson bivector: :math:`L(x)` linear in the state.

.. math:: L_{ij}(x) = \sum_k c_{ij}^{\,k}\,x_k,\qquad c_{ij}^{\,k} = -c_{ji}^{\,k},

the bracket on the dual of a Lie algebra with structure constants :math:`c` (the rigid body's
:math:`L(m) = -\varepsilon m` is one). It is the prior for rigid-body-like systems: far fewer
parameters than a network, and exact extrapolation wherever the truth is Lie–Poisson. The
Jacobi identity holds iff :math:`c` satisfies the Lie algebra's Jacobi identity; train with the
Jacobi penalty (``--jacobi exact``, the command line's default with ``--poisson lie-poisson``;
in Python ``JacobiPenalty(ExactJacobi())`` in the loss) to get it.
"""

from __future__ import annotations

from typing import Any, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np

from .._errors import MetriplexError
from .._types import Matrix, State
from ._registry import register
from ._abstract import AbstractPoisson
from .poisson import AbstractProjectedPoisson
from .scaling import Scaling, scaling_spec


@register("poisson", "lie-poisson")
class LiePoisson(AbstractPoisson):
    r"""Learned :math:`L_{ij}(x) = \sum_k c_{ij}^{\,k}x_k` (see the module docstring).

    With a :class:`~metriplex.structure.scaling.Scaling` the weights are dimensionless:
    :math:`L = f\,D\,\big(\sum_k \tilde c^{\,k} x_k/d_k\big)\,D^\top` (no shift: :math:`L` stays
    linear in :math:`x`, as a Lie–Poisson bracket must).

    ``linear_in``: the variables the sum runs over (default every one). The command line leaves
    out the entropy variables of ``--entropy sum:...``: an entropy's zero is arbitrary, and a
    new-user check's bath entropy recorded at 1000 made :math:`L` one constant matrix (its term
    :math:`c^{\,s}s` outweighed the rest by far) and the model worse than predicting no motion.

    ```python
    L = LiePoisson(3, key=jr.key(0))
    L(jnp.ones(3))  # antisymmetric, linear in x
    ```
    """

    weight: jax.Array  # (n, n, n): weight[k] is the (not yet antisymmetric) matrix for x_k
    n: int = eqx.field(static=True)
    scaling: Scaling | None = eqx.field(static=True)
    linear_in: tuple[int, ...] | None = eqx.field(static=True)

    def __init__(self, n: int, *, scaling: Scaling | None = None,
                 linear_in: tuple[int, ...] | None = None, key: jax.Array) -> None:
        if n < 2:
            raise MetriplexError(f"a Lie-Poisson bivector needs n >= 2 variables; got {n}.")
        if linear_in is not None and not (linear_in and all(0 <= k < n for k in linear_in)):
            raise MetriplexError(f"a Lie-Poisson bivector is linear in some of its {n} "
                                 f"variables, counted from 0; got linear_in={linear_in}. Give "
                                 f"one or more indices from 0 to {n - 1}, or None for all.")
        self.n = n
        self.scaling = scaling
        self.linear_in = None if linear_in is None else tuple(sorted(set(linear_in)))
        self.weight = jr.normal(key, (n, n, n)) / np.sqrt(
            n if linear_in is None else len(self.linear_in))

    uses_gradient: ClassVar[bool] = False

    def __call__(self, x: State, grad_entropy: State | None = None) -> Matrix:
        s = self.scaling
        z = x if s is None else x / jnp.asarray(s.scale, x.dtype)
        if self.linear_in is not None:
            z = z * jnp.asarray(np.isin(np.arange(self.n), self.linear_in), x.dtype)
        A = jnp.tensordot(z, self.weight.astype(x.dtype), axes=1)
        L = A - A.T
        return L if s is None else L * jnp.asarray(s.congruence(), x.dtype)

    def spec(self) -> dict[str, Any]:
        return {"kind": "lie-poisson", "scaling": scaling_spec(self.scaling),
                **({} if self.linear_in is None else {"linear_in": list(self.linear_in)})}

    @classmethod
    def from_spec(cls, spec: dict[str, Any], n: int, *, key: jax.Array) -> "LiePoisson":
        """The block that ``spec`` (the output of :meth:`spec`) describes, for ``n`` variables;
        ``key`` draws weights that the model file then overwrites."""
        linear_in = spec.get("linear_in")
        return cls(n, scaling=Scaling.from_json(spec.get("scaling")),
                   linear_in=None if linear_in is None else tuple(linear_in), key=key)


@register("poisson", "projected-lie-poisson")
class ProjectedLiePoisson(AbstractProjectedPoisson):
    r"""A :class:`LiePoisson` :math:`A(x)` with :math:`L\nabla S = 0` by construction:
    :math:`L = Q A Q^\top`, :math:`Q` the projector of
    :class:`~metriplex.structure.poisson.ProjectedSkewMLPPoisson` against :math:`\nabla S`.

    Where S is a sum of entropy variables its gradient is constant, and so is :math:`Q`:
    :math:`L` stays linear in the state (a Lie–Poisson bracket in which the entropy variables
    bracket with nothing), and the entropy never falls by L's doing. With another S, :math:`Q`
    varies with the state and :math:`L` is not linear: the command line builds it only beside
    a sum, with ``--degeneracy exact`` (not by default: on two systems it was less accurate
    than the plain block with the penalty L grad S = 0, docs/zoo.md).

    ```python
    L = ProjectedLiePoisson(4, key=jr.key(0))
    g = jnp.array([0.0, 0.0, 0.0, 1.0])  # S = x_3
    L(x, g) @ g  # ~ 0
    ```
    """

    network: ClassVar[type] = LiePoisson

    uses_gradient: ClassVar[bool] = True

    def spec(self) -> dict[str, Any]:
        return {**self.base.spec(), "kind": "projected-lie-poisson", "eps": self.eps}

    @classmethod
    def from_spec(cls, spec: dict[str, Any], n: int, *,
                  key: jax.Array) -> "ProjectedLiePoisson":
        """The block that ``spec`` (the output of :meth:`spec`) describes, for ``n`` variables;
        ``key`` draws weights that the model file then overwrites."""
        linear_in = spec.get("linear_in")
        return cls(n, scaling=Scaling.from_json(spec.get("scaling")), eps=spec.get("eps"),
                   linear_in=None if linear_in is None else tuple(linear_in), key=key)
