r"""Time stepping: implicit Crank–Nicolson, midpoint and discrete-gradient steps (fixed-point
iteration with a Newton fallback), explicit RK4, batched rollouts.

Each scheme is a small object with two verbs:

- ``step(model, x, dt, guess)`` advances one step and says whether it converged;
- ``residual(model, x0, x1, dt, terms0, terms1)`` is the defect of a data pair under the scheme,
  in units of ``dx/dt`` — zero when ``x1`` is exactly the scheme's step from ``x0``. Training
  minimises it, so the model is learned for the scheme that will roll it out.

Implicit equations are solved with Optimistix (fixed-point iteration, and Newton's method where
that does not converge; see ``solver``); a step that does not converge is reported
(``Rollout.failed_step``), never passed on as a silent NaN.

Which scheme keeps what (for any model, to solver tolerance):

============================  ==================  ===================  =========
scheme                        :math:`E` conserved  :math:`\Delta S\ge0`  order
============================  ==================  ===================  =========
:class:`DiscreteGradient`     yes (any :math:`E`)  yes (any :math:`S`)   2
:class:`ImplicitMidpoint`     quadratic :math:`E`  linear :math:`S`      2
:class:`CrankNicolson`        no                   linear :math:`S`      2
:class:`RK4`                  no                   no                    4
============================  ==================  ===================  =========
"""

from __future__ import annotations

import abc
from typing import Any, ClassVar, NamedTuple

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

    def step_batch(self, model: GenericModel, x, dt, guess):
        """:meth:`step` for a batch of states ``x`` ``(B, n)``, steps ``dt`` ``(B,)``."""
        return jax.vmap(lambda x, dt, g: self.step(model, x, dt, g))(x, dt, guess)

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


class _FixedPointIteration(optx.FixedPointIteration):
    """Optimistix's fixed-point iteration, with its error estimate in the state's dtype.

    Upstream starts the estimate as ``jnp.array(inf)``, which is float64 when x64 is enabled;
    a float32 state then changes the loop carry's dtype and the solve fails to trace.
    """

    def init(self, fn, y, args, options, f_struct, aux_struct, tags):
        state = super().init(fn, y, args, options, f_struct, aux_struct, tags)
        return type(state)(jnp.array(jnp.inf, jnp.result_type(y)))


SOLVERS = ("auto", "newton", "fixed-point")


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

    def start(self, model, x0) -> Any:
        """The part of the average that depends on ``x0`` alone (default: nothing)."""
        return None

    @abc.abstractmethod
    def average(self, model, x0, x1, start) -> State:
        """The scheme's average of the vector field over the step, ``(x1 - x0)/dt``."""

    def increment(self, model, x0, x1) -> State:
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

    def step(self, model, x, dt, guess):
        y, ok, its = self.step_batch(model, x[None], jnp.asarray(dt)[None], guess[None])
        return y[0], ok[0], its[0]

    def step_batch(self, model, x, dt, guess):
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


class CrankNicolson(_Implicit):
    r"""Crank–Nicolson (trapezoidal rule): :math:`\frac{x_{n+1}-x_n}{\Delta t} =
    \tfrac12\big(f(x_n) + f(x_{n+1})\big)`. Second order; the seed paper's scheme."""

    name: ClassVar[str] = "cn"

    def start(self, model, x0):
        return model.vector_field(x0)

    def average(self, model, x0, x1, start):
        return 0.5 * (start + model.vector_field(x1))

    def residual(self, model, x0, x1, dt, terms0, terms1):
        return (x1 - x0) / dt - 0.5 * (terms0.vector_field + terms1.vector_field)


class ImplicitMidpoint(_Implicit):
    r"""Implicit midpoint: :math:`\frac{x_{n+1}-x_n}{\Delta t} = f\big(\tfrac{x_n+x_{n+1}}2\big)`.
    Second order, symplectic; conserves quadratic invariants exactly."""

    name: ClassVar[str] = "midpoint"

    def average(self, model, x0, x1, start):
        return model.vector_field(0.5 * (x0 + x1))

    def residual(self, model, x0, x1, dt, terms0, terms1):
        return (x1 - x0) / dt - model.vector_field(0.5 * (x0 + x1))


# --------------------------------------------------------------------------------------------
# Discrete gradients


def _sum(a):
    return jnp.sum(a, axis=-1)


