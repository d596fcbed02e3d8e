"""Time stepping: orders of convergence, failure reporting, ragged grids, batching.

Each distinct (model, scheme, shape) compiles once (seconds), so the tests share models and
array shapes, and fold several resolutions into one padded, ragged batch.
"""

import logging

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import metriplex as mx
from metriplex.integrate import (
    RK4,
    SCHEMES,
    CrankNicolson,
    DiscreteGradient,
    Hermite,
    ROOT_FINDERS,
    FixedPoint,
    FixedPointThenNewton,
    ImplicitMidpoint,
    Newton,
    simulate,
    solve,
)
from metriplex.app.config import scheme_from_name
from metriplex.diagnostics import rollout_data
from metriplex.systems import Substeps


def _rotor_energy(x):
    r2 = jnp.sum(x**2)
    return 0.5 * r2 + 0.25 * r2**2


#: A nonlinear oscillator with a closed-form solution: :math:`E = \tfrac12 r^2 + \tfrac14 r^4`,
#: :math:`r^2 = q^2 + p^2`, canonical :math:`L`, so :math:`\dot q = (1 + r^2)p`,
#: :math:`\dot p = -(1 + r^2)q`: a rotation at the amplitude-dependent rate
#: :math:`\omega = 1 + r_0^2` (:func:`rotor_exact`).
ROTOR = mx.GenericModel(
    mx.Known(_rotor_energy), mx.ZeroPotential(), mx.CanonicalPoisson(2, 1), mx.ZeroFriction(2)
)
X_ROTOR = jnp.array([0.6, -0.3])


def rotor_exact(x0, t):
    x0 = np.asarray(x0, dtype=np.float64)
    w = 1.0 + np.sum(x0**2)
    c, s = np.cos(w * t), np.sin(w * t)
    return np.array([c * x0[0] + s * x0[1], -s * x0[0] + c * x0[1]])


def _cube(x):
    return x[0] ** 3 / 3.0


def _one(x):
    return jnp.ones((1, 1), x.dtype)


#: :math:`\dot x = x^2` as GENERIC (:math:`S = x^3/3`, :math:`M = 1`), with the solution
#: :math:`x_0/(1 - x_0 t)`. An implicit step of size :math:`\Delta t` from :math:`x` has no real
#: solution once :math:`\Delta t\,x` is large (for CN: :math:`2\Delta t x + \Delta t^2x^2 > 1`),
#: so Newton cannot converge.
BLOW_UP = mx.GenericModel(
    mx.ZeroPotential(), mx.Known(_cube), mx.ZeroPoisson(1), mx.KnownFriction(_one)
)
TS_BLOW_UP = jnp.array([0.0, 0.5, 1.0, 8.0, 8.5])


def _padded_grids(horizon, steps):
    """One row per resolution, each padded to the finest with repeated final times."""
    width = max(steps) + 1
    rows = [np.concatenate([np.linspace(0.0, horizon, k + 1), np.full(width - k - 1, horizon)])
            for k in steps]
    return jnp.asarray(np.stack(rows))


@pytest.mark.parametrize(
    "scheme, order",
    [(CrankNicolson(), 2), (ImplicitMidpoint(), 2), (RK4(), 4), (DiscreteGradient(), 2),
     (Hermite(), 4)],
    ids=["cn", "midpoint", "rk4", "discrete-gradient", "hermite"],
)
def test_order_of_convergence(scheme, order):
    horizon, steps = 2.0, [20, 40, 80, 160]
    ts = _padded_grids(horizon, steps)
    out = solve(ROTOR, jnp.broadcast_to(X_ROTOR, (len(steps), 2)), ts, scheme=scheme)
    assert out.ok
    xs = np.asarray(out.xs)
    exact = rotor_exact(X_ROTOR, horizon)
    errors = np.linalg.norm(xs[:, -1] - exact[None, :], axis=-1)
    slope = np.polyfit(np.log(horizon / np.asarray(steps)), np.log(errors), 1)[0]
    assert abs(slope - order) < 0.15, (slope, errors)
    if scheme.name in ("midpoint", "discrete-gradient"):
        # Both keep this energy (a function of the quadratic invariant r^2) exactly.
        E = np.asarray(jax.vmap(jax.vmap(_rotor_energy))(out.xs))
        assert np.max(np.abs(E - E[:, :1])) < 1e-13 * E[0, 0]


