"""The implicit midpoint step."""

from __future__ import annotations

from typing import Any, ClassVar

from .._model import GenericModel, Terms
from .._types import Scalar, State
from ._implicit import AbstractImplicitScheme


class ImplicitMidpoint(AbstractImplicitScheme):
    r"""Implicit midpoint: :math:`\frac{x_{n+1}-x_n}{\Delta t} = f\big(\tfrac{x_n+x_{n+1}}2\big)`.
    Second order, symplectic; conserves quadratic invariants exactly."""

    name: ClassVar[str] = "midpoint"
    summary: ClassVar[str] = "implicit midpoint: keeps a quadratic E"

    def average(self, model: GenericModel, x0: State, x1: State, start: Any,
                dt: Scalar | float) -> State:
        r"""The field at the midpoint, :math:`f(\tfrac12(x_0 + x_1))` (``start`` is not needed)."""
        return model.vector_field(0.5 * (x0 + x1))

    def residual(self, model: GenericModel, x0: State, x1: State, dt: Scalar, terms0: Terms,
                 terms1: Terms) -> State:
        return (x1 - x0) / dt - model.vector_field(0.5 * (x0 + x1))


# --------------------------------------------------------------------------------------------
# Discrete gradients
