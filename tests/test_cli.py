"""The command line: bad input gets one clear message and exit status 2, no traceback, and no
existing file is modified; the forms of docs/design.md, 'Command line', work end to end."""

import contextlib
import hashlib
import io
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import metriplex as mx
from metriplex.cli import main


def run(*args):
    """Run the CLI in this process (fast); one test below also runs it as a real subprocess."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main([str(a) for a in args])
        except SystemExit as e:  # argparse usage errors and --help
            code = e.code
    return subprocess.CompletedProcess(args, code, out.getvalue(), err.getvalue())


def test_cli_as_a_subprocess(tmp_path):
    res = subprocess.run([sys.executable, "-m", "metriplex", "train", str(tmp_path / "no.npz"),
                          "--out", str(tmp_path / "r")], capture_output=True, text=True,
                         timeout=300)
    assert_clean_error(res, r"data file .*no.npz' does not exist")


def digest(folder: Path) -> dict:
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def assert_clean_error(res, pattern):
    assert res.returncode == 2, (res.returncode, res.stdout, res.stderr)
    assert "Traceback" not in res.stderr, res.stderr
    import re

    assert re.search(pattern, res.stderr), res.stderr


@pytest.fixture
def oscillator_run(trained_run):
    """The session's shared training run (tests/conftest.py): ``data.npz`` and ``run/``."""
    return trained_run


def test_run_folder_contents(oscillator_run):
    run_dir = oscillator_run / "run"
    for name in ("model.mpx", "config.json", "history.json", "metrics.json", "checkpoint.ckpt",
                 "figures/loss.png", "figures/loss.pdf", "figures/loss.npz",
                 "figures/trajectories.png", "figures/energy_entropy.npz", "figures/error.pdf",
                 "figures/residual.png", "figures/residual.npz"):
        assert (run_dir / name).exists(), name
    cfg = json.loads((run_dir / "config.json").read_text())
    assert cfg["names"] == ["q", "p", "s"] and cfg["config"]["poisson"] == "canonical:1"
    # What the options left at their default decided, spelled out (the options read null).
    assert cfg["config"]["reversible_first"] is None and cfg["config"]["patience"] is None
    assert cfg["config"]["float64"] is None
    assert cfg["decided"] == {"confine": True, "reversible_first": True, "hold_energy": False,
                              "w_temperature": 1.0, "temperature_init": True,
                              "starts": 1, "residual_metric": "correlated", "jacobi": "none",
                              "exact_poisson_degeneracy": False,
                              "exact_friction_degeneracy": True, "entropy_of": None,
                              "patience": 20, "repeats": 4, "good_score": 0.02, "every": 1,
                              "scheme": "cn", "coarse_steps": None, "float64": False}
    # How each training ended is recorded however many ran (one here or more).
    assert cfg["trainings"] and 0 <= cfg["kept_training"] < len(cfg["trainings"])
    assert {"score", "stopped", "converged"} <= set(cfg["trainings"][cfg["kept_training"]])
    # The run released its folder, and every file has the user's umask (not mkstemp's 0600).
    assert not (run_dir / ".metriplex.lock").exists()
    mask = os.umask(0)
    os.umask(mask)
    modes = {str(p.relative_to(run_dir)): oct(p.stat().st_mode & 0o777)
             for p in run_dir.rglob("*") if p.is_file()}
    assert set(modes.values()) == {oct(0o666 & ~mask)}, modes
    assert set(cfg["train_trajectories"]).isdisjoint(cfg["validation_trajectories"])