@pytest.mark.parametrize("scheme", [CrankNicolson(), DiscreteGradient()], ids=lambda s: s.name)
def test_failed_step_is_reported_not_silent_nan(scheme):
    x0 = jnp.array([[0.1], [0.01]])  # the first has no implicit step 1.0 -> 8.0, the second has
    out = solve(BLOW_UP, x0, TS_BLOW_UP, scheme=scheme)
    assert np.asarray(out.failed_step).tolist() == [3, -1]
    assert not out.ok
    xs = np.asarray(out.xs)
    assert np.all(np.isfinite(xs[0, :3])) and np.all(np.isnan(xs[0, 3:]))
    its = np.asarray(out.iterations)
    # It tried: the fixed-point iteration (which may stop early on overflow), then the whole
    # Newton budget.
    finder = scheme.root_finder
    assert finder.max_steps < its[0, 3] <= finder.fixed_point_steps + finder.max_steps
    assert np.all(its[0, 4:] == 0)  # and then stopped trying
    # The failed trajectory does not hold back the other one.
    assert np.all(np.isfinite(xs[1]))
    exact = 0.01 / (1.0 - 0.01 * np.asarray(TS_BLOW_UP))
    np.testing.assert_allclose(xs[1, :, 0], exact, rtol=1e-3)


@pytest.mark.parametrize("run", [lambda x0: simulate(BLOW_UP, x0, TS_BLOW_UP, retry=0),
                                 lambda x0: solve(BLOW_UP, x0, TS_BLOW_UP, throw=True)],
                         ids=["simulate", "solve-throw"])
def test_simulate_raises_with_partial_states(run):
    x0 = jnp.array([[0.01], [0.1]])
    with pytest.raises(mx.RolloutFailure, match=r"from t=1 to t=8 of trajectory 1 did not") as err:
        run(x0)
    assert err.value.trajectory == 1
    assert err.value.time == 8.0
    partial = np.asarray(err.value.partial)
    assert partial.shape == (3, 1) and np.all(np.isfinite(partial))
    assert partial[0, 0] == 0.1


def test_simulate_retakes_a_failed_step_in_substeps_as_rollout_does():
    # A new-user check's far initial state failed at the first step in Python and ran on
    # with `metriplex rollout`, which retries in substeps: simulate now does too.
    xs = np.asarray(simulate(BLOW_UP, jnp.array([[0.01], [0.1]]), TS_BLOW_UP))
    assert np.all(np.isfinite(xs))
    exact = 0.1 / (1.0 - 0.1 * np.asarray(TS_BLOW_UP))  # blows up at t = 10
    # Crank-Nicolson in 8 substeps of 0.875 near the blow-up: 10 % off at t = 8, more later.
    np.testing.assert_allclose(xs[1, :4, 0], exact[:4], rtol=0.1)
    assert np.all(np.diff(xs[1, :, 0]) > 0)


def test_rk4_blow_up_is_reported():
    ts = jnp.array([0.0, 0.5, 1.0, 100.0, 1.0e4])
    out = solve(BLOW_UP, jnp.array([1.0]), ts, scheme=RK4())
    # x(t) = 1/(1 - t) blows up at t = 1, which RK4 does not notice; its states stay finite
    # (about 1e45 at t = 100) until the last step overflows.
    assert int(out.failed_step) == 4
    assert np.all(np.isfinite(np.asarray(out.xs)[:4]))
    assert np.all(np.isnan(np.asarray(out.xs)[4]))


