"""The interface of a one-step scheme."""

from __future__ import annotations

import abc
import equinox as eqx
import jax

from .._model import GenericModel, Terms
from .._types import Scalar, State, States


class AbstractScheme(eqx.Module):
    """A one-step time integrator for a :class:`~metriplex.GenericModel`.

    A concrete scheme declares its ``name`` (how the command line and the files spell it) and
    a one-line ``summary`` (what the command line's help says of it); adding a scheme is its
    class in its own file plus one line in :data:`metriplex.integrate.SCHEMES`.
    """

    name: eqx.AbstractClassVar[str]
    summary: eqx.AbstractClassVar[str]

    @abc.abstractmethod
    def step(self, model: GenericModel, x: State, dt: Scalar | float,
             guess: State) -> tuple[State, jax.Array, jax.Array]:
        """One step of size ``dt`` from ``x``, the implicit solve started at ``guess``:
        ``(x_next, converged, iterations)``."""

    def step_batch(self, model: GenericModel, x: States, dt: jax.Array,
                   guess: States) -> tuple[States, jax.Array, jax.Array]:
        """:meth:`step` for a batch of states ``x`` ``(B, n)``, steps ``dt`` ``(B,)``."""
        return jax.vmap(lambda x, dt, g: self.step(model, x, dt, g))(x, dt, guess)

    def differentiable_step(self, model: GenericModel, x: State, dt: Scalar | float,
                            solved: State) -> State:
        r"""The step from ``x`` as a function that JAX can differentiate in ``model`` and
        ``x``, given the step's result ``solved`` (a constant: a root finder's result cannot
        be differentiated through). Explicit schemes return their step; implicit ones one
        update :math:`x + \Delta t\,\bar f(x, x_1)` at the solved :math:`x_1`, whose
        derivative is the implicit step's to first order in ``dt`` (the step's Jacobian
        factor :math:`(I - \Delta t\,\partial\bar f/\partial x_1)^{-1}` taken as ``I``).
        Used by :class:`~metriplex.RolloutWindow` to train through rollouts. By default the
        step itself, started at ``solved``."""
        return self.step(model, x, dt, solved)[0]

    @abc.abstractmethod
    def residual(self, model: GenericModel, x0: State, x1: State, dt: Scalar, terms0: Terms,
                 terms1: Terms) -> State:
        r"""The defect of the data pair ``x0 -> x1`` over a step ``dt`` under this scheme,
        :math:`(x_1 - x_0)/\Delta t` minus the scheme's field, shape ``(n,)``; ``terms0`` and
        ``terms1`` are :class:`~metriplex.Terms` at the two states, shared by every loss term (zero
        on data that the scheme made)."""
