"""The residual's metric (``Units.residual_metric``, ``--residual-metric``): weight on the
combinations of variables that the data keep nearly still, nothing else."""

import dataclasses

import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np
import pytest

import metriplex as mx
from metriplex._errors import MetriplexError
from metriplex._units import METRIC_CAP
from metriplex.app._build import build_loss, units_for
from metriplex.config import RunConfig, validate
from metriplex.losses import Batch, Context, SchemeResidual
from helpers import damped_oscillator, make_data, oscillator_x0


def _trajectories(x: np.ndarray, dt: float = 0.1) -> mx.Trajectories:
    """One trajectory of the rows ``x``, a step ``dt`` apart."""
    t = dt * np.arange(len(x))
    return mx.Trajectories(np.zeros(len(x), np.int64), t, np.asarray(x, np.float64))


def _metric(data: mx.Trajectories) -> np.ndarray:
    return units_for(RunConfig(), data).residual_metric(data)


def test_uncorrelated_rates_give_the_plain_residual():
    # Steps (1, 0), (0, 1), (-1, 0), (0, -1), ...: each variable moves, never together.
    steps = np.tile([[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [0.0, -1.0]], (5, 1))
    x = np.vstack([np.zeros((1, 2)), np.cumsum(steps, axis=0)])
    np.testing.assert_allclose(_metric(_trajectories(x)), np.eye(2), atol=1e-12)


def test_a_combination_the_data_keep_still_gets_the_cap():
    # x1 + x2 never moves (heat passed from one cell to the other): its residual weighs
    # METRIC_CAP times the plain one; the difference x1 - x2, which moves, keeps weight 1.
    rng = np.random.default_rng(0)
    x1 = np.cumsum(rng.normal(size=40))
    x = np.stack([x1, 3.0 - x1], axis=1)
    w = _metric(_trajectories(x))
    both = np.array([1.0, 1.0]) / np.sqrt(2.0)
    apart = np.array([1.0, -1.0]) / np.sqrt(2.0)
    assert both @ w @ both == pytest.approx(METRIC_CAP, rel=1e-9)
    assert apart @ w @ apart == pytest.approx(1.0, rel=1e-9)


def test_a_variable_alone_keeps_weight_one_however_slowly_it_moves_and_a_still_one_is_left_out():
    rng = np.random.default_rng(1)
    fast = np.cumsum(rng.normal(size=60))
    slow = 1e-4 * np.cumsum(rng.normal(size=60))  # moves, slowly, on its own
    still = np.full(60, 7.0)
    w = _metric(_trajectories(np.stack([fast, slow, still], axis=1)))
    assert 1.0 <= w[1, 1] < 1.5  # the slow variable: neither dropped nor weighed up
    assert w[2, 2] == 1.0 and not np.any(w[2, :2]) and not np.any(w[:2, 2])
    # The two moving variables are independent draws: weights near 1, no large one.
    assert np.linalg.eigvalsh(w).max() < 1.5


def test_the_metric_does_not_depend_on_units_or_offsets():
    data = make_data(damped_oscillator(), oscillator_x0(8), 0.1, 30, names=("q", "p", "s"))
    other = mx.Trajectories(data.trajectory, 1e3 * data.t,
                            data.x * np.array([1e-3, 1.0, 1e4]) + np.array([1e3, 0.0, -5.0]),
                            data.names)
    np.testing.assert_allclose(_metric(data), _metric(other), rtol=1e-6, atol=1e-9)


def test_the_residual_is_measured_in_the_metric():
    scheme = mx.CrankNicolson()
    plain, identity = SchemeResidual(scheme), SchemeResidual(scheme, metric=np.eye(2))
    w = np.array([[2.0, 0.5], [0.5, 1.0]])
    weighted = SchemeResidual(scheme, metric=w)
    model = mx.GenericModel(energy=mx.MLPPotential(2, width=4, depth=1, key=jr.key(0)),
                            entropy=mx.ZeroPotential(), poisson=mx.CanonicalPoisson(2, 1),
                            friction=mx.ZeroFriction(2))
    x0 = jr.normal(jr.key(1), (5, 2))
    x1 = x0 + 0.1 * jr.normal(jr.key(2), (5, 2))
    dt = jnp.full((5,), 0.1)
    scale = jnp.array([0.5, 2.0])
    batch = Batch(x0, x1, dt, scale)
    terms = jax.vmap(model.terms)
    ctx = Context(terms(x0), terms(x1))
    key = jr.key(3)
    r = jax.vmap(scheme.residual, in_axes=(None, 0, 0, 0, 0, 0))(
        model, x0, x1, dt, ctx.terms0, ctx.terms1) / scale[None, :]
    assert float(identity(model, batch, ctx, key)) == pytest.approx(
        float(plain(model, batch, ctx, key)), rel=1e-12)
    expected = np.mean(np.einsum("bi,ij,bj->b", r, w, r))
    assert float(weighted(model, batch, ctx, key)) == pytest.approx(expected, rel=1e-10)


@pytest.mark.parametrize("bad", [np.array([[1.0, 2.0], [0.0, 1.0]]), np.eye(3)[:2],
                                 np.array([[1.0, 0.0], [0.0, -1.0]])])
def test_a_bad_metric_is_refused_with_the_rule(bad):
    with pytest.raises(MetriplexError, match="symmetric, positive definite"):
        SchemeResidual(mx.CrankNicolson(), metric=bad)


def test_the_command_line_choice_reaches_the_loss_and_a_bad_one_is_refused():
    data = make_data(damped_oscillator(), oscillator_x0(4), 0.1, 10, names=("q", "p", "s"))
    config = RunConfig(entropy="sum:2", poisson="canonical:1")
    units = units_for(config, data)

    def metric(**changes):
        return build_loss(dataclasses.replace(config, **changes), units, data).terms[0].metric

    # auto, the default: the metric where the model has a friction, the plain residual where not
    assert config.residual_metric == "auto"
    np.testing.assert_allclose(metric(), units.residual_metric(data))
    assert metric(friction="zero") is None
    np.testing.assert_allclose(metric(friction="zero", residual_metric="correlated"),
                               units.residual_metric(data))
    assert metric(residual_metric="diagonal") is None
    with pytest.raises(MetriplexError, match="--residual-metric"):
        validate(dataclasses.replace(config, residual_metric="whitened"), 3)