def discrete_gradient(grad_mid, value0, value1, x0, x1):
    r"""Gonzalez's midpoint discrete gradient of a scalar :math:`F` between ``x0`` and ``x1``.

    .. math::
        \bar\nabla F = \nabla F(\bar x)
        + \frac{F(x_1) - F(x_0) - \nabla F(\bar x)\cdot\Delta}{|\Delta|^2 + \delta^2}\,\Delta,
        \qquad \Delta = x_1 - x_0,\ \bar x = \tfrac12(x_0 + x_1),

    with ``grad_mid`` :math:`=\nabla F(\bar x)`. With :math:`\delta = 0` this is exactly
    Gonzalez's (1996) discrete gradient, :math:`\bar\nabla F\cdot\Delta = F(x_1) - F(x_0)`.

    **The limit** :math:`\Delta\to0`. The numerator is :math:`O(|\Delta|^3)` in exact arithmetic
    but carries the rounding error of :math:`F(x_1) - F(x_0)`, about
    :math:`\varepsilon|F|`; divided by :math:`|\Delta|^2` alone it would blow up (0/0 at
    :math:`\Delta = 0`, noise :math:`\varepsilon|F|/|\Delta|` for tiny steps). The smooth,
    never-zero denominator uses :math:`\delta^2 = \varepsilon\,\tfrac12(|x_0|^2+|x_1|^2) +
    \sqrt{\text{tiny}}` (machine epsilon and smallest normal number of the dtype):

    - it is smooth in :math:`(x_0, x_1)` (Newton and training see an honest Jacobian) and
      equals :math:`\nabla F(x_0)` at :math:`\Delta = 0`, with no ``NaN`` in value or
      derivatives (:math:`\delta^4` never underflows);
    - rounding noise enters with a Lipschitz constant of at most about
      :math:`|F|/|x|^2`, the size of a genuine Hessian, so a near-stationary state is not
      kicked by noise;
    - the identity :math:`\bar\nabla F\cdot\Delta = F(x_1)-F(x_0)` is violated by
      :math:`\frac{\delta^2}{|\Delta|^2+\delta^2}\cdot\text{numerator} \le
      \tfrac1{24}|D^3F|\,|\Delta|\,\delta^2`, i.e. :math:`\varepsilon\,|\Delta|/|x|` relative to
      the third-order scale of :math:`F`: below the rounding error of :math:`F` itself.
    """
    d = x1 - x0
    eps = jnp.finfo(d.dtype).eps
    floor = np.sqrt(np.finfo(jnp.dtype(d.dtype)).tiny)
    delta2 = eps * 0.5 * (_sum(x0 * x0) + _sum(x1 * x1)) + floor
    defect = (value1 - value0) - _sum(grad_mid * d)
    return grad_mid + (defect / (_sum(d * d) + delta2)) * d


def project_out(g, v):
    r""":math:`v - g\,\frac{g\cdot v}{|g|^2 + \tau}`: ``v`` with its component along ``g``
    removed (the projector :math:`I - gg^\top/|g|^2`, symmetric and idempotent).

    :math:`\tau = \sqrt{\text{tiny}}` only guards :math:`g = 0`, where the projector becomes the
    identity instead of ``NaN``; for any :math:`|g|^2 \gg \tau` (about 1e-154 in float64,
    1e-19 in float32) it is the exact projector to rounding.
    """
    tau = np.sqrt(np.finfo(jnp.dtype(v.dtype)).tiny)
    return v - g * (_sum(g * v) / (_sum(g * g) + tau))


def discrete_generic_field(model: GenericModel, x0, x1, energy0, energy1, entropy0, entropy1,
                           mid: Terms | None = None):
    r"""The discrete-gradient GENERIC average :math:`\bar L\bar\nabla E + \bar M\bar\nabla S`.

    With :math:`\bar\nabla E,\ \bar\nabla S` the discrete gradients of
    :func:`discrete_gradient` and :math:`P = I - \hat s\hat s^\top`, :math:`Q = I - \hat e\hat
    e^\top` the projectors orthogonal to them (:func:`project_out`),

    .. math:: \bar L = P\,L(\bar x)\,P, \qquad \bar M = Q\,M(\bar x)\,Q .

    :math:`\bar L` is antisymmetric with :math:`\bar L\bar\nabla S = 0`; :math:`\bar M` is
    symmetric positive semi-definite (when :math:`M` is) with :math:`\bar M\bar\nabla E = 0`:
    the GENERIC degeneracy holds discretely, whatever the model. The blocks are called as
    ``poisson(x̄, ∇̄S)`` and ``friction(x̄, ∇̄E)``, so exactly degenerate parametrisations see
    the discrete gradients.

    ``mid``: the model's :class:`~metriplex.Terms` at the midpoint, if already computed (the
    training loss shares them); their gradients are used, and their ``L`` and ``M`` for blocks
    that do not depend on the gradient argument (``uses_gradient``).
    """
    xm = 0.5 * (x0 + x1)
    gE_mid = jax.grad(model.energy)(xm) if mid is None else mid.grad_energy
    gS_mid = jax.grad(model.entropy)(xm) if mid is None else mid.grad_entropy
    gE = discrete_gradient(gE_mid, energy0, energy1, x0, x1)
    gS = discrete_gradient(gS_mid, entropy0, entropy1, x0, x1)
    reuse = mid is not None
    L = mid.poisson if reuse and not model.poisson.uses_gradient else model.poisson(xm, gS)
    M = mid.friction if reuse and not model.friction.uses_gradient else model.friction(xm, gE)
    reversible = project_out(gS, L @ project_out(gS, gE))
    irreversible = project_out(gE, M @ project_out(gE, gS))
    return reversible + irreversible