@pytest.mark.parametrize("scheme", [CrankNicolson(), RK4()], ids=lambda s: s.name)
def test_zero_steps_keep_the_state_and_ragged_grids_match(scheme):
    grids = jnp.array(
        [
            [0.0, 0.1, 0.25, 0.3, 0.35, 0.4],  # reference, no zero step
            [0.0, 0.1, 0.25, 0.3, 0.3, 0.3],  # padded at the end (ragged batch)
            [0.0, 0.1, 0.1, 0.25, 0.3, 0.3],  # a repeated time in the middle
        ]
    )
    out = solve(ROTOR, jnp.broadcast_to(X_ROTOR, (3, 2)), grids, scheme=scheme)
    assert out.ok
    xs = np.asarray(out.xs)
    ref = xs[0, :4]
    np.testing.assert_allclose(xs[1, :4], ref, rtol=0.0, atol=1e-14)
    assert np.all(xs[1, 4:] == xs[1, 3])
    np.testing.assert_allclose(xs[2, [0, 1, 3, 4]], ref, rtol=0.0, atol=1e-14)
    assert np.all(xs[2, 2] == xs[2, 1]) and np.all(xs[2, 5] == xs[2, 4])
    if scheme.name != "rk4":
        its = np.asarray(out.iterations)
        assert its[1, 4] <= 1 and its[2, 2] <= 1  # a zero step needs no real Newton work


def test_batched_equals_one_by_one_and_newton_stays_short():
    x0 = jnp.array([[0.6, -0.3], [0.1, 0.2], [-0.4, 0.0]])
    ts = jnp.stack([jnp.linspace(0.0, 3.0, 31), jnp.linspace(0.0, 1.0, 31),
                    jnp.concatenate([jnp.linspace(0.0, 2.0, 21), jnp.full((10,), 2.0)])])
    newton = CrankNicolson(root_finder=Newton())
    batched = solve(ROTOR, x0, ts, scheme=newton)
    assert np.asarray(batched.xs).shape == (3, 31, 2)
    for b in range(3):
        one = solve(ROTOR, x0[b], ts[b], scheme=newton)
        np.testing.assert_allclose(np.asarray(batched.xs[b]), np.asarray(one.xs),
                                   rtol=1e-12, atol=1e-14)
        # Rounding may differ between the batched and single programs, not the Newton work.
        assert np.max(np.abs(np.asarray(batched.iterations[b]) - np.asarray(one.iterations))) <= 1
    # A shared grid broadcasts over the batch.
    shared = solve(ROTOR, x0, ts[0], scheme=newton)
    np.testing.assert_allclose(
        np.asarray(shared.xs[1]), np.asarray(solve(ROTOR, x0[1], ts[0], scheme=newton).xs),
        rtol=1e-12, atol=1e-14,
    )
    # Newton starts from the quadratic through the last three states (error O(dt^3)): after
    # two steps, at dt = 1/30, one update plus Optimistix's confirming iteration suffice.
    its = np.asarray(batched.iterations)
    assert np.all(its[1, 3:] <= 2), its


def test_float32_rollout_keeps_its_dtype():
    # x64 is on in the tests: a float64 loop carry in the fixed-point solve would not trace.
    x0 = X_ROTOR.astype(jnp.float32)
    ts = jnp.linspace(0.0, 1.0, 11, dtype=jnp.float32)
    for scheme in (CrankNicolson(), CrankNicolson(root_finder=FixedPoint()), DiscreteGradient()):
        out = solve(ROTOR, x0, ts, scheme=scheme)
        assert out.ok and out.xs.dtype == jnp.float32
        np.testing.assert_allclose(np.asarray(out.xs[-1]), rotor_exact(X_ROTOR, 1.0), atol=5e-3)


def test_scheme_names():
    assert set(SCHEMES) >= {"cn", "midpoint", "discrete-gradient", "rk4"}
    for name, cls in SCHEMES.items():
        scheme = scheme_from_name(name)
        assert scheme.name == name and isinstance(scheme, cls)
    with pytest.raises(mx.MetriplexError, match="unknown time-stepping scheme 'euler'"):
        scheme_from_name("euler")


