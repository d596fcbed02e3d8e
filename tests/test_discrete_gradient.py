"""The discrete-gradient GENERIC step: exact energy balance and entropy production, any model.

Each distinct (model, scheme, shape) compiles once (seconds): the tests share models and shapes.
"""

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np
import pytest
from scipy.integrate import solve_ivp

import metriplex as mx
from metriplex.integrate import (
    CrankNicolson,
    DiscreteGradient,
    discrete_generic_field,
    discrete_gradient,
    project_out,
    solve,
)

DG = DiscreteGradient()


@eqx.filter_jit
def _along(fn, xs):
    """``fn`` at every state of rollouts ``xs`` (batch, time, n), one compiled call (op by op,
    every operation of a network would compile on its own)."""
    return jax.vmap(jax.vmap(fn))(xs)


def random_model(n, seed, *, poisson=mx.SkewMLPPoisson, friction=mx.CholeskyFriction):
    k = jr.split(jr.key(seed), 4)
    return mx.GenericModel(
        energy=mx.MLPPotential(n, width=16, depth=2, key=k[0]),
        entropy=mx.MLPPotential(n, width=16, depth=2, key=k[1]),
        poisson=poisson(n, width=16, depth=2, key=k[2]),
        friction=friction(n, width=16, depth=2, key=k[3]),
    )


def _damped_friction(x):
    w = jnp.stack([jnp.zeros((), x.dtype), jnp.ones((), x.dtype), -x[1]])
    return 0.5 * jnp.outer(w, w)


def _damped_energy(x):
    return 0.5 * (x[0] ** 2 + x[1] ** 2) + x[2] + 0.1 * x[0] ** 4


#: A smooth dissipative GENERIC system, (q, p, s): E = (q^2 + p^2)/2 + q^4/10 + s, S = s,
#: canonical L on (q, p), M = kappa w w^T with w = (0, 1, -p), so M grad E = 0, the momentum is
#: damped, q' = p, p' = -q - 0.4 q^3 - kappa p, and s' = kappa p^2 >= 0.
DAMPED = mx.GenericModel(
    mx.Known(_damped_energy), mx.SumOf((2,)), mx.CanonicalPoisson(3, 1),
    mx.KnownFriction(_damped_friction),
)
X_DAMPED = jnp.array([[1.0, 0.0, 0.0], [-0.5, 0.8, 0.3]])


def _pairs(n, seed, scales):
    """Random pairs (x0, x1) with |x1 - x0| about each of ``scales`` (0: identical)."""
    k0, k1 = jr.split(jr.key(seed))
    x0 = jr.normal(k0, (len(scales), n))
    d = jr.normal(k1, (len(scales), n))
    d = d / jnp.linalg.norm(d, axis=1, keepdims=True) * jnp.asarray(scales)[:, None]
    return x0, x0 + d


SCALES = [1.0, 0.1, 1e-3, 1e-6, 1e-9, 0.0]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_discrete_gradient_identity(seed):
    n = 5
    # The third network sees rotation-invariant features, as the pendulum presets do.
    features = mx.FeatureMap((((0, 1), ()), ((2, 3), (0, 1))), (4,)) if seed == 2 else None
    E = mx.MLPPotential(n, width=16, depth=2, features=features, key=jr.key(seed))
    x0, x1 = _pairs(n, seed + 10, SCALES)

    @jax.jit
    @jax.vmap
    def check(a, b):
        g = discrete_gradient(jax.grad(E)(0.5 * (a + b)), E(a), E(b), a, b)
        return jnp.sum(g * (b - a)), E(b) - E(a), g, jax.grad(E)(a)

    lhs, rhs, g, g0 = (np.asarray(v) for v in check(x0, x1))
    scale = np.abs(np.asarray(jax.vmap(E)(x0))) + 1.0
    assert np.all(np.isfinite(g))
    assert np.all(np.abs(lhs - rhs) <= 1e-15 * scale), (lhs - rhs) / scale
    # A second-order approximation of the midpoint gradient; exactly the gradient at x0 == x1.
    np.testing.assert_allclose(g[3:], g0[3:], atol=1e-5)
    np.testing.assert_array_equal(g[-1], g0[-1])


