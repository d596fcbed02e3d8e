r"""Time stepping: implicit Crank–Nicolson and midpoint (Newton), explicit RK4, batched rollouts.

Each scheme is a small object with two verbs:

- ``step(model, x, dt, guess)`` advances one step and says whether it converged;
- ``residual(model, x0, x1, dt, terms0, terms1)`` is the defect of a data pair under the scheme,
  in units of ``dx/dt`` — zero when ``x1`` is exactly the scheme's step from ``x0``. Training
  minimises it, so the model is learned for the scheme that will roll it out.

Implicit equations are solved with Optimistix's Newton method; a step that does not converge is
reported (``Rollout.failed_step``), never passed on as a silent NaN.
"""

from __future__ import annotations

import abc
from typing import ClassVar
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from ._errors import MetriplexError, RolloutFailure
from ._model import GenericModel, Terms
from ._types import Array, Float, Int, State


def _tolerance(value: float | None, dtype) -> float:
    if value is not None:
        return value
    return 1e-11 if jnp.dtype(dtype) == jnp.float64 else 1e-5


class AbstractScheme(eqx.Module):
    """A one-step time integrator for a :class:`~metriplex.GenericModel`."""

    name: ClassVar[str] = ""

    @abc.abstractmethod
    def step(self, model: GenericModel, x: State, dt, guess: State):
        """Return ``(x_next, converged, iterations)``."""

    @abc.abstractmethod
    def residual(self, model, x0, x1, dt, terms0: Terms, terms1: Terms) -> State: ...


class RK4(AbstractScheme):
    """Classical explicit fourth-order Runge–Kutta (a reference scheme; no structure kept)."""

    name: ClassVar[str] = "rk4"

    def advance(self, model, x, dt):
        f = model.vector_field
        k1 = f(x)
        k2 = f(x + 0.5 * dt * k1)
        k3 = f(x + 0.5 * dt * k2)
        k4 = f(x + dt * k3)
        return x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)

    def step(self, model, x, dt, guess):
        y = self.advance(model, x, dt)
        return y, jnp.all(jnp.isfinite(y)), jnp.array(0)

    def residual(self, model, x0, x1, dt, terms0, terms1):
        return (x1 - self.advance(model, x0, dt)) / dt


class _Implicit(AbstractScheme):
    rtol: float | None = None
    atol: float | None = None
    max_steps: int = 32

    @abc.abstractmethod
    def increment(self, model, x0, x1) -> State:
        """The scheme's average of the vector field over the step, ``(x1 - x0)/dt``."""

    def step(self, model, x, dt, guess):
        def fn(y, args):
            return y - x - dt * self.increment(model, x, y)

        solver = optx.Newton(
            rtol=_tolerance(self.rtol, x.dtype), atol=_tolerance(self.atol, x.dtype)
        )
        sol = optx.root_find(fn, solver, guess, max_steps=self.max_steps, throw=False)
        y = sol.value
        ok = (sol.result == optx.RESULTS.successful) & jnp.all(jnp.isfinite(y))
        return y, ok, sol.stats["num_steps"]


class CrankNicolson(_Implicit):
    r"""Crank–Nicolson (trapezoidal rule): :math:`\frac{x_{n+1}-x_n}{\Delta t} =
    \tfrac12\big(f(x_n) + f(x_{n+1})\big)`. Second order; the seed paper's scheme."""

    name: ClassVar[str] = "cn"

    def increment(self, model, x0, x1):
        return 0.5 * (model.vector_field(x0) + model.vector_field(x1))

    def residual(self, model, x0, x1, dt, terms0, terms1):
        return (x1 - x0) / dt - 0.5 * (terms0.vector_field + terms1.vector_field)


class ImplicitMidpoint(_Implicit):
    r"""Implicit midpoint: :math:`\frac{x_{n+1}-x_n}{\Delta t} = f\big(\tfrac{x_n+x_{n+1}}2\big)`.
    Second order, symplectic; conserves quadratic invariants exactly."""

    name: ClassVar[str] = "midpoint"

    def increment(self, model, x0, x1):
        return model.vector_field(0.5 * (x0 + x1))

    def residual(self, model, x0, x1, dt, terms0, terms1):
        return (x1 - x0) / dt - model.vector_field(0.5 * (x0 + x1))


SCHEMES: dict[str, type[AbstractScheme]] = {
    "cn": CrankNicolson,
    "midpoint": ImplicitMidpoint,
    "rk4": RK4,
}


def scheme_from_name(name: str) -> AbstractScheme:
    if name not in SCHEMES:
        raise MetriplexError(
            f"unknown time-stepping scheme {name!r}; choose one of {sorted(SCHEMES)}."
        )
    return SCHEMES[name]()


class Rollout(NamedTuple):
    """States along a rollout, and where (if anywhere) an implicit step failed.

    ``xs[..., k, :]`` for ``k >= failed_step`` are NaN: they were never computed.
    ``failed_step`` is ``-1`` for a rollout that completed.
    """

    ts: Float[Array, "*batch T"]
    xs: Float[Array, "*batch T n"]
    failed_step: Int[Array, "*batch"]
    iterations: Int[Array, "*batch T"]

    @property
    def ok(self) -> bool:
        return bool(np.all(np.asarray(self.failed_step) < 0))


