"""`--dt STEP` (and `read(path, dt=STEP)`): a uniform time grid t = k * STEP per trajectory that
replaces or supplies a data file's times, in every format (issue 14: a published `.mat` whose
time vector has fewer entries than the snapshots was refused with no way out)."""

import contextlib
import io
import json
import re
import subprocess

import h5py
import jax.random as jr
import numpy as np
import pytest
import scipy.io

import metriplex as mx
from metriplex._errors import MetriplexError
from metriplex.cli import main
from metriplex.data import uniform_times
from metriplex.io import read_mat


def run(*args):
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main([str(a) for a in args])
        except SystemExit as e:
            code = e.code
    return subprocess.CompletedProcess(args, code, out.getvalue(), err.getvalue())


K, N, T = 3, 2, 30


def snapshots() -> np.ndarray:
    """Trajectories x variables x snapshots, as SPNN datasets store them."""
    t = np.arange(T) * 0.1
    return np.stack([np.stack([np.cos(t + k), -np.sin(t + k)]) for k in range(K)])


def expected_grid(dt: float) -> np.ndarray:
    return np.tile(np.arange(T) * dt, K)


@pytest.fixture
def short_time_vector(tmp_path):
    """Half as many times as snapshots (the published case was 1 x 150 for 300)."""
    path = tmp_path / "spnn.mat"
    scipy.io.savemat(path, {"Z": snapshots(), "t_vec": (np.arange(T // 2) * 0.1)[None],
                            "names": np.array(["q", "p"], dtype=object)[None]})
    return path


def test_a_time_vector_that_does_not_fit_is_refused_naming_dt(short_time_vector):
    with pytest.raises(MetriplexError, match=r"time vector `t_vec` .* is 1×15; state array `Z` "
                       r"\(3×2×30\) has 30 snapshots.* pass --dt STEP on the command line "
                       r"\(read\(path, dt=STEP\)"):
        mx.read(short_time_vector)
    data = mx.read(short_time_vector, dt=0.25)
    np.testing.assert_array_equal(data.t, expected_grid(0.25))
    assert data.names == ("q", "p") and list(data.ids) == [0, 1, 2]
    np.testing.assert_array_equal(data.x[:T], snapshots()[0].T)


def test_dt_replaces_or_supplies_the_times_of_every_format(tmp_path):
    Z = snapshots()
    ids = np.repeat(np.arange(K), T)
    x = Z.transpose(0, 2, 1).reshape(K * T, N)
    # NPZ without `t`; with a `t` that is not increasing, --dt replaces it.
    np.savez(tmp_path / "no_t.npz", trajectory=ids, x=x)
    np.savez(tmp_path / "bad_t.npz", trajectory=ids, t=np.zeros(K * T), x=x)
    with pytest.raises(MetriplexError, match=r"lacks the array\(s\) \['t'\]"):
        mx.read(tmp_path / "no_t.npz")
    # CSV whose `t` column is empty or decreasing.
    lines = ["trajectory,t,q,p"] + [f"{i},{'' if j % 2 else -j},{a!r},{b!r}"
                                    for j, (i, (a, b)) in enumerate(zip(ids.tolist(), x.tolist()))]
    (tmp_path / "t.csv").write_text("\n".join(lines) + "\n")
    # HDF5 without `t`.
    with h5py.File(tmp_path / "no_t.h5", "w") as f:
        for k in range(K):
            f.create_group(f"trajectory_{k}").create_dataset("x", data=Z[k].T)
    # MAT: snapshots without any time; the long table without `t`.
    scipy.io.savemat(tmp_path / "snap.mat", {"Z": Z})
    scipy.io.savemat(tmp_path / "long.mat", {"trajectory": ids[:, None].astype(float), "x": x})
    for name in ("no_t.npz", "bad_t.npz", "t.csv", "no_t.h5", "snap.mat", "long.mat"):
        data = mx.read(tmp_path / name, dt=0.5)
        np.testing.assert_array_equal(data.t, expected_grid(0.5), err_msg=name)
        np.testing.assert_array_equal(data.x, x, err_msg=name)
    with pytest.raises(MetriplexError, match=r"gives no times .* Add one, or pass --dt STEP"):
        mx.read(tmp_path / "snap.mat")


def test_the_grid_follows_each_trajectorys_rows_in_file_order():
    assert uniform_times(np.array([5, 2, 5, 2, 2, 9]), 0.5).tolist() == [0, 0, 0.5, 0.5, 1, 0]
    data = mx.Trajectories(np.array([5, 2, 5, 2]), uniform_times(np.array([5, 2, 5, 2]), 1.0),
                           np.arange(4.0))
    assert data.t.tolist() == [0, 1, 0, 1] and data.x[:, 0].tolist() == [1, 3, 0, 2]


@pytest.mark.parametrize("dt", [0, -1.0, float("nan"), float("inf"), True, "0.1"])
def test_a_bad_step_is_refused(short_time_vector, dt):
    with pytest.raises(MetriplexError, match=r"dt must be a positive finite time step; got"):
        mx.read(short_time_vector, dt=dt)


def test_read_mat_takes_a_time_vector_or_a_step_not_both(short_time_vector):
    with pytest.raises(MetriplexError, match=r"time='t_vec' names the time vector .* and "
                       r"dt=0\.1 replaces the file's times .*; got both"):
        read_mat(short_time_vector, time="t_vec", dt=0.1)


def test_the_command_line_way_out(short_time_vector, tmp_path):
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    model = mx.GenericModel(mx.MLPPotential(2, width=4, depth=1, key=jr.key(0)),
                            mx.ZeroPotential(), mx.CanonicalPoisson(2, 1), mx.ZeroFriction(2))
    mx.save(run_dir / "model.mpx", model, n=2, names=("q", "p"))
    for command, out in (("rollout", "p.npz"), ("evaluate", "m.json"),):
        res = run(command, run_dir, short_time_vector, "--out", tmp_path / out)
        assert res.returncode == 2 and "Traceback" not in res.stderr, res.stderr
        assert len(res.stderr.strip().splitlines()) == 1, res.stderr
        assert re.search(rf"metriplex {command}: error: time vector `t_vec` .* pass --dt STEP",
                         res.stderr), res.stderr
    res = run("train", short_time_vector, "--out", tmp_path / "r", "--poisson", "canonical:1",
              "--entropy", "zero", "--quiet")
    assert res.returncode == 2 and "--dt STEP" in res.stderr and not (tmp_path / "r").exists()
    res = run("rollout", run_dir, short_time_vector, "--out", tmp_path / "p.npz", "--dt", "0.1",
              "--trajectories", "1-2", "--quiet")
    assert res.returncode == 0, res.stderr
    pred = mx.read(tmp_path / "p.npz")
    assert list(pred.ids) == [1, 2]
    np.testing.assert_allclose(pred.t, np.tile(np.arange(T) * 0.1, 2), rtol=1e-15)
    # The same trajectories as the rollout: evaluate reuses its compiled rollout.
    res = run("evaluate", run_dir, short_time_vector, "--dt", "0.1", "--no-verdict", "--quiet",
              "--trajectories", "1-2", "--out", tmp_path / "m.json")
    assert res.returncode == 0, res.stderr
    assert json.loads((tmp_path / "m.json").read_text())["trajectory_ids"] == [1, 2]


def test_dt_never_silently_replaces_times_that_the_file_has(tmp_path):
    # A file with usable times of step 0.1: --dt 0.2 would train a model of other dynamics.
    ids = np.repeat(np.arange(K), T)
    x = snapshots().transpose(0, 2, 1).reshape(K * T, N)
    data = mx.Trajectories(ids, np.tile(np.arange(T) * 0.1, K), x, ("q", "p"))
    for name in ("d.csv", "d.npz", "d.h5", "d.mat"):
        mx.write(tmp_path / name, data)
        with pytest.raises(MetriplexError, match=r"--dt 0\.2 would replace the file's own "
                           r"times, whose steps are 0\.1\. .*Leave out --dt"):
            mx.read(tmp_path / name, dt=0.2)
        # The same step is no contradiction.
        np.testing.assert_allclose(mx.read(tmp_path / name, dt=0.1).t, data.t, atol=1e-12)
    # Uneven times whose mean step is dt are refused too; times stored in float32, whose steps
    # wobble by their rounding, are not.
    jitter = np.cumsum(np.random.default_rng(0).uniform(0.05, 0.15, T))
    mx.write(tmp_path / "uneven.npz", mx.Trajectories(np.zeros(T, int), jitter - jitter[0],
                                                       x[:T], ("q", "p")))
    with pytest.raises(MetriplexError, match=r"whose steps are 0\.05\d* to 0\.14\d*"):
        mx.read(tmp_path / "uneven.npz", dt=0.1)
    many = 20_000
    np.savez(tmp_path / "f32.npz", trajectory=np.zeros(many, int), x=np.zeros((many, 1)),
             t=(np.arange(many) * np.float32(1e-3)).astype(np.float32))
    assert mx.read(tmp_path / "f32.npz", dt=1e-3).t[-1] == pytest.approx(19.999)
    # A float64 clock far from zero with one sample missing (a new-user check's lab file, times
    # near 1.7e9 s, whose gap float32's rounding of 128 s hid): refused, naming the gap.
    clock = 1.7e9 + 0.05 * np.delete(np.arange(T + 1), 7)
    mx.write(tmp_path / "clock.csv", mx.Trajectories(np.zeros(T, int), clock, x[:T], ("q", "p")))
    with pytest.raises(MetriplexError, match=r"--dt 0\.05 would replace the file's own times, "
                       r"whose steps are 0\.05 to 0\.1"):
        mx.read(tmp_path / "clock.csv", dt=0.05)
    result = run("train", tmp_path / "d.csv", "--out", tmp_path / "run", "--dt", "0.2",
                 "--steps", "1")
    assert result.returncode == 2 and "would replace the file's own times" in result.stderr
    assert "Traceback" not in result.stderr
