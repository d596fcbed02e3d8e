"""How soon a model's rollouts from nearby states part (``predictability_time``): on chaotic
motion a whole-trajectory error measures that growth as much as the model, and ``evaluate``
says so with the horizon to judge it by (new-user check 16: a chaotic Hénon–Heiles test set
erred 1.1 over 200 time units, 5e-3 up to t = 20, and nothing said why)."""

from __future__ import annotations

import functools

import jax.numpy as jnp
import numpy as np

import metriplex as mx
from metriplex.app._warnings import structure_warnings
from metriplex.diagnostics import initial_state_sensitivity


@functools.cache
def henon_heiles() -> mx.GenericModel:
    def energy(x):
        q1, q2, p1, p2 = x
        return 0.5 * (p1**2 + p2**2 + q1**2 + q2**2) + q1**2 * q2 - q2**3 / 3.0

    return mx.GenericModel(mx.Known(energy), mx.ZeroPotential(), mx.CanonicalPoisson(4, 2),
                           mx.ZeroFriction(4))


def _data(energy: float) -> mx.Trajectories:
    """Five trajectories at one energy, from (0, y, 0.05, p2), over 200 time units."""
    y = np.array([-0.1, -0.05, 0.0, 0.05, 0.1])
    p2 = np.sqrt(2.0 * energy - 0.05**2 - y**2 + 2.0 * y**3 / 3.0)
    x0 = np.stack([np.zeros(5), y, np.full(5, 0.05), p2], axis=1)
    ts = np.arange(2001) * 0.1
    return mx.Trajectories.from_arrays(ts, np.asarray(mx.simulate(henon_heiles(), jnp.asarray(x0),
                                                                  jnp.asarray(ts))))


def test_chaotic_motion_has_a_predictability_time_and_evaluate_names_it():
    data = _data(0.16)  # near the escape energy 1/6: chaotic
    report = mx.evaluate(henon_heiles(), data)
    assert report["twin_growth"] > 1e3
    when = report["predictability_time"]
    assert 5.0 < when < 150.0
    (note,) = [w for w in structure_warnings(report) if "apart" in w]
    assert f"--horizon {when:.3g}" in note
    # Judged up to that time, as the note says, the note has nothing more to say.
    short = mx.evaluate(henon_heiles(), data, horizon=when)
    assert not [w for w in structure_warnings(short) if "apart" in w]


def test_regular_motion_has_none():
    report, why = initial_state_sensitivity(henon_heiles(), _data(0.02))
    assert 1.0 <= report["twin_growth"] < 20.0 and report["predictability_time"] is None
    assert "stay within 0.1 of each other" in why["predictability_time"]
    # A dissipative flow brings nearby states together: no growth at all.
    model = mx.GenericModel(mx.Known(lambda x: 0.5 * (x[0] ** 2 + x[1] ** 2) + x[2]),
                            mx.SumOf((2,)), mx.CanonicalPoisson(3, 1), mx.KnownFriction(
                                lambda x: 0.5 * jnp.outer(jnp.array([0.0, 1.0, -x[1]]),
                                                          jnp.array([0.0, 1.0, -x[1]]))))
    ts = np.arange(201) * 0.1
    x0 = jnp.asarray([[1.0, 0.0, 0.0], [0.5, 0.5, 0.1]])
    damped = mx.Trajectories.from_arrays(ts, np.asarray(mx.simulate(model, x0, jnp.asarray(ts))))
    report, _ = initial_state_sensitivity(model, damped)
    assert report["twin_growth"] < 1.5 and report["predictability_time"] is None
