"""Training does not depend on the units: time in ms instead of s, or a variable offset by 1e3."""

import dataclasses

import jax.random as jr
import numpy as np
import pytest

import metriplex as mx
from metriplex.app._build import build_loss, build_model, units_for
from metriplex.config import RunConfig
from metriplex.data import time_scale
from helpers import damped_oscillator, make_data, oscillator_x0


def _data():
    return make_data(damped_oscillator(), oscillator_x0(8), 0.1, 30, names=("q", "p", "s"))


def _transformed(data, time_factor=1.0, offset=(0.0, 0.0, 0.0)):
    return mx.Trajectories(data.trajectory, data.t * time_factor,
                           data.x + np.asarray(offset)[None, :], data.names)


def test_time_scale_follows_the_unit_of_time_and_ignores_offsets():
    data = _data()
    tau = time_scale(data.pairs())
    assert tau > 0
    assert time_scale(_transformed(data, 1e3).pairs()) == pytest.approx(1e3 * tau, rel=1e-12)
    assert time_scale(_transformed(data, 1.0, (1e3, -5.0, 1e4)).pairs()) == pytest.approx(
        tau, rel=1e-6)


def test_units_put_the_learned_energy_on_the_scale_of_the_given_bracket():
    data = _data()
    config = RunConfig(entropy="sum:2", poisson="canonical:1", friction="neural")
    u = units_for(config, data)
    # Canonical L: the learned E must give dq/dt ~ d_q / tau from dE/dp, so sigma_E ~ d_q d_p / tau.
    d = np.asarray(u.scale)
    assert u.energy == pytest.approx(d[0] * d[1] / u.time, rel=1e-12)
    assert u.entropy == pytest.approx(d[2], rel=1e-12)  # S = s: grad S = 1, in units of s
    slow = units_for(config, _transformed(data, 1e3))
    assert slow.time == pytest.approx(1e3 * u.time, rel=1e-12)
    assert slow.energy == pytest.approx(u.energy / 1e3, rel=1e-12)


# One training stage from the model as built: the reversible-first stage (a default with S
# given), its hinge and the exact M grad E = 0 that goes with it are left out here, so that
# 300 steps of one fit show both the units' invariance and that it learns.
CONFIG = RunConfig(entropy="sum:2", poisson="canonical:1", friction="neural", width=16,
                   float64=True, reversible_first=False, w_temperature=0.0)


def _fit(d, time_factor):
    """The history and the learned vector field (in the units of ``_data()``) of a short fit."""
    units = units_for(CONFIG, d)
    model = build_model(CONFIG, d, key=jr.key(0), units=units)
    # lr 3e-3: at 1e-2 rounding differences (1e-16) grow to 1e-3 within 300 steps.
    model, history = mx.fit(model, d, loss=build_loss(CONFIG, units, d), steps=300,
                            learning_rate=3e-3, eval_every=100, scale=units.rate, progress=False,
                            rollout_check=None, key=jr.key(1))
    # The vector field in the data's own units, mapped back to the first data's units.
    f = np.stack([np.asarray(model.vector_field(x)) for x in d.x[:20]])
    return history, f * time_factor


@pytest.fixture(scope="module")
def fit_in_the_first_units():
    """The fit on the data as generated, which both other units are compared with."""
    return _fit(_data(), 1.0)


@pytest.mark.parametrize("time_factor, offset", [(1e3, (0.0, 0.0, 0.0)), (1.0, (1e3, 0.0, -1e3))])
def test_training_is_the_same_in_other_units(fit_in_the_first_units, time_factor, offset):
    a, f0 = fit_in_the_first_units
    b, f1 = _fit(_transformed(_data(), time_factor, offset), time_factor)
    # It learns: the validation loss falls 20x within 300 steps (measured: 270x). This is the
    # default run's check that a short fit learns; test_train's full-size accuracy test is slow.
    assert a.valid["total"][-1] < a.valid["total"][0] / 20
    np.testing.assert_allclose(a.valid["total"], b.valid["total"], rtol=1e-5)
    np.testing.assert_allclose(f0, f1, rtol=1e-4, atol=1e-6 * np.abs(f0).max())


