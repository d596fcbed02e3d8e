"""Batched rollouts of a model with a scheme: :func:`solve` (a result code per trajectory)
and :func:`simulate` (raises on failure)."""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._precision import in_full_precision
from .._errors import MetriplexError, RolloutFailure, expect_integer
from .._model import AbstractModel, float_dtype
from .._types import Array, Float, Int
from ._scheme import AbstractScheme
from ._implicit import AbstractImplicitScheme
from .root_finder import Newton, _solver_name
from .crank_nicolson import CrankNicolson


#: The substeps in which evaluations and ``metriplex rollout`` retake a step whose solve failed
#: (``solve(retry=...)``), and, where one of those fails too, the square of it.
RETRY_SUBSTEPS = 8

#: How many times a failed step is retaken, each time from its start in ``retry`` times more
#: substeps than the last attempt: ``retry``, then ``retry ** 2``.
RETRY_LEVELS = 2

#: The largest ``retry``: its ``retry ** RETRY_LEVELS`` substeps (a million) are counted in
#: int32 where 64-bit types are off.
MAX_RETRY = 1000


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
        """Whether every trajectory was rolled out to its last time."""
        return bool(np.all(np.asarray(self.failed_step) < 0))


def _predict(x, d1, h1, d2, h2, h):
    r"""Newton's starting guess: the quadratic through the last three states, at ``t + h``.

    ``d1 = x_n - x_{n-1}`` over ``h1``, ``d2 = x_{n-1} - x_{n-2}`` over ``h2`` (zero length:
    not known yet, which lowers the degree). The predictor error is :math:`O(h^3)`, below
    the Newton tolerance for moderate steps, so most steps need one or two iterations.
    """
    known1 = h1 > 0
    known2 = known1 & (h2 > 0)
    s1 = jnp.where(known1, d1 / jnp.where(known1, h1, 1.0), 0.0)
    s2 = jnp.where(known2, d2 / jnp.where(known2, h2, 1.0), 0.0)
    curv = jnp.where(known2, (s1 - s2) / jnp.where(known2, h1 + h2, 1.0), 0.0)
    return x + h * s1 + (h * (h + h1)) * curv


def _rollout(model, scheme, x0, ts, retry):
    """Roll out a batch: ``x0`` ``(B, n)``, ``ts`` ``(B, T)``; the scan runs over time and each
    step advances the whole batch at once (so the scheme can decide per step, for the batch,
    whether Newton is needed). ``retry`` (an integer array, traced: one program serves every
    value): a step whose solve fails is taken again as that many equal substeps before the
    trajectory is marked failed (0: never)."""
    dts = jnp.diff(ts, axis=-1).T  # (T - 1, B)
    zero = jnp.zeros(x0.shape[:1], x0.dtype)

    def body(carry, dt):
        x, d1, h1, d2, h2, failed = carry
        # A failed trajectory takes zero steps from here on: its solves end at once.
        h = jnp.where(failed, 0.0, dt)
        guess = jax.vmap(_predict)(x, d1, h1, d2, h2, h)
        y, ok, its = _step_or_retry(model, scheme, x, h, guess, retry)
        moved = h > 0
        bad = failed | (moved & ~ok)
        y = jnp.where(moved[:, None], y, x)  # a zero step keeps the state exactly
        x_new = jnp.where(bad[:, None], x, y)
        advance = moved & ~bad
        a = advance[:, None]
        carry = (
            x_new,
            jnp.where(a, y - x, d1),
            jnp.where(advance, h, h1),
            jnp.where(a, d1, d2),
            jnp.where(advance, h1, h2),
            bad,
        )
        its = jnp.where(failed, 0, jnp.asarray(its, jnp.asarray(0).dtype))
        return carry, (jnp.where(bad[:, None], jnp.nan, y), bad, its)

    no = jnp.zeros(x0.shape[:1], bool)
    init = (x0, jnp.zeros_like(x0), zero, jnp.zeros_like(x0), zero, no)
    _, (xs, bad, its) = jax.lax.scan(body, init, dts)
    xs = jnp.concatenate([x0[:, None], jnp.swapaxes(xs, 0, 1)], axis=1)
    bad = jnp.concatenate([no[:, None], bad.T], axis=1)
    failed_step = jnp.where(jnp.any(bad, axis=1), jnp.argmax(bad, axis=1), -1)
    its = jnp.concatenate([jnp.zeros_like(its[:1]).T, its.T], axis=1)
    return xs, failed_step, its


