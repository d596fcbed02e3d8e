"""The implicit midpoint step."""

from __future__ import annotations

from typing import ClassVar


from ._implicit import _Implicit


class ImplicitMidpoint(_Implicit):
    r"""Implicit midpoint: :math:`\frac{x_{n+1}-x_n}{\Delta t} = f\big(\tfrac{x_n+x_{n+1}}2\big)`.
    Second order, symplectic; conserves quadratic invariants exactly."""

    name: ClassVar[str] = "midpoint"
    summary: ClassVar[str] = "implicit midpoint: keeps a quadratic E"

    def average(self, model, x0, x1, start):
        return model.vector_field(0.5 * (x0 + x1))

    def residual(self, model, x0, x1, dt, terms0, terms1):
        return (x1 - x0) / dt - model.vector_field(0.5 * (x0 + x1))


# --------------------------------------------------------------------------------------------
# Discrete gradients
