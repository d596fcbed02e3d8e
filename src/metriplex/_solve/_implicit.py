r"""What the implicit schemes share: the step :math:`x_1 = x_0 + \Delta t\,\bar f(x_0, x_1)`,
solved by the scheme's root finder (:mod:`metriplex._solve.root_finder`)."""

from __future__ import annotations

import abc
from typing import Any

import jax
import jax.numpy as jnp

from .._errors import expect_instance
from .._model import GenericModel
from .._types import Scalar, State, States
from ._scheme import AbstractScheme
from .root_finder import AbstractRootFinder, FixedPointThenNewton


class AbstractImplicitScheme(AbstractScheme):
    r"""A step :math:`x_1 = x_0 + \Delta t\,\bar f(x_0, x_1)`, solved by ``root_finder``.

    ``root_finder``: how the step is solved, an :class:`~metriplex.integrate.AbstractRootFinder`
    with its own tolerances and iteration limits:

    - :class:`~metriplex.integrate.FixedPointThenNewton` (default): fixed-point iteration
      :math:`x_1 \leftarrow x_0 + \Delta t\,\bar f(x_0, x_1)` from the rollout's predictor,
      **Newton** for the steps where it does not converge (in a batched rollout, one batched
      Newton solve whenever any trajectory needs it). For non-stiff steps the fixed point
      converges in a few iterations, each one evaluation of the vector field, where a Newton
      iteration also builds and solves with an :math:`n\times n` Jacobian.
    - :class:`~metriplex.integrate.Newton`: Newton only (stiff models, e.g. fast heat
      conduction, where the fixed point diverges at every step and the fallback would only add
      work).
    - :class:`~metriplex.integrate.FixedPoint`: fixed-point iteration only; a step where it
      does not converge fails.

    ```python
    scheme = mx.CrankNicolson(root_finder=mx.Newton(rtol=1e-13, atol=1e-13))
    ```

    Subclasses give the scheme's average of the vector field, :meth:`average`, and may compute
    once per step, in :meth:`start`, whatever of it depends on ``x0`` only (it is then not
    re-evaluated at every iteration).
    """

    root_finder: AbstractRootFinder = FixedPointThenNewton()

    def __check_init__(self):
        expect_instance(
            self.root_finder, AbstractRootFinder, what="root_finder",
            expected="a root finder such as FixedPointThenNewton() (the default), Newton() or "
            "FixedPoint() (metriplex.integrate)",
        )

    def start(self, model: GenericModel, x0: State) -> Any:
        """The part of the average that depends on ``x0`` alone (default: nothing)."""
        return None

    @abc.abstractmethod
    def average(self, model: GenericModel, x0: State, x1: State, start: Any,
                dt: Scalar | float) -> State:
        """The scheme's average of the vector field over the step of size ``dt``, ``(x1 -
        x0)/dt``."""

    def increment(self, model: GenericModel, x0: State, x1: State,
                  dt: Scalar | float) -> State:
        """The average of the vector field over the step ``dt`` from ``x0`` to ``x1``
        (:meth:`average` with its :meth:`start`)."""
        return self.average(model, x0, x1, self.start(model, x0), dt)

    def differentiable_step(self, model: GenericModel, x: State, dt: Scalar | float,
                            solved: State) -> State:
        return x + dt * self.increment(model, x, solved, dt)

    def step(self, model: GenericModel, x: State, dt: Scalar | float,
             guess: State) -> tuple[State, jax.Array, jax.Array]:
        y, ok, its = self.step_batch(model, x[None], jnp.asarray(dt)[None], guess[None])
        return y[0], ok[0], its[0]

    def step_batch(self, model: GenericModel, x: States, dt: jax.Array,
                   guess: States) -> tuple[States, jax.Array, jax.Array]:
        # What depends on x0 alone is computed once, for every iteration of the root finder.
        pre = jax.vmap(lambda x: self.start(model, x))(x)

        def update(x0, x1, args):
            dt, pre = args
            return dt * self.average(model, x0, x1, pre, dt)

        return self.root_finder.solve_batch(update, x, guess, (dt, pre))
