import equinox as eqx
import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np
import pytest

import metriplex as mx
from metriplex.losses import Batch
from helpers import damped_oscillator, make_data, oscillator_x0, rigid_body, rigid_x0


def _batch(data):
    p = data.pairs()
    return Batch(jnp.asarray(p.x0), jnp.asarray(p.x1), jnp.asarray(p.dt), jnp.ones(data.n))


def _compiled(loss):
    """``loss(model, batch)`` as one compiled program: evaluated op by op, a loss with nested
    derivatives compiles each of its many small operations separately (seconds each test)."""
    return eqx.filter_jit(lambda model, batch: loss(model, batch))


@pytest.mark.parametrize("system,x0", [(rigid_body, rigid_x0(3)), (damped_oscillator, oscillator_x0(3))])
def test_loss_is_zero_on_data_made_by_the_same_scheme(system, x0):
    model = system()
    data = make_data(model, x0, 0.1, 50)
    loss = mx.CrankNicolsonResidual() + 10.0 * mx.DegeneracyPenalty() + mx.JacobiPenalty()
    total, parts = _compiled(loss)(model, _batch(data))
    assert float(total) < 1e-20, parts
    # ... and clearly not zero for another scheme's residual on the same data
    total_mid, _ = _compiled(mx.MidpointResidual().as_loss())(model, _batch(data))
    assert float(total_mid) > 1e3 * max(float(total), 1e-30)


def test_loss_with_nonuniform_dt():
    model = damped_oscillator()
    ts = np.cumsum(np.r_[0.0, np.random.default_rng(0).uniform(0.02, 0.2, 40)])
    xs = mx.simulate(model, jnp.asarray(oscillator_x0(2)), jnp.asarray(ts))
    data = mx.Trajectories.from_arrays(ts, np.asarray(xs))
    total, _ = _compiled(mx.CrankNicolsonResidual().as_loss())(model, _batch(data))
    assert float(total) < 1e-20


def test_loss_composition_and_weights():
    loss = 2.0 * mx.CrankNicolsonResidual() + 3.0 * mx.DegeneracyPenalty()
    assert loss.names == ("residual", "degeneracy_L", "degeneracy_M")
    assert loss.weights == (2.0, 3.0, 3.0)
    with pytest.raises(mx.MetriplexError, match="loss weights must be >= 0"):
        -1.0 * mx.CrankNicolsonResidual()
    # Options are objects; a string (the former spelling) is explained, never silently kept.
    assert isinstance(mx.JacobiPenalty().estimator, mx.ExactJacobi)
    with pytest.raises(mx.MetriplexError, match=r"estimator must be a Jacobi estimator object, "
                       r"ExactJacobi\(\) .* or StochasticJacobi\(probes=K\) .*; got "
                       r"'stochastic'\. Write JacobiPenalty\(ExactJacobi\(\)\)"):
        mx.JacobiPenalty("stochastic")
    with pytest.raises(mx.MetriplexError, match=r"StochasticJacobi's probes \(random probe "
                                                r"triples per sample\) must be an integer >= 1; "
                                                r"got 0\."):
        mx.StochasticJacobi(probes=0)


def test_the_command_line_names_are_parsed_into_objects_at_the_edge():
    from metriplex.app._build import build_loss
    from metriplex.app.config import RunConfig

    def terms(**options):
        # Without the reversible-first stage the learned M keeps its M grad E = 0 penalty,
        # whose options are parsed here (with it, M is exactly degenerate: no penalty).
        config = RunConfig(reversible_first=False, **options)
        return {type(t).__name__: t for t in build_loss(config).terms}

    t = terms(jacobi="stochastic", jacobi_probes=3, jacobi_samples=5, degeneracy_at="midpoints")
    assert t["JacobiPenalty"] == mx.JacobiPenalty(mx.StochasticJacobi(probes=3), samples=5)
    assert t["PoissonDegeneracy"].at_midpoints is True
    assert t["FrictionDegeneracy"].at_midpoints is True
    t = terms(jacobi="exact")
    assert t["JacobiPenalty"] == mx.JacobiPenalty(mx.ExactJacobi())
    # auto, the default: the exact penalty for a Lie-Poisson L (its Jacobi residual linear in
    # the state, cheap), none for a network's L or a given one.
    assert terms(poisson="lie-poisson")["JacobiPenalty"] == mx.JacobiPenalty(mx.ExactJacobi())
    assert "JacobiPenalty" not in terms() and "JacobiPenalty" not in terms(poisson="zero")
    assert "JacobiPenalty" not in terms(poisson="lie-poisson", jacobi="none")
    assert t["PoissonDegeneracy"].at_midpoints is False
    assert t["FrictionDegeneracy"].at_midpoints is False
    with pytest.raises(mx.MetriplexError, match=r"--jacobi must be one of auto, none, exact, "
                                                r"stochastic; got 'approximate'\."):
        terms(jacobi="approximate")
    with pytest.raises(mx.MetriplexError, match=r"--degeneracy-at must be one of states, "
                                                r"midpoints; got 'edges'\."):
        terms(degeneracy_at="edges")


