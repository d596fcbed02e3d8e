"""An entropy step along a rollout that falls by rounding only is not a decrease: a float32
rollout at an equilibrium moves S by about one rounding unit either way, and neither the
fraction of decreasing steps nor the bar "entropy never decreasing" counts that; a larger
fall is counted, and float64 keeps the tight tolerance."""

import jax.numpy as jnp
import jax.random as jr
import numpy as np
import pytest

import metriplex as mx
from metriplex._model import with_dtype
from metriplex.app.experiments import _met
from metriplex.diagnostics import ENTROPY_ROUNDING_UNITS, entropy_step_rounding
from metriplex.integrate import Rollout


def test_the_rounding_of_S_is_counted_in_the_models_precision():
    s = np.array([4.0, 4.0, 4.0])
    one_unit = float(np.spacing(np.float32(4.0)))  # 4.77e-7
    assert entropy_step_rounding(s, np.float32) == pytest.approx(
        ENTROPY_ROUNDING_UNITS * float(np.finfo(np.float32).eps) * 4.0)
    assert one_unit < entropy_step_rounding(s, np.float32) < 1e-5
    assert entropy_step_rounding(s, np.float64) == pytest.approx(4e-12)
    # A small S keeps the former absolute floor; a state that is not finite is left out.
    assert entropy_step_rounding(np.array([1e-3, np.nan]), np.float64) == pytest.approx(1e-12)
    assert entropy_step_rounding(np.array([4.0, np.inf]), np.float32) == pytest.approx(
        entropy_step_rounding(s, np.float32))


def _report(fall_units: float, dtype):
    """evaluate() on one trajectory whose rolled-out entropy s falls by ``fall_units`` units
    of float32 rounding at 4 in its last step, for a model in ``dtype``."""
    n = 3
    t = np.arange(4.0) * 0.1
    x = np.zeros((1, 4, n))
    x[0, :, 0] = [0.0, 0.1, 0.2, 0.3]
    x[0, :, 2] = 4.0 + np.array([0.0, 1e-3, 2e-3, 2e-3])
    x[0, 3, 2] -= fall_units * float(np.spacing(np.float32(4.0)))
    data = mx.Trajectories.from_arrays(t, x)
    model = with_dtype(mx.GenericModel(mx.MLPPotential(n, key=jr.key(0)), mx.SumOf((2,)),
                                          mx.ZeroPoisson(n), mx.ZeroFriction(n)), dtype)
    pred = jnp.asarray(x, dtype)
    out = Rollout(jnp.asarray(t[None], dtype), pred, jnp.array([-1]), jnp.zeros((1, 4), int))
    return mx.evaluate(model, data, rollout=(out, x, np.array([4])), step_check=False)


def test_a_fall_by_rounding_is_not_a_decrease_and_a_larger_one_is():
    rounded = _report(1.0, jnp.float32)
    assert rounded["entropy_min_step"] < 0.0
    assert rounded["entropy_negative_step_fraction"] == 0.0
    assert rounded["entropy_step_rounding"] > -rounded["entropy_min_step"]
    assert _met("entropy_min_step", rounded["entropy_min_step"], 0.0,
                rounded["entropy_step_rounding"])
    larger = _report(4 * ENTROPY_ROUNDING_UNITS, jnp.float32)
    assert larger["entropy_negative_step_fraction"] == pytest.approx(1 / 3)
    assert not _met("entropy_min_step", larger["entropy_min_step"], 0.0,
                    larger["entropy_step_rounding"])
    # In float64 the same one-unit fall (of float32's unit) is a decrease.
    exact = _report(1.0, jnp.float64)
    assert exact["entropy_negative_step_fraction"] == pytest.approx(1 / 3)
    assert not _met("entropy_min_step", exact["entropy_min_step"], 0.0,
                    exact["entropy_step_rounding"])