@eqx.filter_jit
def _rollout_one(model, scheme, x0, ts):
    dts = jnp.diff(ts)

    def body(carry, dt):
        x, prev_dx, prev_dt, failed = carry
        ratio = jnp.where(prev_dt > 0, dt / jnp.where(prev_dt > 0, prev_dt, 1.0), 0.0)
        guess = x + prev_dx * ratio
        y, ok, its = scheme.step(model, x, dt, guess)
        bad = failed | ~ok
        x_new = jnp.where(bad, x, y)
        out = jnp.where(bad, jnp.nan, y)
        return (x_new, jnp.where(bad, prev_dx, y - x), jnp.where(bad, prev_dt, dt), bad), (
            out,
            bad,
            its,
        )

    init = (x0, jnp.zeros_like(x0), jnp.zeros((), x0.dtype), jnp.array(False))
    _, (xs, bad, its) = jax.lax.scan(body, init, dts)
    xs = jnp.concatenate([x0[None], xs])
    bad = jnp.concatenate([jnp.array([False]), bad])
    failed_step = jnp.where(jnp.any(bad), jnp.argmax(bad), -1)
    return xs, failed_step, jnp.concatenate([jnp.array([0]), its])


def _check_inputs(x0, ts, n):
    if x0.ndim not in (1, 2):
        raise MetriplexError(
            f"x0 must have shape (n,) or (batch, n); got shape {x0.shape}."
        )
    if n is not None and x0.shape[-1] != n:
        raise MetriplexError(
            f"x0 has {x0.shape[-1]} state variables but the model expects {n}; pass states with "
            f"{n} components."
        )
    if ts.ndim not in (1, 2) or ts.shape[-1] < 1:
        raise MetriplexError(f"ts must have shape (T,) or (batch, T); got shape {ts.shape}.")
    if not np.all(np.isfinite(np.asarray(x0))) or not np.all(np.isfinite(np.asarray(ts))):
        raise MetriplexError("x0 and ts must be finite; found NaN or inf. Clean the input first.")
    if ts.shape[-1] > 1 and np.any(np.diff(np.asarray(ts), axis=-1) < 0):
        raise MetriplexError(
            "ts must be non-decreasing; got a negative time step. Sort the time grid."
        )


def model_size(model: GenericModel) -> int | None:
    for block in (model.poisson, model.friction, model.energy):
        n = getattr(block, "n", None)
        if isinstance(n, int):
            return n
    return None


def solve(
    model: GenericModel,
    x0: Float[Array, "*batch n"],
    ts: Float[Array, "*batch T"],
    *,
    scheme: AbstractScheme | None = None,
) -> Rollout:
    """Roll out ``model`` from ``x0`` on the time grid ``ts``; never raises on a failed step.

    ``x0`` of shape ``(n,)`` or ``(batch, n)``; ``ts`` of shape ``(T,)`` (shared) or
    ``(batch, T)`` (one grid per trajectory, e.g. non-uniform or padded with repeated times:
    a zero step keeps the state).
    """
    scheme = CrankNicolson() if scheme is None else scheme
    x0 = jnp.asarray(x0)
    ts = jnp.asarray(ts, dtype=x0.dtype)
    _check_inputs(x0, ts, model_size(model))
    if x0.ndim == 1:
        if ts.ndim != 1:
            raise MetriplexError(f"a single x0 needs ts of shape (T,); got {ts.shape}.")
        xs, failed, its = _rollout_one(model, scheme, x0, ts)
        return Rollout(ts, xs, failed, its)
    if ts.ndim == 1:
        ts = jnp.broadcast_to(ts, (x0.shape[0], ts.shape[0]))
    if ts.shape[0] != x0.shape[0]:
        raise MetriplexError(
            f"ts has {ts.shape[0]} grids for {x0.shape[0]} initial states; give one shared grid "
            "of shape (T,) or one per state."
        )
    xs, failed, its = eqx.filter_vmap(_rollout_one, in_axes=(None, None, 0, 0))(
        model, scheme, x0, ts
    )
    return Rollout(ts, xs, failed, its)


def simulate(
    model: GenericModel,
    x0: Float[Array, "*batch n"],
    ts: Float[Array, "*batch T"],
    *,
    scheme: AbstractScheme | None = None,
) -> Float[Array, "*batch T n"]:
    """Simulate ``model`` from ``x0`` on ``ts``; shape ``(T, n)`` or ``(batch, T, n)``.

    Implicit Crank–Nicolson by default. If a step does not converge this raises
    :class:`~metriplex.RolloutFailure` naming the trajectory and time, with the states computed
    up to there in ``.partial``; use :func:`solve` to get the marked result without raising.

    ```python
    xs = mx.simulate(model, x0, jnp.linspace(0.0, 10.0, 101))
    ```
    """
    out = solve(model, x0, ts, scheme=scheme)
    failed = np.atleast_1d(np.asarray(out.failed_step))
    if np.any(failed >= 0):
        b = int(np.argmax(failed >= 0))
        k = int(failed[b])
        ts_b = np.asarray(out.ts).reshape(-1, np.asarray(out.ts).shape[-1])[b]
        xs_b = np.asarray(out.xs).reshape(-1, *np.asarray(out.xs).shape[-2:])[b]
        raise RolloutFailure(
            f"the implicit step from t={ts_b[k - 1]:.6g} to t={ts_b[k]:.6g} of trajectory {b} "
            f"did not converge (step {k}); {k} states were computed. Try a smaller time step, "
            "`scheme=RK4()` to inspect, or check the model for blow-up.",
            partial=xs_b[:k],
            trajectory=b,
            time=float(ts_b[k]),
        )
    return out.xs
