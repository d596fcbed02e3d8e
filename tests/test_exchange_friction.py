"""ExchangeFriction (``--friction exchange``): symmetric, PSD and M grad E = 0 by construction,
off-diagonal entries that only exchange between pairs of variables, finite where grad E = 0, the
model-file round trip, and the command-line spelling."""

from dataclasses import replace

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np
import pytest

import metriplex as mx
from metriplex.app.config import RunConfig, validate
from metriplex.app.runs import train_run
from metriplex.app._thermal import confine_on, exact_blocks, reversible_first_on
from metriplex.structure import ExchangeFriction, Scaling
from metriplex.structure._registry import REGISTRY
from metriplex.systems import generate

N = 5
SCALING = Scaling((0.3, -1.0, 5.0, 0.0, 2.0), (0.5, 2.0, 10.0, 0.1, 1.0))


@eqx.filter_jit
def _call(M, xs, gs):
    return jax.vmap(M)(xs, gs)


def _states(count, seed):
    z = jr.normal(jr.key(seed), (count, N))
    return jnp.asarray(SCALING.shift)[None, :] + jnp.asarray(SCALING.scale)[None, :] * z


@pytest.mark.parametrize("scaling", [None, SCALING], ids=["identity", "scaled"])
def test_exchange_friction_is_symmetric_psd_and_degenerate(scaling):
    M = ExchangeFriction(N, width=16, scaling=scaling, key=jr.key(0))
    xs, gs = _states(200, 1), jr.normal(jr.key(2), (200, N))
    F = _call(M, xs, gs)
    assert bool(jnp.all(jnp.isfinite(F)))
    assert float(jnp.min(jnp.max(jnp.abs(F), axis=(1, 2)))) > 1e-8  # not trivially zero
    top = float(jnp.max(jnp.abs(F)))
    assert float(jnp.max(jnp.abs(F - jnp.swapaxes(F, 1, 2)))) <= 1e-15 * top
    assert float(jnp.max(jnp.abs(jnp.einsum("bij,bj->bi", F, gs)))) < 1e-13 * top
    eig = jnp.linalg.eigvalsh(F)
    assert float(jnp.min(eig)) > -1e-13 * float(jnp.max(eig))
    # Pairwise exchange: each off-diagonal term moves E between two variables only, so
    # M_ij dE/dx_i dE/dx_j <= 0 for i != j (a general M grad E = 0 friction need not).
    cross = F * gs[:, :, None] * gs[:, None, :]
    off = jnp.where(jnp.eye(N, dtype=bool)[None], 0.0, cross)
    assert float(jnp.max(off)) <= 1e-15 * top


def test_exchange_friction_matches_its_formula():
    M = ExchangeFriction(N, width=16, scaling=SCALING, eps=1e-3, key=jr.key(3))
    x, g = _states(1, 4)[0], jr.normal(jr.key(5), (N,))
    W = M.rates(x)
    assert bool(jnp.all(W >= 0)) and bool(jnp.all(jnp.diag(W) == 0))
    np.testing.assert_array_equal(W, W.T)
    d = jnp.asarray(SCALING.scale)
    h = d * g
    s = jnp.sum(h * h) + 1e-6
    expected = jnp.zeros((N, N))
    for i in range(N):
        for j in range(i + 1, N):
            z = jnp.zeros(N).at[i].set(h[j]).at[j].set(-h[i])
            expected = expected + W[i, j] * jnp.outer(z, z) / s
    expected = SCALING.factor * d[:, None] * expected * d[None, :]
    np.testing.assert_allclose(M(x, g), expected, rtol=1e-12, atol=1e-15)


def test_no_nan_where_the_energy_gradient_vanishes():
    M = ExchangeFriction(N, width=16, scaling=SCALING, key=jr.key(6))
    x = _states(1, 7)[0]
    for r in (0.0, 1e-300, 1e-17, 1e-9):
        assert bool(jnp.all(jnp.isfinite(M(x, r * jnp.ones(N)))))
    assert bool(jnp.all(M(x, jnp.zeros(N)) == 0))
    grads = eqx.filter_grad(lambda m: jnp.sum(m(x, jnp.zeros(N)) ** 2 + m(x, jnp.ones(N))))(M)
    leaves = jax.tree_util.tree_leaves(eqx.filter(grads, eqx.is_inexact_array))
    assert leaves and all(bool(jnp.all(jnp.isfinite(v))) for v in leaves)


def test_exchange_friction_rejects_one_variable_and_a_bad_eps():
    with pytest.raises(mx.MetriplexError, match="2"):
        ExchangeFriction(1, key=jr.key(0))
    with pytest.raises(mx.MetriplexError, match="eps"):
        ExchangeFriction(3, eps=-1.0, key=jr.key(0))


def test_exchange_friction_round_trips_a_model_file(tmp_path):
    assert REGISTRY["friction"]["exchange"] is ExchangeFriction
    k = jr.split(jr.key(8), 3)
    model = mx.GenericModel(
        energy=mx.MLPPotential(N, width=16, key=k[0]),
        entropy=mx.SumOf((3, 4)),
        poisson=mx.CanonicalPoisson(N, 1),
        friction=ExchangeFriction(N, width=16, depth=1, activation="tanh", scaling=SCALING,
                                  eps=1e-7, key=k[2]),
    )
    path = tmp_path / "exchange.mpx"
    mx.save(path, model, n=N)
    back = mx.load(path)
    assert back.spec() == model.spec()
    assert type(back.friction) is ExchangeFriction
    xs = _states(16, 9)
    np.testing.assert_array_equal(np.asarray(jax.vmap(back.vector_field)(xs)),
                                  np.asarray(jax.vmap(model.vector_field)(xs)))


def test_training_with_the_command_line_spelling(tmp_path):
    data = generate("oscillator-bath", trajectories=6, steps=40, seed=0)
    config = RunConfig(poisson="canonical:1", entropy="sum:2", friction="exchange", steps=200,
                       eval_every=50, average_steps=0, validation=0.0,
                       reversible_first=False)
    model, history, _, _, _ = train_run(data, config, tmp_path / "run", progress=False)
    assert type(model.friction) is ExchangeFriction
    assert "degeneracy_M" not in history.train  # exact: no penalty to weigh
    t = eqx.filter_jit(eqx.filter_vmap(model.terms))(jnp.asarray(data.x[:50], jnp.float32))
    M, gE = t.friction, t.grad_energy
    scale = float(jnp.max(jnp.abs(M))) * float(jnp.max(jnp.abs(gE)))
    assert float(jnp.max(jnp.abs(jnp.einsum("bij,bj->bi", M, gE)))) < 1e-5 * scale
    with pytest.raises(mx.MetriplexError, match="--friction exchange .* Leave friction out"):
        validate(replace(config, features="pendulum", features_for="energy,friction"), 10)


def test_the_command_line_spelling_builds_an_exactly_degenerate_friction():
    # The exchange friction is exactly degenerate whatever --degeneracy says; it takes part in
    # the stages and the wall that a learned friction gets.
    cfg = RunConfig(poisson="canonical:1", entropy="sum:2", friction="exchange")
    assert exact_blocks(cfg) == (False, True)
    assert reversible_first_on(cfg) and confine_on(cfg)
    assert exact_blocks(replace(cfg, degeneracy="soft")) == (False, True)
    assert exact_blocks(replace(cfg, poisson="neural")) == (True, True)
