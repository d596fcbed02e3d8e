"""Ground-truth systems: GENERIC structure, explicit equations, and generated data."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import metriplex as mx
from metriplex.systems import (
    SYSTEMS,
    GasContainers,
    PendulumConfig,
    PendulumEnergetic,
    PendulumTemperature,
    RigidBody,
    entropy_to_temperature,
    generate,
    get_system,
    temperature_to_entropy,
)

CASES = {
    "rigid-body": ("rigid-body", {}),
    "pendulum-energetic": ("pendulum-energetic", {}),
    "pendulum-energetic-spnn": ("pendulum-energetic", {"parameter_set": "spnn"}),
    "pendulum-temperature": ("pendulum-temperature", {}),
    "pendulum-temperature-spnn": ("pendulum-temperature", {"parameter_set": "spnn"}),
    "gas-containers": ("gas-containers", {}),
}

# (steps, bound on max |generate - DOP853|) with 3 trajectories, seed 0, the system's published
# dt and default substeps: the figures stated in `generate`'s docstring. Print the measured ones
# with `pytest tests/test_systems.py -k dop853 -s` (the full spnn horizon is marked slow: the
# stiff heat conduction costs explicit DOP853 ~1e5 evaluations per trajectory).
DOP853_BOUND = {
    "rigid-body": (200, 1e-10),
    "pendulum-energetic": (400, 1e-6),
    "pendulum-energetic-spnn": (40, 1e-7),
    "pendulum-temperature": (500, 1e-6),
    # theta ~ 300: DOP853's own theta error (3.6e-6, i.e. 1e-8 relative; it moves by as much at
    # rtol 1e-13) dominates; against DOP853 run in (q, p, s) and mapped, generate is 5e-8 off.
    "pendulum-temperature-spnn": (40, 2e-5),
    "gas-containers": (400, 1e-7),
}


def batched(fn):
    """``fn`` mapped over a leading axis, compiled once (eager vmap compiles op by op)."""
    return jax.jit(jax.vmap(fn))


def system(case: str):
    name, params = CASES[case]
    return get_system(name, **params)


@functools.cache
def data(case: str) -> np.ndarray:
    """Generated trajectories, shape (3, steps + 1, n); cached across tests."""
    s = system(case)
    steps = DOP853_BOUND[case][0]
    out = generate(s, trajectories=3, steps=steps, dt=s.defaults.dt, seed=0)
    assert out.names == s.names
    return out.x.reshape(3, steps + 1, s.n)


def states(case: str) -> jnp.ndarray:
    """64 states: 32 freshly sampled initial states and 32 from generated trajectories."""
    s = system(case)
    if isinstance(s, RigidBody):
        sampled = np.random.default_rng(1).normal(size=(32, 3)) * 2.0
    else:
        sampled = s.sample_initial(32, seed=1)
    along = data(case).reshape(-1, s.n)
    along = along[np.linspace(0, len(along) - 1, 32).astype(int)]
    return jnp.asarray(np.concatenate([sampled, along]))


# -- structure ----------------------------------------------------------------------------------
@pytest.mark.parametrize("case", CASES)
def test_generic_structure(case):
    model = system(case).model
    x = states(case)
    t = batched(model.terms)(x)
    L, M = np.asarray(t.poisson), np.asarray(t.friction)
    gE, gS = np.asarray(t.grad_energy), np.asarray(t.grad_entropy)
    np.testing.assert_array_equal(L, -np.swapaxes(L, 1, 2))
    np.testing.assert_array_equal(M, np.swapaxes(M, 1, 2))
    scale_M = np.max(np.abs(M), axis=(1, 2))
    assert np.all(np.linalg.eigvalsh(M)[:, 0] >= -1e-12 * scale_M)
    LgS = np.einsum("bij,bj->bi", L, gS)
    MgE = np.einsum("bij,bj->bi", M, gE)
    tol_L = 1e-13 * (1.0 + np.max(np.abs(L), axis=(1, 2)) * np.max(np.abs(gS), axis=1))
    tol_M = 1e-13 * (1.0 + scale_M * np.max(np.abs(gE), axis=1))
    assert np.all(np.max(np.abs(LgS), axis=1) <= tol_L)
    assert np.all(np.max(np.abs(MgE), axis=1) <= tol_M)
    # dS/dt = grad S . M grad S >= 0 at every state.
    assert np.all(np.einsum("bi,bij,bj->b", gS, M, gS) >= -1e-13 * scale_M)


@pytest.mark.parametrize("case", CASES)
def test_jacobi_identity(case):
    model = system(case).model
    residual = batched(model.jacobi_tensor)(states(case)[::4])
    assert float(jnp.max(jnp.abs(residual))) <= 1e-12


# -- explicit equations ---------------------------------------------------------------------------
def test_rigid_body_is_euler():
    s = get_system("rigid-body", inertia=(2.0, 3.0, 7.0))
    m = np.asarray(states("rigid-body"))
    f = np.asarray(batched(s.model.vector_field)(jnp.asarray(m)))
    expected = np.cross(m, m / np.array([2.0, 3.0, 7.0])[None, :])
    np.testing.assert_allclose(f, expected, rtol=1e-13, atol=1e-14)


def _pendulum_explicit(c: PendulumConfig, x: np.ndarray) -> np.ndarray:
    """docs/physics.md, 'Thermoelastic pendulum in entropy variables', written out by hand (numpy,
    float64), states in (q, p, s)."""
    q1, q2, p1, p2, s = x[:, 0:2], x[:, 2:4], x[:, 4:6], x[:, 6:8], x[:, 8:10]
    d = q2 - q1
    r1, r2 = np.sum(q1**2, axis=1), np.sum(d**2, axis=1)
    a = 0.5 * np.log(np.stack([r1, r2], axis=1) / np.asarray(c.rest_lengths)[None, :] ** 2)
    beta, c0, C = (np.asarray(v)[None, :] for v in (c.beta, c.heat_capacity, c.stiffness))
    theta = c.theta_ref * np.exp((s - beta * a) / c0)
    sigma = C * a + beta * c.theta_ref - beta * theta  # dE/da at fixed s
    m1, m2 = c.masses
    dp1 = -sigma[:, :1] * q1 / r1[:, None] + sigma[:, 1:] * d / r2[:, None]
    dp2 = -sigma[:, 1:] * d / r2[:, None]
    ds1 = c.kappa * (theta[:, 1] / theta[:, 0] - 1.0)
    ds2 = c.kappa * (theta[:, 0] / theta[:, 1] - 1.0)
    return np.concatenate([p1 / m1, p2 / m2, dp1, dp2, ds1[:, None], ds2[:, None]], axis=1)


@pytest.mark.parametrize("case", ["pendulum-energetic", "pendulum-energetic-spnn"])
def test_pendulum_energetic_explicit(case):
    s = system(case)
    x = states(case)
    f = np.asarray(batched(s.model.vector_field)(x))
    expected = _pendulum_explicit(s.config, np.asarray(x))
    scale = np.max(np.abs(expected), axis=0, keepdims=True)
    np.testing.assert_allclose(f / scale, expected / scale, rtol=0.0, atol=1e-12)


@pytest.mark.parametrize("case", ["pendulum-temperature", "pendulum-temperature-spnn"])
def test_pendulum_temperature_is_the_transformed_flow(case):
    """f_theta(x') = J(x) f_s(x) with J = d(q,p,theta)/d(q,p,s), and E' = E, S' = S."""
    s = system(case)
    energetic = PendulumEnergetic(s.config)
    xt = states(case)
    xs = temperature_to_entropy(xt, s.config)
    np.testing.assert_allclose(entropy_to_temperature(xs, s.config), xt, rtol=1e-14)
    to_t = functools.partial(entropy_to_temperature, config=s.config)
    J = batched(jax.jacfwd(to_t))(xs)
    f_s = batched(energetic.model.vector_field)(xs)
    pushed = np.asarray(jnp.einsum("bij,bj->bi", J, f_s))
    f_t = np.asarray(batched(s.model.vector_field)(xt))
    scale = np.max(np.abs(pushed), axis=0, keepdims=True)
    np.testing.assert_allclose(f_t / scale, pushed / scale, rtol=0.0, atol=1e-12)
    # Also the closed forms L' = J L J^T and M' = J M J^T themselves.
    Ls = batched(energetic.model.poisson_matrix)(xs)
    Lt = batched(s.model.poisson_matrix)(xt)
    JLJ = jnp.einsum("bik,bkl,bjl->bij", J, Ls, J)
    np.testing.assert_allclose(Lt, JLJ, rtol=1e-12, atol=1e-12 * float(jnp.max(jnp.abs(JLJ))))
    gE = batched(jax.grad(energetic.model.energy))(xs)
    Ms = batched(energetic.model.friction)(xs, gE)
    Mt = batched(s.model.friction)(xt, batched(jax.grad(s.model.energy))(xt))
    JMJ = jnp.einsum("bik,bkl,bjl->bij", J, Ms, J)
    np.testing.assert_allclose(Mt, JMJ, rtol=1e-12, atol=1e-12 * float(jnp.max(jnp.abs(JMJ))))
    # E and S are sums of terms up to ~c0 * theta_ref in size that cancel; compare at that scale.
    term = max(c0 * s.config.theta_ref for c0 in s.config.heat_capacity)
    pairs = ((s.model.energy, energetic.model.energy), (s.model.entropy, energetic.model.entropy))
    for a, b in pairs:
        np.testing.assert_allclose(batched(a)(xt), batched(b)(xs), rtol=0.0, atol=1e-14 * term)
    # The explicit temperature equation of docs/physics.md, 'Thermoelastic pendulum in temperature
    # variables'.
    c = s.config
    x = np.asarray(xs)
    f = _pendulum_explicit(c, x)
    th = np.asarray(xt)[:, 8:10]
    d, dd = x[:, 2:4] - x[:, 0:2], f[:, 2:4] - f[:, 0:2]
    adot = np.stack(
        [np.sum(x[:, 0:2] * f[:, 0:2], 1) / np.sum(x[:, 0:2] ** 2, 1),
         np.sum(d * dd, 1) / np.sum(d**2, 1)], axis=1)
    beta, c0 = np.asarray(c.beta)[None, :], np.asarray(c.heat_capacity)[None, :]
    thdot = -beta * th / c0 * adot + c.kappa * (th[:, ::-1] - th) / c0
    np.testing.assert_allclose(f_t[:, 8:10], thdot, rtol=1e-10, atol=1e-10 * np.max(np.abs(thdot)))


def test_gas_containers_explicit():
    s = get_system("gas-containers", alpha=3.0, mass=2.0)
    x = np.asarray(states("gas-containers"))
    f = np.asarray(batched(s.model.vector_field)(jnp.asarray(x)))
    q, p, S1, S2 = x.T
    E1 = (np.exp(S1) / q) ** (2.0 / 3.0)
    E2 = (np.exp(S2) / (2.0 - q)) ** (2.0 / 3.0)
    expected = np.stack(
        [p / 2.0, 2.0 / 3.0 * (E1 / q - E2 / (2.0 - q)),
         9.0 * 3.0 / 4.0 / E1 * (1.0 / E1 - 1.0 / E2),
         -9.0 * 3.0 / 4.0 / E2 * (1.0 / E1 - 1.0 / E2)], axis=1)
    np.testing.assert_allclose(f, expected, rtol=1e-12, atol=1e-12)


# -- generated data -------------------------------------------------------------------------------
# Bounds on |E(t) - E(0)| relative to |E(0)|, measured values are 10-1000x lower.
ENERGY_DRIFT = {
    "rigid-body": 1e-12,
    "pendulum-energetic": 1e-8,
    "pendulum-energetic-spnn": 2e-7,
    "pendulum-temperature": 1e-8,
    "pendulum-temperature-spnn": 2e-7,
    "gas-containers": 1e-9,
}


@pytest.mark.parametrize("case", CASES)
def test_generated_energy_conserved_entropy_nondecreasing(case):
    s = system(case)
    xs = jnp.asarray(data(case))
    E = np.asarray(batched(batched(s.model.energy))(xs))
    S = np.asarray(batched(batched(s.model.entropy))(xs))
    drift = np.max(np.abs(E - E[:, :1]) / np.abs(E[:, :1]))
    assert drift <= ENERGY_DRIFT[case], drift
    dS = np.diff(S, axis=1)
    assert np.min(dS) >= -1e-13 * np.max(np.abs(S)), np.min(dS)
    if isinstance(s, RigidBody):  # the Casimir |m|^2 too
        c = np.sum(np.asarray(xs) ** 2, axis=2)
        assert np.max(np.abs(c - c[:, :1])) <= 1e-12
    else:  # heat does flow: S grows by a visible amount
        assert np.all(S[:, -1] - S[:, 0] > 1e-6 * np.max(np.abs(S)))


def _dop853(model, x0: np.ndarray, ts: np.ndarray) -> np.ndarray:
    """All trajectories as one ODE (one callback per stage), DOP853 rtol = atol = 1e-12."""
    f = batched(model.vector_field)
    shape = x0.shape

    def rhs(t, y):
        # The NumPy state straight into the compiled call: jnp.asarray first would be an eager
        # conversion per evaluation, 3x the call itself (up to 2e4 evaluations per case).
        return np.asarray(f(y.reshape(shape))).reshape(-1)

    sol = solve_ivp(rhs, (ts[0], ts[-1]), x0.reshape(-1), method="DOP853", rtol=1e-12,
                    atol=1e-12, t_eval=ts)
    assert sol.success, sol.message
    return np.moveaxis(sol.y.reshape(shape[0], shape[1], -1), 2, 1)


def _check_dop853(case, got, bound):
    s = system(case)
    steps = got.shape[1] - 1
    ts = np.arange(steps + 1) * s.defaults.dt
    ref = _dop853(s.model, got[:, 0, :], ts)
    err = float(np.max(np.abs(got - ref)))
    print(f"\n{case}: {steps} steps of dt={s.defaults.dt:.4g}, max |generate - DOP853| = {err:.2e}"
          f" (max |x| = {np.max(np.abs(ref)):.3g})")
    assert err <= bound


@pytest.mark.parametrize("case", CASES)
def test_generate_matches_dop853(case):
    _check_dop853(case, data(case), DOP853_BOUND[case][1])


@pytest.mark.slow
def test_generate_matches_dop853_spnn_full_horizon():
    s = system("pendulum-energetic-spnn")
    got = generate(s, trajectories=3, seed=0).x.reshape(3, s.defaults.steps + 1, s.n)
    _check_dop853("pendulum-energetic-spnn", got, 2e-5)


def test_generate_float32_without_x64():
    with jax.enable_x64(False):
        d = generate("gas-containers", trajectories=2, steps=20, dt=0.02, seed=0)
    ref = generate("gas-containers", trajectories=2, steps=20, dt=0.02, seed=0)
    assert d.x.shape == ref.x.shape == (42, 4)
    np.testing.assert_allclose(d.x, ref.x, atol=1e-4)


def test_generate_api():
    d = generate("gas-containers", trajectories=2, steps=5, dt=0.02, seed=4, substeps=3)
    assert isinstance(d, mx.Trajectories)
    assert d.names == ("q", "p", "S1", "S2")
    np.testing.assert_allclose(d.t[:6], np.arange(6) * 0.02)
    x0 = GasContainers().sample_initial(2, seed=4)
    np.testing.assert_array_equal(d.x.reshape(2, 6, 4)[:, 0], x0)
    same = generate(GasContainers(), x0=x0, steps=5, dt=0.02, substeps=3)
    np.testing.assert_array_equal(same.x, d.x)
    cn = generate("gas-containers", x0=x0, steps=5, dt=0.02, substeps=1,
                  scheme=mx.CrankNicolson())
    direct = mx.simulate(GasContainers().model, jnp.asarray(x0), jnp.arange(6.0) * 0.02)
    np.testing.assert_allclose(cn.x.reshape(2, 6, 4), direct, rtol=1e-12, atol=1e-12)
    for bad, match in (
        (dict(steps=0), "`steps` must be an integer >= 1; got 0"),
        (dict(dt=-0.1), "`dt` must be a positive finite number; got -0.1"),
        (dict(substeps=0), "`substeps` must be an integer >= 1; got 0"),
        (dict(x0=np.zeros((2, 3))), r"x0 must have shape \(trajectories, 4\)"),
        (dict(x0=np.ones((3, 4))), "got trajectories=2 but 3 initial states in x0"),
        (dict(steps=2.5), "`steps` must be an integer >= 1; got 2.5"),
    ):
        with pytest.raises(mx.MetriplexError, match=match):
            generate("gas-containers", trajectories=2, **{"steps": 5, "dt": 0.02, **bad})


# -- registry, parameters, sampling ---------------------------------------------------------------
def test_registry_and_errors():
    from metriplex.systems.zoo import ZOO

    assert set(SYSTEMS) == {"rigid-body", "pendulum-energetic", "pendulum-temperature",
                            "gas-containers"} | set(ZOO)
    for name, s in SYSTEMS.items():
        assert s.name == name and len(s.names) == s.n
        assert name in s.help_text() and "dt=" in s.help_text() and s.description
    with pytest.raises(mx.MetriplexError, match="unknown system 'nope'; the built-in systems "
                       "are rigid-body, pendulum-energetic, pendulum-temperature, gas-containers"):
        get_system("nope")
    with pytest.raises(mx.MetriplexError, match="has no parameter 'mass'; its parameters are"):
        get_system("rigid-body", mass=1.0)
    with pytest.raises(mx.MetriplexError, match=r"parameter 'inertia' must be a sequence of 3 "
                       r"numbers .*; got \(1, 2\) \(expected 3 numbers\)"):
        get_system("rigid-body", inertia=(1, 2))
    with pytest.raises(mx.MetriplexError, match="three positive moments"):
        get_system("rigid-body", inertia=(1.0, -2.0, 3.0))
    with pytest.raises(mx.MetriplexError, match="unknown pendulum parameter set 'big'"):
        get_system("pendulum-energetic", parameter_set="big")
    with pytest.raises(mx.MetriplexError, match="strictly inside"):
        get_system("gas-containers", x0_halfwidth=(1.5, 1, 1, 1))


def test_parameters():
    rb = get_system("rigid-body", inertia=(1, 2, 3), radius=0.5)
    assert rb.config.inertia == (1.0, 2.0, 3.0) and rb.config.radius == 0.5
    assert "inertia=(1, 2, 3)" in rb.parameter_summary()
    spnn = get_system("pendulum-temperature", parameter_set="spnn", kappa=100.0)
    assert isinstance(spnn, PendulumTemperature)
    assert spnn.config.masses == (1.0, 2.0) and spnn.config.kappa == 100.0
    assert (spnn.defaults.dt, spnn.defaults.steps, spnn.defaults.trajectories) == (0.3, 199, 50)
    unit = get_system("pendulum-energetic")
    assert (unit.defaults.dt, unit.defaults.steps, unit.defaults.trajectories) == (0.1, 400, 100)
    assert unit.names[-2:] == ("s1", "s2") and spnn.names[-2:] == ("theta1", "theta2")
    assert PendulumEnergetic(PendulumConfig.named("spnn")).relaxation_rate == pytest.approx(120.0)
    # Equal configurations give equal (hashable) models: jit caches are shared.
    assert get_system("rigid-body", radius=0.5).model == get_system("rigid-body", radius=0.5).model


def test_sampling():
    rb = get_system("rigid-body", radius=2.0)
    m = rb.sample_initial(500, seed=0)
    assert m.shape == (500, 3) and m.dtype == np.float64
    r = np.linalg.norm(m, axis=1)
    assert r.max() <= 2.0 and np.mean(r**3 <= 1.0) == pytest.approx(1.0 / 8.0, abs=0.05)
    np.testing.assert_array_equal(m, rb.sample_initial(500, seed=0))
    x = get_system("pendulum-energetic").sample_initial(200, seed=0)
    center = np.array([1.0, 0.0, 2.2, 0.0, 0.0, 2.0, 1.0, 0.0, 1.0, 0.2])
    assert np.all(np.abs(x - center[None, :]) <= 0.1)
    xt = get_system("pendulum-temperature").sample_initial(200, seed=0)
    np.testing.assert_allclose(xt, entropy_to_temperature(jnp.asarray(x)), rtol=1e-14)
    g = get_system("gas-containers").sample_initial(200, seed=0)
    lo = np.array([0.2, -1.0, 1.0, 1.0])
    assert np.all(g >= lo[None, :]) and np.all(g <= np.array([1.8, 1.0, 3.0, 3.0])[None, :])
    with pytest.raises(mx.MetriplexError, match="must be an integer >= 1; got 0"):
        rb.sample_initial(0, seed=0)