def _step_or_retry(model, scheme, x, h, guess, retry):
    """One step of the batch; a row whose solve fails is taken again from ``x`` as ``retry``
    equal substeps (those of :class:`~metriplex.systems.Substeps`: the first from ``x``, each
    next one from the last state plus the last increment); where one of them fails, again from
    ``x`` as ``retry ** 2`` substeps (:data:`RETRY_LEVELS`), and fails if one of those fails.

    The scheme's step appears once in the program, in a loop whose rounds are the first
    attempt and then the substeps (each row at its own stage; a row that is done takes zero
    steps), so the retry adds no second copy of the solver to compile, and ``retry`` is
    traced: rollouts of one shape with and without it are one program. A step that converges
    at once takes one round; a zero step takes none (its iterations: 0), and a failed retry
    stops counting at its failed substep.
    """
    dtype = jnp.asarray(0).dtype

    def round_(state):
        y, dy, left, step, ok, its, level = state
        active = left > 0
        z, ok1, its1 = scheme.step_batch(model, y, jnp.where(active, step, 0.0),
                                         jnp.where(active[:, None], y + dy, y))
        done = active & ok1
        # A failed attempt starts the step again from x, in retry times more substeps.
        again = active & ~ok1 & (level < RETRY_LEVELS) & (retry > 0)
        failed = active & ~ok1 & ~again
        substeps = jnp.maximum(retry, 1) ** (level + 1)
        a = done[:, None]
        return (jnp.where(again[:, None], x, jnp.where(a, z, y)),
                jnp.where(again[:, None], 0.0, jnp.where(a, z - y, dy)),
                jnp.where(again, substeps,
                          jnp.where(done, left - 1, jnp.where(failed, 0, left))),
                jnp.where(again, h / substeps.astype(h.dtype), step),
                ok & ~failed,
                its + jnp.where(active, jnp.asarray(its1, dtype), 0),
                level + again.astype(dtype))

    # one round for each row that moves; the first round's guess is the predictor (y + dy)
    init = (x, guess - x, (h > 0).astype(dtype), h, jnp.ones(x.shape[:1], bool),
            jnp.zeros(x.shape[:1], dtype), jnp.zeros(x.shape[:1], dtype))
    y, _, _, _, ok, its, _ = jax.lax.while_loop(lambda s: jnp.any(s[2] > 0), round_, init)
    return y, ok, its


@eqx.filter_jit
def _rollout_one(model, scheme, x0, ts, retry):
    xs, failed, its = _rollout(model, scheme, x0[None], ts[None], retry)
    return xs[0], failed[0], its[0]


_rollout_batch = eqx.filter_jit(_rollout)