def test_rollout_and_evaluate(oscillator_run, tmp_path):
    src, tmp = oscillator_run, tmp_path  # the run and data; the outputs
    shared = digest(src)
    res = run("rollout", src / "run", src / "data.npz", "--out", tmp / "pred.npz")
    assert res.returncode == 0, res.stderr
    pred, data = mx.read(tmp / "pred.npz"), mx.read(src / "data.npz")
    assert pred.names == data.names and len(pred) == len(data)
    np.testing.assert_array_equal(pred.t, data.t)
    np.testing.assert_allclose(pred.x[pred.t == 0], data.x[data.t == 0], rtol=1e-6)
    # Newton instead of the default fixed-point-first solver: the same rollout to tolerance.
    res = run("rollout", src / "run", src / "data.npz", "--out", tmp / "pred_newton.npz",
              "--solver", "newton")
    assert res.returncode == 0, res.stderr
    np.testing.assert_allclose(mx.read(tmp / "pred_newton.npz").x, pred.x, rtol=1e-4, atol=1e-5)
    res = run("rollout", src / "run", src / "data.npz", "--out", tmp / "pred_rk4.npz",
              "--scheme", "rk4", "--solver", "newton")
    assert_clean_error(res, r"--solver applies to the implicit schemes")
    # A short reference training for the verdict: the keys written are checked here, the
    # verdict itself in test_verdict.py.
    res = run("evaluate", src / "run", src / "data.npz", "--out", tmp / "metrics.json",
              "--verdict-steps", "100", "--every", "2")
    assert res.returncode == 0, res.stderr
    m = json.loads((tmp / "metrics.json").read_text())
    assert m["every"] == 2  # every second sample (the verdict's way round noise)
    assert "--every 2: the rollouts step 2 samples at a time" in res.stderr
    assert 0 <= m["noise_over_spread"] < 0.005  # clean data: no note on noise
    assert "carry noise" not in res.stderr
    for key in ("rollout_error", "rollout_error_mean", "energy_relative_drift", "entropy_min_step",
                "degeneracy_L_gradS", "degeneracy_M_gradE", "jacobi_residual", "verdict"):
        assert key in m, key
    assert len(m["rollout_error"]) == len(data)
    # The warning that the model does not beat predicting no motion comes exactly when so.
    worse = m["rollout_error_mean_completed"] >= m["constant_prediction_error_mean_completed"]
    assert ("NO better than predicting x(t) = x(0)" in res.stderr) == worse, res.stderr
    # These are the run's training data: the figures are in-sample, and evaluate says so.
    trained = len(json.loads((src / "run" / "config.json").read_text())["train_trajectories"])
    assert m["trajectories_trained_on"] == trained > 0
    assert f"{trained} of the {len(data)} trajectories evaluated were trained on" in res.stderr
    # The output exists now: evaluate refuses to overwrite it.
    before = digest(tmp)
    res = run("evaluate", src / "run", src / "data.npz", "--out", tmp / "metrics.json")
    assert_clean_error(res, r"exists; refusing to overwrite it\. Pass --overwrite")
    assert digest(tmp) == before
    assert digest(src) == shared  # the run folder and the data are only read


def test_train_refuses_to_overwrite_a_run(oscillator_run):
    tmp = oscillator_run
    before = digest(tmp / "run")
    res = run("train", tmp / "data.npz", "--out", tmp / "run", "--steps", "10", "--quiet")
    assert_clean_error(res, r"exists and is not empty; refusing to overwrite it")
    assert digest(tmp / "run") == before


@pytest.mark.parametrize(
    "options,pattern",
    [
        (["--poisson", "canonical:6"], r"canonical:6 needs 2K <= n .* n=3 variables"),
        (["--entropy", "sum:12"], r"indices must lie in \[0, 2\] .* got \[12\]"),
        (["--entropy", "sum:a"], r"comma-separated integer indices"),
        (["--friction", "learned"],
         r"--friction must be one of neural, exchange, local, zero, file; got 'learned'"),
        (["--jacobi", "maybe"], r"--jacobi must be one of auto, none, exact, stochastic"),
        (["--lr", "-1"], r"--lr must be > 0; got -1"),
        (["--validation", "1.5"], r"--validation must lie in \[0, 1\); got 1.5"),
        (["--degeneracy-at", "edges"], r"--degeneracy-at must be one of states, midpoints"),
        (["--features-for", "energy,poisson"], r"--features-for lists the networks .* entries "
         r"of L are not invariant"),
    ],
)
def test_structure_options_that_do_not_fit_the_data(oscillator_run, tmp_path, options, pattern):
    res = run("train", oscillator_run / "data.npz", "--out", tmp_path / "r", *options, "--quiet")
    assert_clean_error(res, pattern)
    assert not (tmp_path / "r").exists() or not any((tmp_path / "r").iterdir())