def test_no_nan_at_zero_step_nor_zero_gradients():
    n = 4
    model = random_model(n, 3)
    x = jr.normal(jr.key(4), (n,))

    @eqx.filter_jit
    def at_zero_step(model, x):
        # What Newton sees from a zero guess: the field and its Jacobian in x1 at x1 == x0.
        field, jac = jax.jvp(lambda y: DG.increment(model, x, y, 0.1), (x,), (jnp.ones_like(x),))
        t = model.terms(x)
        expected = project_out(t.grad_entropy, t.poisson @ project_out(t.grad_entropy,
                                                                        t.grad_energy))
        expected = expected + project_out(t.grad_energy,
                                          t.friction @ project_out(t.grad_energy, t.grad_entropy))

        # The gradient of the training residual in the weights, at a zero-length pair.
        def loss(m):
            tm = m.terms(x)
            return jnp.sum(DG.residual(m, x, x, 0.1, tm, tm) ** 2)

        return field, expected, jac, eqx.filter_grad(loss)(model)

    field, expected, jac, grads = at_zero_step(model, x)
    assert np.all(np.isfinite(np.asarray(jac)))
    assert all(np.all(np.isfinite(np.asarray(g))) for g in jax.tree_util.tree_leaves(grads))
    # At x1 == x0 the discrete gradients are the gradients: the step's field is the projected
    # continuous one, P L P grad E + Q M Q grad S.
    np.testing.assert_allclose(np.asarray(field), np.asarray(expected), rtol=1e-12, atol=1e-15)
    # Vanishing discrete gradients: the projectors become the identity, never NaN.
    flat = mx.GenericModel(mx.ZeroPotential(), mx.ZeroPotential(), model.poisson, model.friction)
    zero = jnp.zeros(())
    f = discrete_generic_field(flat, x, x + 0.1, zero, zero, zero, zero)
    assert np.all(np.asarray(f) == 0.0)
    v = jr.normal(jr.key(5), (n,))
    np.testing.assert_array_equal(np.asarray(project_out(jnp.zeros(n), v)), np.asarray(v))


@pytest.mark.parametrize("seed", [0, 1])
def test_discrete_operators_are_degenerate(seed):
    n = 6
    model = random_model(n, seed)
    x0, x1 = _pairs(n, seed + 20, [1.0, 0.3, 0.01, 1e-5])

    @jax.jit
    @jax.vmap
    def parts(a, b):
        E0, E1, S0, S1 = model.energy(a), model.energy(b), model.entropy(a), model.entropy(b)
        xm = 0.5 * (a + b)
        gE = discrete_gradient(jax.grad(model.energy)(xm), E0, E1, a, b)
        gS = discrete_gradient(jax.grad(model.entropy)(xm), S0, S1, a, b)
        f = discrete_generic_field(model, a, b, E0, E1, S0, S1)
        B = model.friction.factor(xm)
        q = project_out(gE, gS)
        return jnp.sum(gE * f), jnp.sum(gS * f), jnp.sum((B.T @ q) ** 2), jnp.sum(f**2)

    dE, dS, production, size = (np.asarray(v) for v in parts(x0, x1))
    assert np.all(np.abs(dE) <= 1e-13 * (1.0 + size))  # E-bar . (L-bar E-bar + M-bar S-bar) = 0
    np.testing.assert_allclose(dS, production, rtol=1e-10, atol=1e-15)  # |B^T Q S-bar|^2 >= 0


def _structured_variants():
    out = [("mlp", mx.SkewMLPPoisson, mx.CholeskyFriction)]
    poisson = getattr(mx.structure, "ProjectedSkewMLPPoisson", None)
    friction = getattr(mx.structure, "ProjectedCholeskyFriction", None)
    if poisson is not None and friction is not None:
        out.append(("exactly-degenerate", poisson, friction))
    return out


@pytest.mark.parametrize("label, poisson, friction", _structured_variants(),
                         ids=lambda v: v if isinstance(v, str) else "")
