"""Data that float32 would round by a fair share of a step (a bath entropy offset by 1e4) train
in float64 by default, with a note that says why; ``--no-float64`` keeps float32, and a resumed
run keeps the interrupted run's choice."""

import json

import numpy as np
import pytest

import metriplex as mx
from metriplex._rounding import FLOAT32_ROUNDING_LIMIT, float32_rounding, needs_float64
from metriplex.app.config import RunConfig
from metriplex.data import state_scale, time_scale
from metriplex.app.runs import train_run
from metriplex.io import read_header
from metriplex.systems import generate


def _offset(data: mx.Trajectories, i: int, by: float) -> mx.Trajectories:
    x = data.x.copy()
    x[:, i] += by
    return mx.Trajectories(data.trajectory, data.t, x, data.names)


def test_the_rounding_is_the_float32_spacing_as_a_rate_over_a_step():
    data = generate("oscillator-bath", trajectories=3, steps=30, seed=0)
    near = float32_rounding(data.pairs())
    pairs = _offset(data, 2, 1e4).pairs()
    far = float32_rounding(pairs)
    assert near.max() < 1e-4 < FLOAT32_ROUNDING_LIMIT
    assert far[2] > 2 * FLOAT32_ROUNDING_LIMIT
    np.testing.assert_allclose(far[:2], near[:2], rtol=1e-9)  # the others as they were
    d = state_scale(pairs.x0, pairs.x1)
    top = np.max(np.abs(pairs.x0[:, 2]))
    assert far[2] == pytest.approx(np.spacing(np.float32(top)) / d[2] * time_scale(pairs, d)
                                   / np.median(pairs.dt), rel=1e-3)
    # in ms instead of s: the same share
    slow = mx.Trajectories(data.trajectory, 1e3 * data.t, _offset(data, 2, 1e4).x, data.names)
    np.testing.assert_allclose(float32_rounding(slow.pairs()), far, rtol=1e-9)
    assert needs_float64(data.pairs(), data.names) is None
    why = needs_float64(pairs, data.names)
    assert why is not None and "'s'" in why and "reach 1e+04" in why


def test_values_stored_as_float32_or_constant_lose_nothing_more():
    data = _offset(generate("oscillator-bath", trajectories=3, steps=30, seed=0), 2, 1e4)
    stored = mx.Trajectories(data.trajectory, data.t,
                             data.x.astype(np.float32).astype(np.float64), data.names)
    assert float32_rounding(stored.pairs())[2] == 0.0  # float64 would not restore it
    x = data.x.copy()
    x[:, 1] = 1e4 + 1e-3 * np.pi  # constant
    assert float32_rounding(mx.Trajectories(data.trajectory, data.t, x, data.names).pairs()
                            )[1] == 0.0


def _config(**kw) -> RunConfig:
    return RunConfig(poisson="canonical:1", entropy="sum:2", steps=20, eval_every=10,
                     average_steps=0, starts=1, repeats=1, reversible_first=False,
                     validation=0.0, **kw)


def test_no_float64_keeps_float32_and_the_flags_read_so():
    from metriplex.app._commands import _config_from_args
    from metriplex.app.cli import build_parser

    def parsed(*flags):
        return _config_from_args(build_parser().parse_args(["train", "d.npz", "--out", "r",
                                                            *flags])).float64

    assert (parsed(), parsed("--float64"), parsed("--no-float64")) == (None, True, False)


def test_offset_data_train_in_float64_and_a_resume_keeps_the_choice(tmp_path, capsys):
    data = _offset(generate("oscillator-bath", trajectories=3, steps=30, seed=0), 2, 1e4)
    run = tmp_path / "run"
    train_run(data, _config(), run, progress=False)
    assert read_header(run).get("dtype") == "float64"
    header = json.loads((run / "config.json").read_text())
    assert header["decided"]["float64"] is True and header["config"]["float64"] is None
    assert "note: training in float64: float32 would round 's'" in capsys.readouterr().err
    with pytest.raises(mx.MetriplexError,
                       match="it ran with --float64, this command gives --no-float64"):
        train_run(data, _config(float64=False), run, resume=True, progress=False)
    train_run(data, _config(float64=False), tmp_path / "f32", progress=False)
    assert read_header(tmp_path / "f32").get("dtype") == "float32"
    assert "training in float64" not in capsys.readouterr().err
