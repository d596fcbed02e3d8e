"""RolloutWindow: the windows the training batches carry, the term's value and gradient, and
the option that turns it on."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import metriplex as mx
from metriplex._errors import MetriplexError
from metriplex._pairs import PairRows, PairStore
from metriplex.config import RunConfig, validate
from metriplex.data import Pairs
from metriplex.losses import Context
from helpers import damped_oscillator, make_data, oscillator_data, oscillator_x0


def _rows(data) -> PairRows:
    return PairRows.of(data, data.x.shape[1], "training")


def test_windows_follow_their_trajectory_and_stop_at_its_end():
    data = oscillator_data(k=3, n_t=7)  # 3 x 7 states, 18 pairs
    rows = _rows(data)
    store = PairStore.of(rows, np.ones(3), jnp.float64)
    idx = jnp.array([0, 4, 12, 17])
    batch = store.take(idx, (3, 4))
    x0, targets, dt, mask = batch.window
    xs = data.x.reshape(3, 7, 3)
    np.testing.assert_array_equal(x0, np.stack([xs[0, 0], xs[0, 4], xs[2, 0]]))
    # Pair 0 has 4 steps ahead in its trajectory; pair 4 two (its states 5, 6); pair 12 four.
    np.testing.assert_array_equal(mask, [[1, 1, 1, 1], [1, 1, 0, 0], [1, 1, 1, 1]])
    np.testing.assert_array_equal(targets[0], xs[0, 1:5])
    np.testing.assert_array_equal(targets[1, :2], xs[0, 5:7])
    np.testing.assert_array_equal(targets[2], xs[2, 1:5])
    np.testing.assert_allclose(dt[mask], 0.1)
    # The evaluation subsets gather the same windows on the host.
    host = rows.batch(np.asarray(idx), np.ones(3), jnp.float64, (3, 4)).window
    for a, b in zip(host, batch.window):
        np.testing.assert_array_equal(a, b)
    # Without a window shape, no windows.
    assert store.take(idx).window is None


def test_ready_pairs_give_windows_of_one_step():
    rng = np.random.default_rng(0)
    x0, x1 = rng.normal(size=(5, 2)), rng.normal(size=(5, 2))
    rows = PairRows.of(Pairs(x0, x1, np.full(5, 0.1)), 2, "training")
    window = PairStore.of(rows, np.ones(2), jnp.float64).take(jnp.arange(5), (5, 3)).window
    np.testing.assert_array_equal(window.mask, np.tile([True, False, False], (5, 1)))
    np.testing.assert_array_equal(window.targets[:, 0], x1)


@pytest.mark.slow
def test_the_true_model_rolls_out_its_own_data_exactly_and_other_data_not():
    true = damped_oscillator(0.3)
    data = make_data(true, oscillator_x0(4), 0.1, 20)
    term = mx.RolloutWindow(mx.CrankNicolson(), steps=10, windows=8)
    store = PairStore.of(_rows(data), np.ones(3), jnp.float64)
    batch = store.take(jnp.arange(0, store.count, 3), term.window_shape)
    value = eqx.filter_jit(lambda b: term(true, b, Context(None, None), jax.random.key(0)))
    assert float(value(batch)) < 1e-18
    shifted = batch.window._replace(targets=batch.window.targets.at[:, 3:, 1].add(1e-3))
    assert float(value(batch._replace(window=shifted))) > 1e-6


@pytest.mark.slow
def test_fit_trains_with_windows_and_validation_judges_the_pair_loss():
    data = make_data(damped_oscillator(0.3), oscillator_x0(8), 0.1, 20)
    model = mx.GenericModel(
        mx.MLPPotential(3, width=8, depth=1, key=jax.random.key(1)),
        mx.SumOf((2,)), mx.CanonicalPoisson(3, 1), mx.CholeskyFriction(3, width=8, depth=1,
                                                                      key=jax.random.key(2)))
    loss = mx.CrankNicolsonResidual() + mx.RolloutWindow(steps=5, windows=4)
    _, history = mx.fit(model, data, loss=loss, steps=60, eval_every=20, stopping=None,
                        rollout_check=None, progress=False, key=jax.random.key(3))
    window = history.train["window"]
    assert len(window) == len(history.step) == 4
    # Trained through the solved steps, the rollouts get closer to the data.
    assert np.all(np.isfinite(window)) and window[-1] < 0.5 * window[0]
    assert "window" not in history.valid and "residual" in history.valid


@pytest.mark.parametrize("bad", [0, -1, 2.5, True])
def test_a_window_needs_a_positive_whole_number_of_steps(bad):
    with pytest.raises(MetriplexError, match="RolloutWindow's steps must be an integer >= 1"):
        mx.RolloutWindow(steps=bad)


def test_the_window_option_is_checked_and_builds_the_term():
    from metriplex.app._build import build_loss

    with pytest.raises(MetriplexError, match=r"--window-steps must be an integer >= 0.*got -2"):
        validate(RunConfig(window_steps=-2), 3)
    config = RunConfig(entropy="sum:2", poisson="canonical:1", window_steps=12)
    validate(config, 3)
    terms = build_loss(config).terms
    windows = [t for t in terms if isinstance(t, mx.RolloutWindow)]
    assert len(windows) == 1 and windows[0].steps == 12
    assert not any(isinstance(t, mx.RolloutWindow)
                   for t in build_loss(RunConfig(window_steps=0)).terms)
