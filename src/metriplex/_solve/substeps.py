"""A scheme made of another: :class:`Substeps`, several steps of an inner scheme per recorded
step (the ground truth's fine substeps in :func:`metriplex.systems.generate`, and a rollout's
retry of a step whose solve failed, ``solve(retry=...)``)."""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp

from .._model import GenericModel, Terms
from .._types import Scalar, State
from ._scheme import AbstractScheme


class Substeps(AbstractScheme):
    r"""``count`` steps of ``inner``, each of size :math:`h = \Delta t/\text{count}`, per step.

    A one-step scheme like any other, so :func:`metriplex.solve` records only every
    ``count``-th state: :math:`x_{n+1} = \Phi_h^{\text{count}}(x_n)`. Converged only if every
    inner step converged.

    ```python
    out = mx.solve(model, x0, ts, scheme=Substeps(mx.RK4(), 20))
    ```
    """

    name: ClassVar[str] = "substeps"
    summary: ClassVar[str] = "several steps of an inner scheme per recorded step"
    inner: AbstractScheme
    count: int = eqx.field(static=True)

    def step(self, model: GenericModel, x: State, dt: Scalar | float,
             guess: State) -> tuple[State, jax.Array, jax.Array]:
        h = dt / self.count
        int_dtype = jnp.asarray(0).dtype

        def body(_, carry):
            y, dy, ok, its = carry
            y1, ok1, its1 = self.inner.step(model, y, h, y + dy)
            return y1, y1 - y, ok & ok1, its + jnp.asarray(its1, int_dtype)

        init = (x, (guess - x) / self.count, jnp.asarray(True), jnp.zeros((), int_dtype))
        y, _, ok, its = jax.lax.fori_loop(0, self.count, body, init)
        return y, ok, its

    def residual(self, model: GenericModel, x0: State, x1: State, dt: Scalar, terms0: Terms,
                 terms1: Terms) -> State:
        """The defect of the data pair ``x0 -> x1`` against ``count`` inner steps from ``x0``, over
        ``dt``; ``terms0`` and ``terms1`` are not needed."""
        return (x1 - self.step(model, x0, dt, x0)[0]) / dt
