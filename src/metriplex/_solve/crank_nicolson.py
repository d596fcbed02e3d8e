"""The Crank–Nicolson (trapezoidal) step."""

from __future__ import annotations

from typing import ClassVar

from .._model import GenericModel, Terms
from .._types import Scalar, State
from ._implicit import AbstractImplicitScheme


class CrankNicolson(AbstractImplicitScheme):
    r"""Crank–Nicolson (trapezoidal rule): :math:`\frac{x_{n+1}-x_n}{\Delta t} =
    \tfrac12\big(f(x_n) + f(x_{n+1})\big)`. Second order; the seed paper's scheme."""

    name: ClassVar[str] = "cn"
    summary: ClassVar[str] = "Crank-Nicolson, the paper's scheme"

    def start(self, model: GenericModel, x0: State) -> State:
        """What the step needs of its first state: the field at ``x0``, computed once per step."""
        return model.vector_field(x0)

    def average(self, model: GenericModel, x0: State, x1: State, start: State,
                dt: Scalar | float) -> State:
        r"""The trapezoidal field :math:`\tfrac12(f(x_0) + f(x_1))`, with ``start`` the field at
        ``x0``."""
        return 0.5 * (start + model.vector_field(x1))

    def residual(self, model: GenericModel, x0: State, x1: State, dt: Scalar, terms0: Terms,
                 terms1: Terms) -> State:
        return (x1 - x0) / dt - 0.5 * (terms0.vector_field + terms1.vector_field)