def test_random_learned_models_conserve_energy_and_produce_entropy(label, poisson, friction):
    n = 6
    model = random_model(n, 7, poisson=poisson, friction=friction)
    x0 = jr.normal(jr.key(8), (3, n))
    ts = jnp.linspace(0.0, 50.0, 1001)
    out = solve(model, x0, ts, scheme=DG)
    assert out.ok
    E = np.asarray(_along(model.energy, out.xs))
    S = np.asarray(_along(model.entropy, out.xs))
    drift = np.max(np.abs(E - E[:, :1]), axis=1) / np.maximum(np.abs(E[:, 0]), 1e-3)
    assert np.all(drift < 1e-10), drift
    dS = np.diff(S, axis=1)
    assert np.min(dS) >= -1e-13 * np.max(np.abs(S)), np.min(dS)
    assert np.min(S[:, -1] - S[:, 0]) > 1e-4  # the friction is doing something
    assert np.max(np.abs(np.asarray(out.xs[:, -1] - x0))) > 0.1  # and so is the motion


HORIZON, STEPS = 4.0, [20, 40, 80, 160]


@pytest.fixture(scope="module")
def damped_rollouts():
    """One compiled rollout for several tests: rows 0-3 start at the same state on ever finer
    grids (padded with repeated final times), rows 4-7 start elsewhere on the finest grid."""
    width = max(STEPS) + 1
    grids = [np.concatenate([np.linspace(0.0, HORIZON, k + 1), np.full(width - k - 1, HORIZON)])
             for k in STEPS]
    ts = np.stack(grids + [grids[-1]] * 4)
    others = jr.uniform(jr.key(0), (4, 3), minval=-1.0, maxval=1.0)
    x0 = jnp.concatenate([jnp.broadcast_to(X_DAMPED[1], (4, 3)), others])
    out = solve(DAMPED, x0, jnp.asarray(ts), scheme=DG)
    assert out.ok
    return out


def test_second_order_on_a_dissipative_problem_and_exact_balance(damped_rollouts):
    out = damped_rollouts
    f = jax.jit(DAMPED.vector_field)
    ref = solve_ivp(lambda t, x: np.asarray(f(x)), (0.0, HORIZON),
                    np.asarray(X_DAMPED[1]), method="DOP853", rtol=1e-12, atol=1e-12).y[:, -1]
    errors = np.linalg.norm(np.asarray(out.xs[:4, -1]) - ref[None, :], axis=1)
    slope = np.polyfit(np.log(HORIZON / np.asarray(STEPS)), np.log(errors), 1)[0]
    assert abs(slope - 2.0) < 0.15, (slope, errors)
    E = np.asarray(_along(_damped_energy, out.xs))
    assert np.max(np.abs(E - E[:, :1])) < 1e-13
    s = np.asarray(out.xs[..., 2])
    assert np.min(np.diff(s, axis=1)) >= 0.0 and s[0, -1] - s[0, 0] > 0.1


def _spnn_pendulum():
    """The ``spnn`` pendulum from metriplex.systems (docs/physics.md, 'Parameter sets'), with its
    initial states."""
    from metriplex.systems import get_system

    pend = get_system("pendulum-energetic", parameter_set="spnn")
    return pend.model, jnp.asarray(pend.sample_initial(2, seed=0))


@pytest.mark.slow
def test_spnn_pendulum_energy_at_the_published_dt():
    model, x0 = _spnn_pendulum()
    ts = jnp.arange(200.0) * 0.3  # the published 200 snapshots at dt = 0.3
    drift = {}
    for scheme in (DG, CrankNicolson()):
        out = solve(model, x0, ts, scheme=scheme)
        assert out.ok, scheme.name
        E = np.asarray(_along(model.energy, out.xs))
        drift[scheme.name] = np.max(np.abs(E - E[:, :1]) / np.abs(E[:, :1]))
        if scheme is DG:
            S = np.asarray(_along(model.entropy, out.xs))
            assert np.min(np.diff(S, axis=1)) >= -1e-15
    assert drift["discrete-gradient"] <= 1e-9, drift
    assert drift["cn"] >= 1e-2, drift


