"""The Python API refuses wrong arguments with a MetriplexError naming the rule, instead of a
raw TypeError or AttributeError deep in JAX, and never writes a file it would refuse to read
(found by a new-user check of the API)."""

import jax.numpy as jnp
import jax.random as jr
import numpy as np
import pytest

import metriplex as mx
from helpers import damped_oscillator, make_data, oscillator_x0


@pytest.fixture(scope="module")
def setup():
    data = make_data(damped_oscillator(), oscillator_x0(3), 0.1, 8, names=("q", "p", "s"))
    model = mx.GenericModel(mx.MLPPotential(3, width=4, depth=1, key=jr.key(0)), mx.SumOf((2,)),
                            mx.CanonicalPoisson(3, 1), mx.ZeroFriction(3))
    return data, model


def test_save_refuses_what_load_would_refuse(setup, tmp_path):
    _, model = setup
    with pytest.raises(mx.MetriplexError, match="the model has 3 state variables; pass n=3"):
        mx.save(tmp_path / "m.mpx", model, n=4)
    with pytest.raises(mx.MetriplexError, match="names must be empty or 3 strings"):
        mx.save(tmp_path / "m.mpx", model, n=3, names=["a", "b"])
    with pytest.raises(mx.MetriplexError, match="names must be empty or 3 strings"):
        mx.save(tmp_path / "m.mpx", model, n=3, names=[1, 2, 3])
    with pytest.raises(mx.MetriplexError, match="it is a folder"):
        mx.save(tmp_path, model, n=3)
    with pytest.raises(mx.MetriplexError, match="not strict JSON"):
        mx.save(tmp_path / "m.mpx", model, n=3, extra={"a": float("nan")})
    with pytest.raises(mx.MetriplexError, match="save writes a GenericModel"):
        mx.save(tmp_path / "m.mpx", {"a": 1}, n=3)
    assert list(tmp_path.iterdir()) == []
    mx.save(tmp_path / "m.mpx", model, n=3, names=("q", "p", "s"))
    assert mx.load(tmp_path / "m.mpx").size() == 3


def test_solve_and_evaluate_name_a_wrong_argument(setup):
    data, model = setup
    t, x = next(iter(data))
    with pytest.raises(mx.MetriplexError, match="scheme must be a scheme object"):
        mx.simulate(model, x[0], t, scheme="rk4")
    with pytest.raises(mx.MetriplexError, match="take a model"):
        mx.simulate("model.mpx", x[0], t)
    with pytest.raises(mx.MetriplexError, match="evaluate takes Trajectories"):
        mx.evaluate(model, "data.npz")
    with pytest.raises(mx.MetriplexError, match="evaluate takes a model"):
        mx.evaluate("model.mpx", data)
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(mx.MetriplexError, match="horizon must be a time > 0"):
            mx.evaluate(model, data, horizon=bad)
    with pytest.raises(mx.MetriplexError, match="validation must be a fraction"):
        mx.fit(model, data, validation="0.2", steps=1, progress=False, key=jr.key(0))


def test_integer_states_and_states_narrower_than_the_model_roll_out(setup):
    data, model = setup
    t, x = next(iter(data))
    ints = mx.simulate(model, [1, 0, 0], t)  # integers: in the model's float dtype
    floats = mx.simulate(model, np.asarray([1.0, 0.0, 0.0]), t)
    np.testing.assert_array_equal(np.asarray(ints), np.asarray(floats))
    wide = model  # float64 in the tests; float32 states are raised to its precision
    narrow = mx.simulate(wide, jnp.asarray(x[0], jnp.float32), t)
    assert narrow.dtype == jnp.float64


def test_a_horizon_without_a_step_is_null_not_zero(setup):
    data, model = setup
    short = mx.evaluate(model, data, horizon=1e-9, step_check=False)
    assert short["rollout_error_to_horizon_mean"] is None
    assert short["constant_prediction_error_to_horizon_mean"] is None
    assert "no step within the horizon" in short["null_reasons"]["rollout_error_to_horizon_mean"]