def step_failure(scheme: AbstractScheme, t0: float, t1: float, where: str = "", *,
                 python: bool = False) -> str:
    """What went wrong in a failed step from ``t0`` to ``t1`` (``where``, e.g. " of trajectory
    3", follows the times), and what to try, in the words of ``scheme``: an implicit step's
    solve did not converge; an explicit step (RK4) has nothing to converge, its new state was
    not finite. ``python``: name the fixes as Python arguments, not command-line options."""
    name = scheme.name
    span = f"from t={t0:.6g} to t={t1:.6g}{where}"
    if isinstance(scheme, AbstractImplicitScheme):
        solver = _solver_name(scheme.root_finder)
        newton = ("" if isinstance(scheme.root_finder, Newton)
                  else "the Newton solver ("
                  + (f"scheme={type(scheme).__name__}(root_finder=Newton())" if python
                     else "--solver newton") + "), ")
        rk4 = "scheme=RK4()" if python else "--scheme rk4"
        return (
            f"the implicit {name} step {span} did not converge (solver {solver!r}). Try "
            f"{newton}a smaller time step, or RK4 ({rk4}) to see whether the model "
            "itself blows up"
        )
    return (
        f"the explicit {name} step {span} gave a non-finite state: the model's vector field "
        "overflowed or is NaN there (the model blows up along this trajectory). A smaller time "
        "step helps only if the step itself was unstable; otherwise the model needs more or "
        "wider training data"
    )


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


def model_size(model: AbstractModel) -> int | None:
    """The number of state variables of ``model`` (:meth:`AbstractModel.size`; ``None`` where
    the model cannot tell, e.g. a model of known functions only)."""
    return model.size()


@in_full_precision
def solve(
    model: AbstractModel,
    x0: Float[Array, "*batch n"],
    ts: Float[Array, "*batch T"],
    *,
    scheme: AbstractScheme | None = None,
    throw: bool = False,
    retry: int = 0,
) -> Rollout:
    """Roll out ``model`` from ``x0`` on the time grid ``ts``.

    ``x0`` of shape ``(n,)`` or ``(batch, n)``; ``ts`` of shape ``(T,)`` (shared) or
    ``(batch, T)`` (one grid per trajectory, e.g. non-uniform or padded with repeated times:
    a zero step keeps the state).

    A step that does not converge is marked, not raised: the :class:`Rollout` holds a result
    code per trajectory (``failed_step``, -1 where it completed) and NaN from that step on.
    With ``throw=True`` (as in Diffrax) the first failure raises
    :class:`~metriplex.RolloutFailure` instead, naming the trajectory and the time, with the
    states computed up to there in ``.partial``.

    ``retry``: a step whose solve does not converge (or whose state is not finite) is taken
    again as ``retry`` equal substeps, from the same state, and where one of those fails as
    ``retry ** 2``, before the trajectory is marked failed (0, the default: never; at most
    :data:`MAX_RETRY`). A model that blows up fails either way; one whose field is merely
    stiff somewhere goes on. ``metriplex.evaluate`` and ``metriplex rollout`` use
    :data:`RETRY_SUBSTEPS`.
    """
    retry = expect_integer(retry, what="retry", least=0, below=MAX_RETRY + 1)
    if not isinstance(model, AbstractModel):
        raise MetriplexError(
            f"solve and simulate take a model (metriplex.load(RUN) gives one); got "
            f"{type(model).__name__} {model!r:.60}."
        )
    if scheme is not None and not isinstance(scheme, AbstractScheme):
        raise MetriplexError(
            f"scheme must be a scheme object such as metriplex.CrankNicolson() or "
            f"metriplex.RK4(); got {scheme!r}."
        )
    out = _solve(model, x0, ts, scheme, jnp.asarray(retry, jnp.asarray(0).dtype))
    if throw:
        _raise_first_failure(out, scheme)
    return out


def _solve(model, x0, ts, scheme, retry) -> Rollout:
    scheme = CrankNicolson() if scheme is None else scheme
    x0 = jnp.asarray(x0)
    x0 = x0.astype(_state_dtype(model, x0))
    grid = _from_start(ts, x0.dtype)
    ts = jnp.asarray(ts, dtype=x0.dtype)
    _check_inputs(x0, ts, model_size(model))
    if x0.ndim == 1:
        if ts.ndim != 1:
            raise MetriplexError(f"a single x0 needs ts of shape (T,); got {ts.shape}.")
        xs, failed, its = _rollout_one(model, scheme, x0, grid, retry)
        return Rollout(ts, xs, failed, its)
    if ts.ndim == 1:
        ts = jnp.broadcast_to(ts, (x0.shape[0], ts.shape[0]))
        grid = jnp.broadcast_to(grid, ts.shape)
    if ts.shape[0] != x0.shape[0]:
        raise MetriplexError(
            f"ts has {ts.shape[0]} grids for {x0.shape[0]} initial states; give one shared grid "
            "of shape (T,) or one per state."
        )
    xs, failed, its = _rollout_batch(model, scheme, x0, grid, retry)
    return Rollout(ts, xs, failed, its)