class DiscreteGradient(_Implicit):
    r"""Structure-preserving discrete-gradient GENERIC step (Gonzalez 1996; Öttinger 2018;
    Romero 2009):

    .. math:: \frac{x_1 - x_0}{\Delta t} = \bar L\,\bar\nabla E + \bar M\,\bar\nabla S

    (see :func:`discrete_generic_field`). Because :math:`\bar\nabla E\cdot\Delta = E(x_1) -
    E(x_0)`, antisymmetry of :math:`\bar L` and :math:`\bar M\bar\nabla E = 0` give
    :math:`E(x_1) = E(x_0)` to solver tolerance, and :math:`S(x_1) - S(x_0) = \Delta t\,
    \bar\nabla S^\top\bar M\,\bar\nabla S \ge 0`, at every step, for **any** model — a
    learned one included — and any energy, not only quadratic ones. Second order.

    ```python
    xs = mx.simulate(model, x0, ts, scheme=mx.DiscreteGradient())
    loss = mx.SchemeResidual(mx.DiscreteGradient())  # train for this rollout
    ```
    """

    name: ClassVar[str] = "discrete-gradient"

    def start(self, model, x0):
        return model.energy(x0), model.entropy(x0)

    def average(self, model, x0, x1, start):
        energy0, entropy0 = start
        return discrete_generic_field(
            model, x0, x1, energy0, model.energy(x1), entropy0, model.entropy(x1)
        )

    def residual(self, model, x0, x1, dt, terms0, terms1, mid: Terms | None = None):
        field = discrete_generic_field(
            model, x0, x1, terms0.energy, terms1.energy, terms0.entropy, terms1.entropy, mid
        )
        return (x1 - x0) / dt - field


SCHEMES: dict[str, type[AbstractScheme]] = {
    "cn": CrankNicolson,
    "midpoint": ImplicitMidpoint,
    "discrete-gradient": DiscreteGradient,
    "rk4": RK4,
}


def scheme_from_name(name: str, *, solver: str | None = None) -> AbstractScheme:
    """The scheme called ``name``; ``solver`` (``auto``, ``newton``, ``fixed-point``) for an
    implicit one (default ``auto``)."""
    if name not in SCHEMES:
        raise MetriplexError(
            f"unknown time-stepping scheme {name!r}; choose one of {sorted(SCHEMES)}."
        )
    cls = SCHEMES[name]
    if solver is None:
        return cls()
    if not issubclass(cls, _Implicit):
        raise MetriplexError(
            f"--solver applies to the implicit schemes (cn, midpoint, discrete-gradient); "
            f"{name!r} is explicit. Leave --solver out."
        )
    return cls(solver=solver)


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


def _rollout(model, scheme, x0, ts):
    """Roll out a batch: ``x0`` ``(B, n)``, ``ts`` ``(B, T)``; the scan runs over time and each
    step advances the whole batch at once (so the scheme can decide per step, for the batch,
    whether Newton is needed)."""
    dts = jnp.diff(ts, axis=-1).T  # (T - 1, B)
    zero = jnp.zeros(x0.shape[:1], x0.dtype)

    def body(carry, dt):
        x, d1, h1, d2, h2, failed = carry
        # A failed trajectory takes zero steps from here on: its solves end at once.
        h = jnp.where(failed, 0.0, dt)
        guess = jax.vmap(_predict)(x, d1, h1, d2, h2, h)
        y, ok, its = scheme.step_batch(model, x, h, guess)
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


@eqx.filter_jit
def _rollout_one(model, scheme, x0, ts):
    xs, failed, its = _rollout(model, scheme, x0[None], ts[None])
    return xs[0], failed[0], its[0]


_rollout_batch = eqx.filter_jit(_rollout)


def step_failure(scheme: AbstractScheme, t0: float, t1: float, where: str = "") -> str:
    """What went wrong in a failed step from ``t0`` to ``t1`` (``where``, e.g. " of trajectory
    3", follows the times), and what to try, in the words of ``scheme``: an implicit step's
    solve did not converge; an explicit step (RK4) has nothing to converge, its new state was
    not finite."""
    name = getattr(scheme, "name", "") or type(scheme).__name__
    span = f"from t={t0:.6g} to t={t1:.6g}{where}"
    if isinstance(scheme, _Implicit):
        return (
            f"the implicit {name} step {span} did not converge (solver {scheme.solver!r}). Try "
            "the Newton solver (--solver newton), a smaller time step, or RK4 (--scheme rk4) "
            "to see whether the model itself blows up"
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
    xs, failed, its = _rollout_batch(model, scheme, x0, ts)
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
        what = step_failure(CrankNicolson() if scheme is None else scheme,
                            float(ts_b[k - 1]), float(ts_b[k]), f" of trajectory {b}")
        raise RolloutFailure(
            f"step {k}: {what}. The {k} states computed before it are in .partial.",
            partial=xs_b[:k],
            trajectory=b,
            time=float(ts_b[k]),
        )
    return out.xs
