r"""How an implicit step is solved: the root finders an implicit scheme takes as
``root_finder=`` (:class:`FixedPointThenNewton`, the default; :class:`Newton`;
:class:`FixedPoint`), and their registry by the command line's ``--solver`` names.

A root finder solves :math:`x_1 = x_0 + \Delta t\,\bar f(x_0, x_1)` for a batch of steps; the
scheme gives it the update :math:`\Delta t\,\bar f` as a function. Adding a root finder is
one final subclass of :class:`AbstractRootFinder` here plus one line in :data:`ROOT_FINDERS`
(its ``--solver`` name and the one-line summary that ``--help`` prints).
"""

from __future__ import annotations

import abc
from typing import Any, Callable, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import optimistix as optx

from .._errors import MetriplexError
from .._types import State, States

#: ``update(x0, x1, args)``: the step's :math:`\Delta t\,\bar f(x_0, x_1)` for one state.
Update = Callable[[State, State, Any], State]


class AbstractRootFinder(eqx.Module):
    r"""A solver of the implicit step :math:`x_1 = x_0 + \text{update}(x_0, x_1)` of a batch.

    Concrete root finders are final; each carries its own tolerances and iteration limits.
    """

    @abc.abstractmethod
    def solve_batch(self, update: Update, x0: States, guess: States,
                    args: Any) -> tuple[States, jax.Array, jax.Array]:
        """Solve ``x1 = x0 + update(x0, x1, args)`` for each row of ``x0`` ``(B, n)``,
        starting from ``guess`` ``(B, n)``; every leaf of ``args`` is batched along its first
        axis. Return ``(x1, converged, iterations)``, the last two of shape ``(B,)``."""


# -- the two methods, each for a batch of steps; the root finders below run them ----------------


class _FixedPointIteration(optx.AbstractFixedPointSolver):
    """Optimistix's :class:`optimistix.FixedPointIteration` (``inner``), wrapped so that its
    error estimate starts in the state's dtype.

    Upstream starts the estimate as ``jnp.array(inf)``, which is float64 when x64 is enabled;
    a float32 state then changes the loop carry's dtype and the solve fails to trace. The
    upstream class is final, so this wraps it instead of subclassing it.
    """

    inner: optx.FixedPointIteration

    def __init__(self, rtol: float, atol: float) -> None:
        self.inner = optx.FixedPointIteration(rtol=rtol, atol=atol)

    @property
    def rtol(self) -> float:
        return self.inner.rtol

    @property
    def atol(self) -> float:
        return self.inner.atol

    @property
    def norm(self) -> Callable[[Any], Any]:
        return self.inner.norm

    def init(self, fn: Callable[..., Any], y: State, args: Any, options: dict[str, Any],
             f_struct: Any, aux_struct: Any, tags: frozenset[object]) -> Any:
        state = self.inner.init(fn, y, args, options, f_struct, aux_struct, tags)
        return type(state)(jnp.array(jnp.inf, jnp.result_type(y)))

    def step(self, fn: Callable[..., Any], y: State, args: Any, options: dict[str, Any],
             state: Any, tags: frozenset[object]) -> tuple[State, Any, Any]:
        return self.inner.step(fn, y, args, options, state, tags)

    def terminate(self, fn: Callable[..., Any], y: State, args: Any, options: dict[str, Any],
                  state: Any, tags: frozenset[object]) -> tuple[jax.Array, Any]:
        return self.inner.terminate(fn, y, args, options, state, tags)

    def postprocess(self, fn: Callable[..., Any], y: State, aux: Any, args: Any,
                    options: dict[str, Any], state: Any, tags: frozenset[object],
                    result: Any) -> tuple[State, Any, dict[str, Any]]:
        return self.inner.postprocess(fn, y, aux, args, options, state, tags, result)