def test_degeneracy_penalty_detects_violation():
    k = jr.split(jr.key(0), 4)
    model = mx.GenericModel(mx.MLPPotential(3, width=8, key=k[0]),
                            mx.MLPPotential(3, width=8, key=k[1]),
                            mx.SkewMLPPoisson(3, width=8, key=k[2]),
                            mx.CholeskyFriction(3, width=8, key=k[3]))
    data = make_data(damped_oscillator(), oscillator_x0(2), 0.1, 10)
    _, parts = _compiled(mx.DegeneracyPenalty())(model, _batch(data))
    assert float(parts["degeneracy_L"]) > 1e-8 and float(parts["degeneracy_M"]) > 1e-10


def test_stochastic_jacobi_is_unbiased():
    model = mx.GenericModel(mx.ZeroPotential(), mx.ZeroPotential(),
                            mx.SkewMLPPoisson(5, width=16, key=jr.key(2)), mx.ZeroFriction(5))
    x = jr.normal(jr.key(1), (4, 5))
    b = Batch(x, x, jnp.ones(4), jnp.ones(5))
    exact = float(eqx.filter_jit(lambda m, b: mx.JacobiPenalty()(m, b, None, jr.key(0)))(
        model, b))
    est = mx.JacobiPenalty(mx.StochasticJacobi(probes=8))
    draws = np.asarray(jax.jit(jax.vmap(lambda k: est(model, b, None, k)))(jr.split(jr.key(3), 200)))
    se = draws.std(ddof=1) / np.sqrt(len(draws))
    assert abs(draws.mean() - exact) < 4 * se, (draws.mean(), exact, se)
    assert exact > 0


def test_loss_is_differentiable_and_jittable():
    import equinox as eqx

    model = mx.GenericModel(mx.MLPPotential(3, width=8, key=jr.key(0)), mx.ZeroPotential(),
                            mx.SkewMLPPoisson(3, width=8, key=jr.key(1)), mx.ZeroFriction(3))
    data = make_data(rigid_body(), rigid_x0(2), 0.1, 10)
    loss = mx.CrankNicolsonResidual() + mx.JacobiPenalty(mx.StochasticJacobi(probes=2))

    @eqx.filter_jit
    def f(m, b, k):
        return eqx.filter_value_and_grad(lambda mm: loss(mm, b, key=k)[0])(m)

    v, g = f(model, _batch(data), jr.key(0))
    assert np.isfinite(float(v))
    assert all(np.all(np.isfinite(np.asarray(a))) for a in jax.tree_util.tree_leaves(g))


def _random_generic(n, exact: bool, seed: int):
    k = jr.split(jr.key(seed), 4)
    L = (mx.ProjectedSkewMLPPoisson if exact else mx.SkewMLPPoisson)(n, width=8, key=k[2])
    M = (mx.ProjectedCholeskyFriction if exact else mx.CholeskyFriction)(n, width=8, key=k[3])
    return mx.GenericModel(mx.MLPPotential(n, width=8, key=k[0]),
                           mx.MLPPotential(n, width=8, key=k[1]), L, M)