def test_bad_data_files(tmp_path):
    (tmp_path / "empty.csv").write_text("")
    res = run("train", tmp_path / "empty.csv", "--out", tmp_path / "r")
    assert_clean_error(res, r"empty")
    (tmp_path / "nan.csv").write_text("trajectory,t,q\n0,0.0,1.0\n0,0.1,nan\n")
    assert_clean_error(run("train", tmp_path / "nan.csv", "--out", tmp_path / "r"), r"finite")
    (tmp_path / "t.csv").write_text("trajectory,t,q\n0,0.0,1.0\n0,0.2,2.0\n0,0.1,1.0\n")
    assert_clean_error(run("train", tmp_path / "t.csv", "--out", tmp_path / "r"),
                       r"strictly increasing within each trajectory")
    (tmp_path / "one.csv").write_text("trajectory,t,q\n0,0.0,1.0\n0,0.1,2.0\n1,0.0,1.0\n")
    assert_clean_error(run("train", tmp_path / "one.csv", "--out", tmp_path / "r"),
                       r"at least two samples.*trajectory 1 has 1")
    assert_clean_error(run("train", tmp_path / "missing.npz", "--out", tmp_path / "r"),
                       r"does not exist")


def test_model_file_errors(oscillator_run, tmp_path):
    tmp = oscillator_run
    model = (tmp / "run" / "model.mpx").read_bytes()
    (tmp_path / "cut").mkdir()
    (tmp_path / "cut" / "model.mpx").write_bytes(model[: len(model) // 2])
    res = run("evaluate", tmp_path / "cut", tmp / "data.npz")
    assert_clean_error(res, r"truncated or corrupted")
    (tmp_path / "old").mkdir()
    head, _, rest = model.partition(b"\n")
    header, _, body = rest.partition(b"\n")
    h = json.loads(header)
    h["format_version"] = 99
    (tmp_path / "old" / "model.mpx").write_bytes(head + b"\n" + json.dumps(h).encode() + b"\n" + body)
    assert_clean_error(run("evaluate", tmp_path / "old", tmp / "data.npz"),
                       r"format version 99; this metriplex reads version 1")
    assert_clean_error(run("evaluate", tmp_path / "nothing", tmp / "data.npz"), r"does not exist")
    wide = mx.read(tmp / "data.npz")
    wide = mx.Trajectories(wide.trajectory, wide.t, np.c_[wide.x, wide.x])
    mx.write(tmp_path / "wide.npz", wide)
    assert_clean_error(run("evaluate", tmp / "run", tmp_path / "wide.npz"),
                       r"data have 6 state variables but the model .* was trained on 3")


def test_unknown_or_reordered_columns(oscillator_run, tmp_path):
    data = mx.read(oscillator_run / "data.npz")
    mx.write(tmp_path / "renamed.csv", data.with_names(("q", "p", "entropy")))
    res = run("rollout", oscillator_run / "run", tmp_path / "renamed.csv", "--out", tmp_path / "p.npz")
    assert_clean_error(res, r"columns \(q, p, entropy\) differ from the model's \(q, p, s\); "
                            r"unknown: entropy")
    assert not (tmp_path / "p.npz").exists()


def test_help_lists_commands():
    res = run("--help")
    assert res.returncode == 0
    for cmd in ("generate", "simulate", "train", "rollout", "evaluate", "reproduce"):
        assert cmd in res.stdout


def test_generate_and_its_former_name_simulate_write_the_same_data(tmp_path):
    args = ("oscillator-bath", "--trajectories", "2", "--steps", "5", "--dt", "0.02")
    assert run("generate", *args, "--out", tmp_path / "a.npz").returncode == 0
    assert run("simulate", *args, "--out", tmp_path / "b.npz").returncode == 0
    a, b = mx.read(tmp_path / "a.npz"), mx.read(tmp_path / "b.npz")
    assert np.array_equal(a.x, b.x) and np.array_equal(a.t, b.t)


def test_cli_solver_choices_match_the_library():
    from metriplex.cli import build_parser
    from metriplex.integrate import ROOT_FINDERS

    sub = next(a for a in build_parser()._actions if a.__class__.__name__ == "_SubParsersAction")
    for command in ("rollout", "evaluate"):
        solver = next(a for a in sub.choices[command]._actions if a.dest == "solver")
        assert tuple(solver.choices) == tuple(ROOT_FINDERS)