def _newton(update, x0, guess, args, rtol, atol, max_steps):
    """Newton's method on ``x1 - x0 - update(x0, x1, args)``, for each row of the batch."""

    def one(x, guess, a):
        def fn(y, args):
            x0, a = args
            return y - x0 - update(x0, y, a)

        _check_attainable(rtol, atol, x.dtype)
        solver = optx.Newton(rtol=_tolerance(rtol, x.dtype), atol=_tolerance(atol, x.dtype))
        sol = optx.root_find(fn, solver, guess, (x, a), max_steps=max_steps, throw=False)
        return _outcome(sol)

    return jax.vmap(one)(x0, guess, args)


def _fixed_point(update, x0, guess, args, rtol, atol, max_steps):
    """Fixed-point iteration of ``x1 <- x0 + update(x0, x1, args)``, for each row."""

    def one(x, guess, a):
        def fn(y, args):
            x0, a = args
            return x0 + update(x0, y, a)

        _check_attainable(rtol, atol, x.dtype)
        solver = _FixedPointIteration(
            rtol=_fixed_point_tolerance(rtol, x.dtype),
            atol=_fixed_point_tolerance(atol, x.dtype),
        )
        sol = optx.fixed_point(fn, solver, guess, (x, a), max_steps=max_steps, throw=False)
        return _outcome(sol)

    return jax.vmap(one)(x0, guess, args)


def _tolerance(value: float | None, dtype) -> float:
    r"""A tolerance the user gave; by default 1e-11 in float64, 1e-4 otherwise.

    Newton stops on the size of its last update and converges quadratically, so the state it
    returns is far more accurate than the tolerance. In float32 the discrete-gradient step's
    difference quotient :math:`(E_1 - E_0)/|\Delta|` carries rounding of about
    :math:`\epsilon|E|/|\Delta|`: for small steps the updates stall between 1e-5 and 1e-4 and
    a tolerance of 1e-5 called converged steps failed (2 of 4 test rollouts of the quick
    pendulum-energetic experiment; none with 1e-4, and none in float64)."""
    if value is not None:
        return value
    return 1e-11 if jnp.dtype(dtype) == jnp.float64 else 1e-4


def _check_attainable(rtol: float | None, atol: float | None, dtype) -> None:
    """Refuse tolerances that the states' dtype cannot meet (both given below 2 machine
    epsilons, the rounding of a state's update): every step would fail as if it were too large
    (``Newton(rtol=1e-13, atol=1e-13)`` on float32 states)."""
    floor = 2 * float(jnp.finfo(dtype).eps)
    if rtol is not None and atol is not None and max(rtol, atol) < floor:
        raise MetriplexError(
            f"the root finder's rtol={rtol:g} and atol={atol:g} are below what "
            f"{jnp.dtype(dtype).name} states resolve (2 machine epsilons, {floor:.1e}), so no "
            f"step could converge; give a larger tolerance (the default is "
            f"{_tolerance(None, dtype):g}), or states and a model in float64.")


def _fixed_point_tolerance(value: float | None, dtype) -> float:
    """A tenth of a tolerance the user gave; by default, 8 machine epsilons (rounding level)."""
    return 0.1 * value if value is not None else 8 * float(jnp.finfo(dtype).eps)


def _outcome(sol):
    y = sol.value
    ok = (sol.result == optx.RESULTS.successful) & jnp.all(jnp.isfinite(y))
    return y, ok, sol.stats["num_steps"]


# -- the root finders ---------------------------------------------------------------------------