def test_bad_inputs_are_explained():
    with pytest.raises(mx.MetriplexError, match="non-decreasing"):
        solve(ROTOR, X_ROTOR, jnp.array([0.0, 0.2, 0.1]))
    with pytest.raises(mx.MetriplexError, match="model expects 2"):
        solve(ROTOR, jnp.zeros(3), jnp.array([0.0, 0.1]))
    with pytest.raises(mx.MetriplexError, match="finite"):
        solve(ROTOR, jnp.array([jnp.nan, 0.0]), jnp.array([0.0, 0.1]))
    with pytest.raises(mx.MetriplexError, match="2 grids for 3 initial states"):
        solve(ROTOR, jnp.zeros((3, 2)), jnp.zeros((2, 4)))


#: Linear decay :math:`\dot x = -kx` as GENERIC (:math:`S = -x^2/2`, :math:`M = k`). With
#: :math:`k\Delta t = 5` a fixed-point iteration of an implicit step diverges (its contraction
#: factor is :math:`k\Delta t/2` for CN), so only Newton can take the step.
def _minus_half_square(x):
    return -0.5 * x[0] ** 2


STIFF = mx.GenericModel(
    mx.ZeroPotential(), mx.Known(_minus_half_square), mx.ZeroPoisson(1),
    mx.KnownFriction(lambda x: 50.0 * jnp.ones((1, 1), x.dtype)),
)
TS_STIFF = jnp.linspace(0.0, 1.0, 11)  # k dt = 5


def test_auto_solver_matches_newton_and_falls_back_where_the_fixed_point_diverges():
    # Non-stiff: the fixed point alone converges, to Newton's solution.
    x0 = jnp.array([[0.6, -0.3], [0.1, 0.2]])
    ts = jnp.linspace(0.0, 3.0, 31)
    auto = solve(ROTOR, x0, ts, scheme=CrankNicolson())
    newton = solve(ROTOR, x0, ts, scheme=CrankNicolson(root_finder=Newton()))
    fixed = solve(ROTOR, x0, ts, scheme=CrankNicolson(root_finder=FixedPoint()))
    assert auto.ok and newton.ok and fixed.ok
    np.testing.assert_allclose(np.asarray(auto.xs), np.asarray(newton.xs), rtol=0, atol=1e-13)
    # Once the predictor has two past steps, no step needs Newton.
    assert np.all(np.asarray(auto.iterations)[:, 3:] <= FixedPointThenNewton().fixed_point_steps)
    # Stiff: the fixed point fails, Newton takes over, and the step is exactly CN's.
    x1 = jnp.array([[1.0], [0.5]])
    fixed = solve(STIFF, x1, TS_STIFF, scheme=CrankNicolson(root_finder=FixedPoint()))
    assert np.asarray(fixed.failed_step).tolist() == [1, 1]
    auto = solve(STIFF, x1, TS_STIFF, scheme=CrankNicolson())
    assert auto.ok
    its = np.asarray(auto.iterations)
    assert np.all(its[:, 1:] > FixedPointThenNewton().fixed_point_steps)  # Newton ran at every step
    growth = (1 - 2.5) / (1 + 2.5)  # CN's amplification factor at k dt = 5
    exact_cn = np.asarray(x1) * growth ** np.arange(11)[None, :]
    np.testing.assert_allclose(np.asarray(auto.xs)[..., 0], exact_cn, rtol=1e-12, atol=1e-14)