def _state_dtype(model, x0) -> np.dtype:
    """The dtype a rollout runs in: ``x0``'s, raised to the model's weights' where those are
    wider (float32 states of a float64 model), and the weights' (else JAX's default float)
    for integer states."""
    floating = jnp.issubdtype(x0.dtype, jnp.floating)
    own = float_dtype(model, default=x0.dtype if floating else None)
    if floating and jnp.finfo(own).bits <= jnp.finfo(x0.dtype).bits:
        return x0.dtype
    return own


def _from_start(ts, dtype) -> jax.Array:
    """``ts`` measured from each grid's first time, in ``dtype``: a rollout needs only the
    steps, and times far from 0 (a clock's, t = 1.7e9 s) lose them when cast to float32 (at
    t = 1e6 to multiples of 1/16), so the shift is taken in float64 first where ``ts`` is
    concrete."""
    try:
        a = np.asarray(ts, dtype=np.float64)
    except jax.errors.TracerArrayConversionError:  # under a transformation: as given
        a = jnp.asarray(ts, dtype=dtype)
        return a - a[..., :1] if a.ndim and a.shape[-1] else a
    if a.ndim and a.shape[-1] and np.all(np.isfinite(a[..., :1])):
        a = a - a[..., :1]
    return jnp.asarray(a, dtype=dtype)


@in_full_precision
def simulate(
    model: AbstractModel,
    x0: Float[Array, "*batch n"],
    ts: Float[Array, "*batch T"],
    *,
    scheme: AbstractScheme | None = None,
    retry: int = RETRY_SUBSTEPS,
) -> Float[Array, "*batch T n"]:
    """Simulate ``model`` from ``x0`` on ``ts``; shape ``(T, n)`` or ``(batch, T, n)``.

    Implicit Crank–Nicolson by default. The states of ``solve(..., throw=True, retry=retry)``:
    a step whose solve fails is retaken in ``retry`` substeps (and, where one of those fails,
    in their square), as ``metriplex rollout`` and ``evaluate`` do (0: never); if it still
    does not converge this raises :class:`~metriplex.RolloutFailure` naming the trajectory and
    time, with the states computed up to there in ``.partial``; use :func:`solve` to get the
    marked result without raising.

    ```python
    xs = mx.simulate(model, x0, jnp.linspace(0.0, 10.0, 101))
    ```
    """
    return solve(model, x0, ts, scheme=scheme, throw=True, retry=retry).xs


def _raise_first_failure(out: Rollout, scheme: AbstractScheme | None) -> None:
    """Raise :class:`~metriplex.RolloutFailure` for the first trajectory of ``out`` whose
    rollout failed (nothing if all completed)."""
    failed = np.atleast_1d(np.asarray(out.failed_step))
    if np.any(failed >= 0):
        b = int(np.argmax(failed >= 0))
        k = int(failed[b])
        ts_b = np.asarray(out.ts).reshape(-1, np.asarray(out.ts).shape[-1])[b]
        xs_b = np.asarray(out.xs).reshape(-1, *np.asarray(out.xs).shape[-2:])[b]
        what = step_failure(CrankNicolson() if scheme is None else scheme,
                            float(ts_b[k - 1]), float(ts_b[k]), f" of trajectory {b}",
                            python=True)
        raise RolloutFailure(
            f"step {k}: {what}. The {k} states computed before it are in .partial.",
            partial=xs_b[:k],
            trajectory=b,
            time=float(ts_b[k]),
        )
