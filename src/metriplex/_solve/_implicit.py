"""What the implicit schemes share: the root finders (fixed-point iteration with a Newton
fallback) and the step built on them."""

from __future__ import annotations

import abc
from typing import Any, Callable

import jax
import jax.numpy as jnp
import optimistix as optx

from .._errors import MetriplexError
from .._model import GenericModel
from .._types import Scalar, State, States
from ._scheme import AbstractScheme, _tolerance


class _FixedPointIteration(optx.FixedPointIteration):
    """Optimistix's fixed-point iteration, with its error estimate in the state's dtype.

    Upstream starts the estimate as ``jnp.array(inf)``, which is float64 when x64 is enabled;
    a float32 state then changes the loop carry's dtype and the solve fails to trace.
    """

    def init(self, fn: Callable[..., Any], y: State, args: Any, options: dict[str, Any],
             f_struct: Any, aux_struct: Any, tags: frozenset[object]) -> Any:
        state = super().init(fn, y, args, options, f_struct, aux_struct, tags)
        return type(state)(jnp.array(jnp.inf, jnp.result_type(y)))


#: The solvers of an implicit step, with what the command line's help says of each.
SOLVER_SUMMARIES = {
    "auto": "fixed-point iteration, Newton where it does not converge; the default",
    "newton": "Newton's method from the start, for stiff models",
    "fixed-point": "fixed-point iteration only",
}
SOLVERS = tuple(SOLVER_SUMMARIES)


class _Implicit(AbstractScheme):
    r"""A step :math:`x_1 = x_0 + \Delta t\,\bar f(x_0, x_1)`, solved by fixed-point iteration
    or Newton's method.

    ``solver``:

    - ``"auto"`` (default): fixed-point iteration :math:`x_1 \leftarrow x_0 + \Delta t\,\bar
      f(x_0, x_1)` from the rollout's predictor, at most ``fixed_point_steps`` iterations;
      **Newton** for the steps where it does not converge (in a batched rollout, one batched
      Newton solve whenever any trajectory needs it). A fixed-point iteration costs one
      evaluation of the vector field; a Newton iteration also builds its :math:`n\times n`
      Jacobian (``n`` forward-mode products through the model) and solves with it, about 4-6x
      more on the reference models. For non-stiff steps (:math:`\Delta t\,\|\partial\bar
      f/\partial x_1\| < 1`) the fixed point converges in a few iterations.
    - ``"newton"``: Newton only (stiff models, e.g. fast heat conduction, where the fixed
      point diverges at every step and the fallback would only add work).
    - ``"fixed-point"``: fixed-point iteration only; a step where it does not converge fails.

    The fixed-point iteration converges linearly, so its error is a multiple of its last update
    (Newton's is far below its last update): it iterates to rounding level, an update below 8
    machine epsilons (a tenth of ``rtol``/``atol`` when they are given). Both solvers then give
    the same accuracy (``benchmarks/bench_solvers.py``, pendulum, 64 x 1000 steps: float32
    error at t = 10 against a tight reference 5.3e-7 (Newton) and 6.1e-7; float64
    discrete-gradient energy drift 1.2e-14 for both) at 2.8-6x less CPU time.

    Subclasses give the scheme's average of the vector field, :meth:`average`, and may compute
    once per step, in :meth:`start`, whatever of it depends on ``x0`` only (it is then not
    re-evaluated at every iteration).
    """

    rtol: float | None = None
    atol: float | None = None
    max_steps: int = 32
    solver: str = "auto"
    fixed_point_steps: int = 16

    def __check_init__(self):
        if self.solver not in SOLVERS:
            raise MetriplexError(
                f"solver must be one of {', '.join(SOLVERS)}; got {self.solver!r}."
            )

    def start(self, model: GenericModel, x0: State) -> Any:
        """The part of the average that depends on ``x0`` alone (default: nothing)."""
        return None

    @abc.abstractmethod
    def average(self, model: GenericModel, x0: State, x1: State, start: Any) -> State:
        """The scheme's average of the vector field over the step, ``(x1 - x0)/dt``."""

    def increment(self, model: GenericModel, x0: State, x1: State) -> State:
        return self.average(model, x0, x1, self.start(model, x0))

    def _newton(self, model, x, dt, guess, pre):
        def fn(y, args):
            x0, dt, pre = args
            return y - x0 - dt * self.average(model, x0, y, pre)

        solver = optx.Newton(
            rtol=_tolerance(self.rtol, x.dtype), atol=_tolerance(self.atol, x.dtype)
        )
        sol = optx.root_find(fn, solver, guess, (x, dt, pre), max_steps=self.max_steps,
                             throw=False)
        return _outcome(sol)

    def _fixed_point(self, model, x, dt, guess, pre):
        def fn(y, args):
            x0, dt, pre = args
            return x0 + dt * self.average(model, x0, y, pre)

        solver = _FixedPointIteration(
            rtol=_fixed_point_tolerance(self.rtol, x.dtype),
            atol=_fixed_point_tolerance(self.atol, x.dtype),
        )
        steps = self.fixed_point_steps if self.solver == "auto" else self.max_steps
        sol = optx.fixed_point(fn, solver, guess, (x, dt, pre), max_steps=steps, throw=False)
        return _outcome(sol)

    def step(self, model: GenericModel, x: State, dt: Scalar | float,
             guess: State) -> tuple[State, jax.Array, jax.Array]:
        y, ok, its = self.step_batch(model, x[None], jnp.asarray(dt)[None], guess[None])
        return y[0], ok[0], its[0]

    def step_batch(self, model: GenericModel, x: States, dt: jax.Array,
                   guess: States) -> tuple[States, jax.Array, jax.Array]:
        # What depends on x0 alone is computed once, for both solvers.
        pre = jax.vmap(lambda x: self.start(model, x))(x)
        newton = jax.vmap(lambda *a: self._newton(model, *a))
        if self.solver == "newton":
            return newton(x, dt, guess, pre)
        first = jax.vmap(lambda *a: self._fixed_point(model, *a))(x, dt, guess, pre)
        if self.solver == "fixed-point":
            return first

        def fallback(first):
            y, ok, its = first
            y2, ok2, its2 = newton(x, dt, guess, pre)
            return jnp.where(ok[:, None], y, y2), ok | ok2, its + jnp.where(ok, 0, its2)

        # An unbatched predicate: Newton runs only at steps where some trajectory needs it.
        return jax.lax.cond(jnp.any(~first[1]), fallback, lambda first: first, first)


def _fixed_point_tolerance(value: float | None, dtype) -> float:
    """A tenth of a tolerance the user gave; by default, 8 machine epsilons (rounding level)."""
    return 0.1 * value if value is not None else 8 * float(jnp.finfo(dtype).eps)


def _outcome(sol):
    y = sol.value
    ok = (sol.result == optx.RESULTS.successful) & jnp.all(jnp.isfinite(y))
    return y, ok, sol.stats["num_steps"]