def test_a_step_whose_solve_fails_is_retaken_in_substeps_when_asked():
    # k dt = 5: the fixed point diverges (its contraction factor is k dt / 2 = 2.5); in 8
    # substeps (k dt / 16 < 1) it converges, and the step is exactly 8 CN substeps.
    x1 = jnp.array([[1.0], [0.5]])
    scheme = CrankNicolson(root_finder=FixedPoint())
    assert np.asarray(solve(STIFF, x1, TS_STIFF, scheme=scheme).failed_step).tolist() == [1, 1]
    out = solve(STIFF, x1, TS_STIFF, scheme=scheme, retry=8)
    assert out.ok
    growth = ((1 - 5 / 16) / (1 + 5 / 16)) ** 8  # 8 CN substeps of k dt = 5/8
    exact = np.asarray(x1) * growth ** np.arange(11)[None, :]
    np.testing.assert_allclose(np.asarray(out.xs)[..., 0], exact, rtol=1e-9, atol=1e-12)
    # A model that blows up fails either way: retrying changes nothing there.
    grows = mx.GenericModel(mx.Known(lambda x: 0.0 * x[0]), mx.Known(lambda x: x[0]),
                            mx.ZeroPoisson(1), mx.KnownFriction(lambda x: x[None, :] ** 4))
    big = solve(grows, jnp.array([[2.0]]), jnp.linspace(0.0, 5.0, 6), scheme=scheme, retry=8)
    assert not big.ok
    bound = "retry must be an integer from 0 to 1000; got"
    with pytest.raises(mx.MetriplexError, match=f"{bound} -1"):
        solve(STIFF, x1, TS_STIFF, retry=-1)
    # retry ** 2 substeps must stay countable in int32: 50 000 would wrap to a negative count.
    with pytest.raises(mx.MetriplexError, match=f"{bound} 50000"):
        solve(STIFF, x1, TS_STIFF, retry=50_000)


def test_a_step_whose_substeps_fail_is_retaken_once_more_in_the_square_of_them():
    # k dt = 40: in 8 substeps the fixed point still diverges (k dt / 16 = 2.5); in 64 it
    # converges (k dt / 128 < 1), and the step is exactly 64 CN substeps. At k dt = 400 the
    # 64 substeps diverge too, and the rollout fails: two retries, no more.
    x1 = jnp.array([[1.0], [0.5]])
    scheme = CrankNicolson(root_finder=FixedPoint())
    out = solve(STIFF, x1, 8 * TS_STIFF, scheme=scheme, retry=8)
    assert out.ok
    growth = ((1 - 40 / 128) / (1 + 40 / 128)) ** 64
    exact = np.asarray(x1) * growth ** np.arange(11)[None, :]
    np.testing.assert_allclose(np.asarray(out.xs)[..., 0], exact, rtol=1e-9, atol=1e-12)
    assert np.asarray(solve(STIFF, x1, 80 * TS_STIFF, scheme=scheme,
                            retry=8).failed_step).tolist() == [1, 1]


def test_rollouts_with_and_without_retry_are_one_compiled_program(caplog):
    # The retry's substeps are rounds of the step that the first attempt takes, and the
    # number of substeps is traced: training's held-out rollouts (no retry) and the
    # evaluation's (8 substeps) compile once between them, and retrying changes nothing
    # where every step converges at once.
    x1 = jnp.array([[1.0], [0.5]])
    scheme = CrankNicolson(root_finder=FixedPoint())
    ts = jnp.linspace(0.0, 0.1, 11)  # k dt = 0.05: the fixed point converges at every step
    jax.clear_caches()  # count this test's compilations, whatever ran before in this process
    with jax.log_compiles(), caplog.at_level(logging.WARNING, logger="jax"):
        plain = solve(STIFF, x1, ts, scheme=scheme)
        retried = solve(STIFF, x1, ts, scheme=scheme, retry=8)
        failing = solve(STIFF, x1, TS_STIFF, scheme=scheme, retry=8)
    compiled = [r.getMessage().split(" with ")[0] for r in caplog.records
                if r.getMessage().startswith("Compiling jit(_rollout)")]
    assert len(compiled) == 1, compiled
    np.testing.assert_array_equal(np.asarray(plain.xs), np.asarray(retried.xs))
    np.testing.assert_array_equal(np.asarray(plain.iterations), np.asarray(retried.iterations))
    assert plain.ok and failing.ok  # the retried stiff steps converge in their substeps


