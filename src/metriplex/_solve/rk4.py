"""The explicit fourth-order Runge–Kutta step."""

from __future__ import annotations

from typing import ClassVar

import jax
import jax.numpy as jnp

from .._model import GenericModel, Terms
from .._types import Scalar, State
from ._scheme import AbstractScheme


class RK4(AbstractScheme):
    """Classical explicit fourth-order Runge–Kutta (a reference scheme; no structure kept)."""

    name: ClassVar[str] = "rk4"
    summary: ClassVar[str] = "explicit, fourth order: no implicit solve"

    def advance(self, model: GenericModel, x: State, dt: Scalar | float) -> State:
        """The state one classical Runge–Kutta step of size ``dt`` after ``x``."""
        f = model.vector_field
        k1 = f(x)
        k2 = f(x + 0.5 * dt * k1)
        k3 = f(x + 0.5 * dt * k2)
        k4 = f(x + dt * k3)
        return x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)

    def step(self, model: GenericModel, x: State, dt: Scalar | float,
             guess: State) -> tuple[State, jax.Array, jax.Array]:
        y = self.advance(model, x, dt)
        return y, jnp.all(jnp.isfinite(y)), jnp.array(0)

    def residual(self, model: GenericModel, x0: State, x1: State, dt: Scalar, terms0: Terms,
                 terms1: Terms) -> State:
        return (x1 - self.advance(model, x0, dt)) / dt