@pytest.mark.parametrize("exact", [False, True], ids=["soft-blocks", "projected-blocks"])
def test_midpoint_penalties_and_shared_midpoint_terms(exact):
    n, B = 4, 16
    model = _random_generic(n, exact, seed=5)
    x0 = jr.normal(jr.key(6), (B, n))
    x1 = x0 + 0.1 * jr.normal(jr.key(7), (B, n))
    batch = Batch(x0, x1, jnp.full((B,), 0.1), jnp.asarray([1.0, 2.0, 0.5, 1.5]))
    dg = mx.DiscreteGradient()

    @eqx.filter_jit  # one program, not the many small ones of op-by-op evaluation
    def values(model, batch):
        x0, x1 = batch.x0, batch.x1
        t = jax.vmap(model.terms)(0.5 * (x0 + x1))
        _, at_midpoints = mx.FrictionDegeneracy(at_midpoints=True).as_loss()(model, batch)
        _, at_states = mx.FrictionDegeneracy().as_loss()(model, batch)
        t0, t1 = jax.vmap(model.terms)(x0), jax.vmap(model.terms)(x1)
        own = jax.vmap(dg.residual, in_axes=(None, 0, 0, 0, 0, 0))(model, x0, x1, batch.dt, t0, t1)
        shared = jax.vmap(dg.residual, in_axes=(None, 0, 0, 0, 0, 0, 0))(
            model, x0, x1, batch.dt, t0, t1, t)
        return t, at_midpoints["degeneracy_M"], at_states["degeneracy_M"], own, shared

    t, at_midpoints, at_states, own, shared = values(model, batch)
    # The midpoint penalty is the defect at (x0 + x1)/2, once per pair.
    want = np.mean(np.sum((np.einsum("bij,bj->bi", t.friction, t.grad_energy)
                           / np.asarray(batch.scale)) ** 2, axis=-1))
    # (Projected blocks are degenerate by construction: both sides are rounding, ~1e-39.)
    np.testing.assert_allclose(float(at_midpoints), want, rtol=1e-12, atol=1e-30)
    if not exact:
        assert abs(float(at_states) - want) > 1e-6 * want  # at the states: different
    # The discrete-gradient residual gives the same value whether it takes the midpoint terms
    # from the shared context (and reuses L, M of blocks that ignore the gradient) or not.
    np.testing.assert_allclose(np.asarray(shared), np.asarray(own), rtol=1e-12, atol=1e-14)
    with pytest.raises(mx.MetriplexError, match=r"PoissonDegeneracy's at_midpoints must be True "
                       r"\(.*midpoints.*\) or False \(.*states.*\); got 'midpoints'\. Write "
                       r"at_midpoints=True"):
        mx.PoissonDegeneracy("midpoints")


def test_negative_temperature_hinge_sees_only_cold_states_and_no_unit():
    # E = c (p^2 + (s - 1)^2) / 2 on states with s on both sides of 1: the temperature
    # dE/ds = c (s - 1) is negative below s = 1 only. The term is zero where every temperature
    # is positive, the same for any scale c of E, and refused without entropy indices.
    def model(c):
        energy = mx.Known(lambda x: 0.5 * c * (x[1] ** 2 + (x[2] - 1.0) ** 2))
        return mx.GenericModel(energy, mx.SumOf((2,)), mx.CanonicalPoisson(3, 1),
                               mx.ZeroFriction(3))

    x = jnp.stack([jnp.zeros(8), jnp.linspace(-1.0, 1.0, 8), jnp.linspace(0.5, 1.5, 8)], -1)
    warm = x.at[:, 2].add(1.0)
    term = mx.NegativeTemperature((2,)).as_loss()
    value = lambda m, states: float(_compiled(term)(m, Batch(states, states, jnp.ones(8),  # noqa: E731
                                                             jnp.ones(3)))[0])
    cold = value(model(1.0), x)
    assert cold > 1e-3
    assert value(model(1.0), warm) == 0.0
    assert value(model(1e3), x) == pytest.approx(cold, rel=1e-12)
    with pytest.raises(mx.MetriplexError, match="indices of the entropy variables"):
        mx.NegativeTemperature(())


def test_negative_temperature_hinge_has_a_finite_derivative_in_float32_at_any_scale_of_e():
    # A new-user check (time in ms, a variable of 1e-3) learned an energy of 5e-8 in the data's
    # units: the square of |D grad E|^2 in the hinge's derivative fell to 0 in float32, and
    # training went non-finite at its first evaluation. The term is E's scale-free ratio, so
    # its value and derivative must be those of E at scale 1.
    from metriplex._model import with_dtype

    x = jr.normal(jr.key(0), (16, 3), dtype=jnp.float32)
    term = mx.NegativeTemperature((2,)).as_loss()
    batch = Batch(x, x, jnp.ones(16, jnp.float32), jnp.ones(3, jnp.float32))

    def value_and_grad(scale):
        energy = mx.MLPPotential(3, width=8, output_scale=scale, key=jr.key(1))
        model = with_dtype(mx.GenericModel(energy, mx.SumOf((2,)), mx.CanonicalPoisson(3, 1),
                                           mx.ZeroFriction(3)), jnp.float32)
        return eqx.filter_jit(eqx.filter_value_and_grad(lambda m: term(m, batch)[0]))(model)

    (v1, g1), (v2, g2) = value_and_grad(1.0), value_and_grad(1e-12)
    assert v1.dtype == jnp.float32 and float(v1) > 0.0
    np.testing.assert_allclose(float(v2), float(v1), rtol=1e-5)
    for a, b in zip(jax.tree.leaves(g1), jax.tree.leaves(g2)):
        assert np.all(np.isfinite(b))
        np.testing.assert_allclose(np.asarray(b), np.asarray(a), rtol=1e-3, atol=1e-6)