def test_times_far_from_zero_roll_a_float32_model_out_as_times_from_zero():
    # A clock's times (t = 1e6 s, or 1.7e9 for Unix time) cast to float32 lose the steps (at
    # 1e6 to multiples of 1/16): rollouts are taken on the steps, shifted in float64 first.
    import jax.numpy as jnp

    from metriplex._model import with_dtype
    from metriplex.diagnostics import evaluate

    data = _data()
    small = mx.GenericModel(mx.MLPPotential(3, data=data.x, width=4, depth=1, key=jr.key(0)),
                            mx.SumOf((2,)), mx.CanonicalPoisson(3, 1), mx.ZeroFriction(3))
    model = with_dtype(small, jnp.float32)
    t, x = next(iter(data))
    x0 = jnp.asarray(x[0], jnp.float32)
    near = mx.solve(model, x0, t)
    for offset in (1e6, 1.7e9):
        far = mx.solve(model, x0, t + offset)
        # the steps (t + offset) - (t0 + offset) differ from t - t0 by float64 rounding only
        np.testing.assert_allclose(np.asarray(far.xs), np.asarray(near.xs), rtol=1e-5,
                                   atol=1e-6)
        np.testing.assert_array_equal(np.asarray(far.ts), np.asarray(jnp.asarray(t + offset,
                                                                               jnp.float32)))
    base = evaluate(model, data)
    shifted = evaluate(model, _transformed_time(data, 1e6))
    assert shifted["rollout_error_mean"] == pytest.approx(base["rollout_error_mean"], rel=1e-4)
    assert shifted["step_sensitivity"] == pytest.approx(base["step_sensitivity"], rel=1e-3)
    assert shifted["rollout_error_standardised_mean"] == pytest.approx(
        base["rollout_error_standardised_mean"], rel=1e-4)
    assert base["rollout_error_standardised_mean"] > 0
    check = mx.RolloutCheck(steps=20, trajectories=2)
    ts_near, _, _ = check.prepare(data, jnp.float32)
    ts_far, _, _ = check.prepare(_transformed_time(data, 1e6), jnp.float32)
    np.testing.assert_array_equal(np.asarray(ts_far), np.asarray(ts_near))


def _transformed_time(data, offset):
    return mx.Trajectories(data.trajectory, data.t + offset, data.x, data.names)


def test_the_standardised_rollout_error_does_not_change_with_an_offset():
    # |pred - obs| / |obs| shrinks when a variable is offset (here q by 1e4): the report gives
    # the error in standard deviations about the data's mean beside it, which does not.
    from metriplex._standardised import standardised_errors

    data = _data()
    ts, obs, lengths = data.padded()
    pred = obs + 0.01 * np.sin(np.arange(obs.shape[1]))[None, :, None]
    offset = np.asarray([1e4, 0.0, 0.0])
    near = standardised_errors(pred, obs, lengths, data.x)
    far = standardised_errors(pred + offset, obs + offset, lengths, data.x + offset)
    np.testing.assert_allclose(far, near, rtol=1e-9)
    plain = [np.linalg.norm(pred[k, :T] - obs[k, :T]) / np.linalg.norm(obs[k, :T])
             for k, T in enumerate(lengths)]
    plain_far = [np.linalg.norm(pred[k, :T] - obs[k, :T]) / np.linalg.norm(obs[k, :T] + offset)
                 for k, T in enumerate(lengths)]
    assert max(plain_far) < 1e-3 * min(plain)


def test_data_whose_time_is_in_another_unit_than_the_training_data_are_warned_about():
    from metriplex.app._warnings import time_unit_warning

    data = _data()
    units = {"time": time_scale(data.pairs())}
    assert time_unit_warning(units, data) == []
    assert time_unit_warning(units, _transformed(data, 3.0)) == []
    (line,) = time_unit_warning(units, _transformed(data, 1e3))
    assert "time scale 1e+03 times the training data's" in line and "same unit" in line
    (line,) = time_unit_warning(units, _transformed(data, 1e-3))
    assert "time scale 0.001 times" in line
    assert time_unit_warning({}, data) == []  # an older run without units