class FixedPointThenNewton(AbstractRootFinder):
    r"""Fixed-point iteration :math:`x_1 \leftarrow x_0 + \Delta t\,\bar f(x_0, x_1)` from the
    rollout's predictor, at most ``fixed_point_steps`` iterations; **Newton** (at most
    ``max_steps`` iterations) for the steps where it does not converge. In a batch, the Newton
    fallback is one batched solve, run only at steps where some trajectory needs it. The
    default of every implicit scheme (``--solver auto``).

    A fixed-point iteration costs one evaluation of the vector field; a Newton iteration also
    builds its :math:`n\times n` Jacobian (``n`` forward-mode products through the model) and
    solves with it, about 4-6x more on the reference models. For non-stiff steps
    (:math:`\Delta t\,\|\partial\bar f/\partial x_1\| < 1`) the fixed point converges in a few
    iterations. The fixed-point iteration converges linearly, so its error is a multiple of its
    last update (Newton's is far below its last update): it iterates to rounding level, an
    update below 8 machine epsilons (a tenth of ``rtol``/``atol`` when they are given). Both
    then give the same accuracy (``benchmarks/bench_solvers.py``, pendulum, 64 x 1000 steps:
    float32 error at t = 10 against a tight reference 5.3e-7 (Newton) and 6.1e-7; float64
    discrete-gradient energy drift 1.2e-14 for both) at 2.8-6x less CPU time.

    ``rtol``, ``atol``: Newton's tolerances (default 1e-11 in float64, 1e-4 in float32); the
    fixed point stops at a tenth of them.
    """

    rtol: float | None = None
    atol: float | None = None
    fixed_point_steps: int = 16
    max_steps: int = 32

    def solve_batch(self, update: Update, x0: States, guess: States,
                    args: Any) -> tuple[States, jax.Array, jax.Array]:
        first = _fixed_point(update, x0, guess, args, self.rtol, self.atol,
                             self.fixed_point_steps)

        def fallback(first):
            y, ok, its = first
            y2, ok2, its2 = _newton(update, x0, guess, args, self.rtol, self.atol,
                                    self.max_steps)
            return jnp.where(ok[:, None], y, y2), ok | ok2, its + jnp.where(ok, 0, its2)

        # An unbatched predicate: Newton runs only at steps where some trajectory needs it.
        return jax.lax.cond(jnp.any(~first[1]), fallback, lambda first: first, first)


class _AbstractOneMethod(AbstractRootFinder):
    """A root finder that runs one method (``_method``, :func:`_newton` or
    :func:`_fixed_point`) at every step, at most ``max_steps`` iterations, with the tolerances
    ``rtol`` and ``atol``: what :class:`Newton` and :class:`FixedPoint` share."""

    rtol: float | None = None
    atol: float | None = None
    max_steps: int = 32
    #: ``_method(update, x0, guess, args, rtol, atol, max_steps)`` for a batch.
    _method: ClassVar[Callable[..., tuple[States, jax.Array, jax.Array]]]

    def solve_batch(self, update: Update, x0: States, guess: States,
                    args: Any) -> tuple[States, jax.Array, jax.Array]:
        return self._method(update, x0, guess, args, self.rtol, self.atol, self.max_steps)


class Newton(_AbstractOneMethod):
    """Newton's method (Optimistix ``Newton``) at every step, at most ``max_steps``
    iterations: for stiff models (e.g. fast heat conduction, where the fixed point diverges at
    every step and :class:`FixedPointThenNewton` would only add its wasted iterations).
    ``--solver newton``.

    ``rtol``, ``atol``: default 1e-11 in float64, 1e-4 in float32.
    """

    _method = staticmethod(_newton)


class FixedPoint(_AbstractOneMethod):
    """Fixed-point iteration only, at most ``max_steps`` iterations; a step where it does not
    converge fails. ``--solver fixed-point``.

    ``rtol``, ``atol``: it stops at a tenth of them; by default, at an update below 8 machine
    epsilons (rounding level).
    """

    _method = staticmethod(_fixed_point)


#: The root finders by the command line's ``--solver`` names, each with the one line that
#: ``--solver``'s help says of it; :func:`metriplex.app.config.scheme_from_name` reads it.
ROOT_FINDERS: dict[str, tuple[type[AbstractRootFinder], str]] = {
    "auto": (FixedPointThenNewton,
             "fixed-point iteration, Newton where it does not converge; the default"),
    "newton": (Newton, "Newton's method from the start, for stiff models"),
    "fixed-point": (FixedPoint, "fixed-point iteration only"),
}


def _solver_name(root_finder: AbstractRootFinder) -> str:
    """The ``--solver`` name of ``root_finder`` in :data:`ROOT_FINDERS`; the class name of
    one that is not registered."""
    for name, (cls, _) in ROOT_FINDERS.items():
        if type(root_finder) is cls:
            return name
    return type(root_finder).__name__