def _pairs_of(out, rows):
    xs = np.asarray(out.xs[rows])
    dt = np.diff(np.asarray(out.ts[rows]), axis=1).reshape(-1)
    keep = dt > 0  # drop the padding
    n = xs.shape[-1]
    return xs[:, :-1].reshape(-1, n)[keep], xs[:, 1:].reshape(-1, n)[keep], dt[keep]


def test_residual_vanishes_on_its_own_steps(damped_rollouts):
    x0, x1, dt = (jnp.asarray(a) for a in _pairs_of(damped_rollouts, slice(0, 4)))

    @jax.jit
    def residuals(x0, x1, dt):
        t0, t1 = jax.vmap(DAMPED.terms)(x0), jax.vmap(DAMPED.terms)(x1)
        axes = (None, 0, 0, 0, 0, 0)
        return (jax.vmap(DG.residual, in_axes=axes)(DAMPED, x0, x1, dt, t0, t1),
                jax.vmap(CrankNicolson().residual, in_axes=axes)(DAMPED, x0, x1, dt, t0, t1))

    dg, cn = residuals(x0, x1, dt)
    assert np.max(np.abs(np.asarray(dg))) < 1e-9
    assert np.max(np.abs(np.asarray(cn))) > 1e-5  # a different scheme sees a defect


def test_trained_model_rolls_out_with_its_energy_conserved(damped_rollouts):
    pairs = _pairs_of(damped_rollouts, slice(3, 8))
    k1, k2, k3 = jr.split(jr.key(1), 3)
    model = mx.GenericModel(
        energy=mx.MLPPotential(3, width=16, depth=2, key=k1),
        entropy=mx.SumOf((2,)),
        poisson=mx.CanonicalPoisson(3, 1),
        friction=mx.CholeskyFriction(3, width=16, depth=2, key=k2),
    )
    # lr 1e-3: this unnormalised hand-built model (no data statistics, no output scale) trained
    # at the default 1e-2 for 200 steps becomes stiff enough that a DG step at dt = 0.1 fails.
    trained, history = mx.fit(model, pairs, loss=mx.SchemeResidual(DG), steps=200,
                              batch_size=64, validation=None, eval_every=100, progress=False,
                              learning_rate=1e-3, key=k3)
    assert history.train["residual"][-1] < 0.5 * history.train["residual"][0]
    x0 = jnp.asarray(damped_rollouts.xs[4:6, 0])
    out = solve(trained, x0, jnp.linspace(0.0, 20.0, 201), scheme=DG)
    assert out.ok
    E = np.asarray(_along(trained.energy, out.xs))
    assert np.max(np.abs(E - E[:, :1]) / np.abs(E[:, :1])) <= 1e-9
    S = np.asarray(out.xs[..., 2])
    assert np.min(np.diff(S, axis=1)) >= -1e-15


def test_float32_steps_are_not_failed_for_the_rounding_of_a_large_energy():
    """In float32 the discrete gradient's (E1 - E0)/|x1 - x0| carries rounding of about
    eps |E| / |x1 - x0|: for an energy with a large offset Newton's updates stall above 1e-5.
    The float32 tolerance, 1e-4, accepts those steps (Newton converges quadratically, so the
    state is far more accurate than its last update); the former 1e-5 failed most of them."""
    from metriplex.integrate import FixedPointThenNewton

    energy = mx.Known(lambda x: 0.5 * x[1] ** 2 + 0.25 * x[0] ** 4 - jnp.cos(x[0]) + 1e5)
    model = mx.GenericModel(energy, mx.ZeroPotential(), mx.CanonicalPoisson(2, 1),
                            mx.ZeroFriction(2))
    x0 = jnp.asarray(np.random.default_rng(0).normal(size=(64, 2)), jnp.float32)
    ts = jnp.asarray(np.arange(200) * 0.005, jnp.float32)

    def failed(root_finder):
        out = solve(model, x0, ts, scheme=DiscreteGradient(root_finder=root_finder))
        return int(np.sum(np.asarray(out.failed_step) >= 0))

    assert failed(FixedPointThenNewton()) <= 2
    assert failed(FixedPointThenNewton(rtol=1e-5, atol=1e-5)) >= 20