def test_rows_of_one_batch_retry_converge_and_wait_each_at_its_own_stage():
    # One batch: a stiff row whose every step is retried (k dt = 5), a row whose steps
    # converge at once (k dt = 0.05), and a padded row that takes zero steps. Each is what it
    # would be alone: 8 substeps of the inner scheme, the plain rollout, the constant state.
    scheme = CrankNicolson(root_finder=FixedPoint())
    x0 = jnp.array([[1.0], [0.5], [2.0]])
    grids = jnp.stack([TS_STIFF, jnp.linspace(0.0, 0.1, 11), jnp.zeros(11)])
    out = solve(STIFF, x0, grids, scheme=scheme, retry=8)
    assert out.ok
    alone = solve(STIFF, x0[:1], grids[:1], scheme=Substeps(scheme, 8))
    plain = solve(STIFF, x0[1:2], grids[1:2], scheme=scheme)
    # (to the fixed point's tolerance: Substeps starts each step from another guess)
    np.testing.assert_allclose(np.asarray(out.xs[0]), np.asarray(alone.xs[0]), rtol=1e-9,
                               atol=1e-12)
    np.testing.assert_array_equal(np.asarray(out.xs[1]), np.asarray(plain.xs[0]))
    np.testing.assert_array_equal(np.asarray(out.xs[2]), 2.0)
    its = np.asarray(out.iterations)
    # the retried row's first step: its failed first attempt and its 8 substeps; the padded
    # row: nothing
    assert its[0, 1] > np.asarray(alone.iterations)[0, 1] > 0
    np.testing.assert_array_equal(its[1], np.asarray(plain.iterations)[0])
    assert np.all(its[2] == 0)


def test_a_root_finder_is_an_object_and_a_solver_name_is_parsed_at_the_edge():
    # The library takes root finder objects; a string is explained, never silently kept.
    with pytest.raises(mx.MetriplexError, match="root_finder must be a root finder"):
        CrankNicolson(root_finder="newton")
    assert isinstance(CrankNicolson().root_finder, FixedPointThenNewton)
    # The command line's names: every registered root finder, and only implicit schemes.
    for name, (cls, _) in ROOT_FINDERS.items():
        scheme = scheme_from_name("midpoint", solver=name)
        assert isinstance(scheme, ImplicitMidpoint) and type(scheme.root_finder) is cls
    with pytest.raises(mx.MetriplexError, match="--solver must be one of auto, newton"):
        scheme_from_name("cn", solver="bisection")
    with pytest.raises(mx.MetriplexError, match="--solver applies to the implicit schemes "
                                                r"\(cn, midpoint, discrete-gradient, hermite\)"):
        scheme_from_name("rk4", solver="newton")


def test_error_to_horizon_ignores_a_failure_after_the_horizon():
    # Trajectory 0 blows up between t = 1 and t = 8 (its implicit step fails there); up to
    # t = 1 its states exist and match the exact solution to the scheme's error.
    x0 = np.array([0.1, 0.01])
    ts = np.asarray(TS_BLOW_UP)
    xs = x0[:, None] / (1.0 - x0[:, None] * ts[None, :])
    xs[0, 3:] = xs[0, 2]  # the exact solution is gone too (it blows up at t = 10)
    data = mx.Trajectories.from_list([(ts, xs[b][:, None]) for b in range(2)], ["x"])
    # Without the evaluation's retry: in 8 substeps the step from t = 1 to 8 converges (the
    # exact solution lives until t = 10), and this test is about a rollout that failed.
    failing = rollout_data(BLOW_UP, data, retry=0)
    report = mx.evaluate(BLOW_UP, data, horizon=1.0, rollout=failing)
    assert report["rollout_failures"] == 1
    assert report["rollout_error"][0] == float("inf")
    assert report["rollout_error_to_horizon"][0] < 1e-3
    assert np.isfinite(report["rollout_error_to_horizon_mean"])
    # A failure within the horizon still counts as an infinite error there.
    assert mx.evaluate(BLOW_UP, data, horizon=8.0, rollout=failing)[
        "rollout_error_to_horizon"][0] == float("inf")
    # With the retry (evaluate's default) the rollout completes.
    assert mx.evaluate(BLOW_UP, data, horizon=1.0)["rollout_failures"] == 0
