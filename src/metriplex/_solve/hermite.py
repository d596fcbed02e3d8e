"""The implicit fourth-order Hermite step (two-point Taylor, the (2, 2) Padé approximant)."""

from __future__ import annotations

from typing import ClassVar

import jax

from .._model import GenericModel, Terms
from .._types import Scalar, State
from ._implicit import AbstractImplicitScheme


def _rate_of_field(model: GenericModel, x: State, f: State) -> State:
    r"""The field's own rate along the flow, :math:`\dot f = (\partial f/\partial x)\,f`, at
    ``x`` where the field is ``f`` (one forward-mode product)."""
    return jax.jvp(model.vector_field, (x,), (f,))[1]


class Hermite(AbstractImplicitScheme):
    r"""The implicit Hermite step :math:`x_{n+1} = x_n + \tfrac{\Delta t}{2}(f_n + f_{n+1})
    + \tfrac{\Delta t^2}{12}(\dot f_n - \dot f_{n+1})`, with :math:`\dot f = (\partial
    f/\partial x)\, f` the field's rate along the flow. Fourth order and A-stable (its linear
    map is the (2, 2) Padé approximant of the exponential), so unlike :class:`RK4` a stiff
    learned field cannot blow a rollout up; each step costs about three times Crank–Nicolson's.
    Meant for data whose steps are coarse for their motion: a model trained on a scheme's
    residual learns the scheme's error at the data's step into its field, of order
    :math:`\Delta t^2` for Crank–Nicolson and :math:`\Delta t^4` here."""

    name: ClassVar[str] = "hermite"
    summary: ClassVar[str] = "implicit, fourth order: for coarse steps"

    def start(self, model: GenericModel, x0: State) -> tuple[State, State]:
        """The field at ``x0`` and its rate along the flow, computed once per step."""
        f0 = model.vector_field(x0)
        return f0, _rate_of_field(model, x0, f0)

    def average(self, model: GenericModel, x0: State, x1: State, start: tuple[State, State],
                dt: Scalar | float) -> State:
        """``(x1 - x0)/dt`` of the step, with ``start`` the field and its rate at ``x0``."""
        f0, g0 = start
        f1 = model.vector_field(x1)
        return 0.5 * (f0 + f1) + dt / 12.0 * (g0 - _rate_of_field(model, x1, f1))

    def residual(self, model: GenericModel, x0: State, x1: State, dt: Scalar, terms0: Terms,
                 terms1: Terms) -> State:
        f0, f1 = terms0.vector_field, terms1.vector_field
        g0, g1 = _rate_of_field(model, x0, f0), _rate_of_field(model, x1, f1)
        return (x1 - x0) / dt - 0.5 * (f0 + f1) - dt / 12.0 * (g0 - g1)
