"""Every bad input to the command line ends in one message (the rule, the value received, the
fix), exit status 2 and no traceback, before any work is done and before any file is written.

The cases of issue 14 first (seed, model header, NaN weights, --steps 0, the canonical bound,
negative numbers, the RK4 failure), then their neighbours. No test trains a model: each case is
refused before training, or uses a model built and saved here.
"""

import contextlib
import io
import json
import os
import re
import subprocess

import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np
import pytest

import metriplex as mx
from metriplex.cli import main


def run(*args):
    """The CLI in this process, as tests/test_cli.py runs it."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main([str(a) for a in args])
        except SystemExit as e:  # argparse usage errors
            code = e.code
    return subprocess.CompletedProcess(args, code, out.getvalue(), err.getvalue())


def refused(res, pattern, *, absent=()):
    """Exit status 2, one message on stderr matching ``pattern``, no traceback, and none of the
    misleading words in ``absent``."""
    assert res.returncode == 2, (res.returncode, res.stdout, res.stderr)
    assert "Traceback" not in res.stderr, res.stderr
    assert re.search(pattern, res.stderr), res.stderr
    lines = [line for line in res.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, res.stderr  # one message, not a usage dump or a chain of errors
    assert lines[0].startswith("metriplex"), res.stderr
    for word in absent:
        assert word not in res.stderr, res.stderr


def oscillator_data(k=4, n_t=11, names=("q", "p", "s")) -> mx.Trajectories:
    """Smooth trajectories made with NumPy alone (no JAX compilation)."""
    t = np.arange(n_t) * 0.1
    pieces = [(t, np.c_[np.cos(t + j), -np.sin(t + j), 0.01 * t + 0.1 * j]) for j in range(k)]
    return mx.Trajectories.from_list(pieces, names)


def small_model(n=3, *, energy=None) -> mx.GenericModel:
    energy = energy or mx.MLPPotential(n, width=4, depth=1, key=jr.key(0))
    return mx.GenericModel(energy, mx.SumOf((n - 1,)), mx.CanonicalPoisson(n, 1),
                           mx.ZeroFriction(n))


def with_header(model_file, folder, change):
    """A copy of ``model_file`` in ``folder`` whose JSON header ``change`` edited in place."""
    raw = model_file.read_bytes()
    magic, _, rest = raw.partition(b"\n")
    header, _, body = rest.partition(b"\n")
    h = json.loads(header)
    replaced = change(h)  # edits h in place, or returns a whole new (list) header
    h = replaced if isinstance(replaced, list) else h
    folder.mkdir()
    (folder / "model.mpx").write_bytes(magic + b"\n" + json.dumps(h).encode() + b"\n" + body)
    return folder


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("messages")
    data = oscillator_data()
    mx.write(tmp / "data.npz", data)
    mx.write(tmp / "data.csv", data)
    one = mx.Trajectories.from_list([(t, x[:, :1]) for t, x in data], ("q",))
    mx.write(tmp / "one.npz", one)
    (tmp / "run").mkdir()
    mx.save(tmp / "run" / "model.mpx", small_model(), n=3, names=data.names)
    (tmp / "existing.json").write_text("{}\n")
    return tmp


def nothing_written(folder):
    return not folder.exists() or not any(folder.iterdir())


# -- the cases of issue 14 ---------------------------------------------------------------------

@pytest.mark.parametrize(
    "options,pattern,absent",
    [
        (["--seed", "-1"], r"--seed must be an integer from 0 to 4294967295; got -1\.", ()),
        (["--seed", str(2**32)], r"--seed must be an integer from 0 to 4294967295; got 4294967296",
         ()),
        (["--steps", "0"], r"--steps must be >= 1 \(the most optimiser steps\); got 0\.",
         ("diverged",)),
        (["--steps", "-3"], r"--steps must be >= 1 .*; got -3\.", ("diverged",)),
        # argparse alone reads "-1e-3" as an option, and says "expected one argument"
        (["--lr", "-1e-3"], r"--lr must be > 0; got -0\.001\.", ("expected one argument",)),
        (["--lr=-1e-3"], r"--lr must be > 0; got -0\.001\.", ()),
        (["--lr", "-.5"], r"--lr must be > 0; got -0\.5\.", ()),
        (["--lr", "-2E+1"], r"--lr must be > 0; got -20\.0\.", ()),
        (["--lr", "nan"], r"--lr must be a finite number; got nan\.", ()),
        (["--lr", "-inf"], r"--lr must be a finite number; got -inf\.", ()),
        (["--lr", "inf"], r"--lr must be a finite number; got inf\.", ("diverged",)),
        (["--w-traj", "nan"], r"--w-traj must be a finite number; got nan\.", ("diverged",)),
        (["--weight-decay", "inf"], r"--weight-decay must be a finite number; got inf", ()),
        (["--max-minutes", "nan"], r"--max-minutes must be a finite number; got nan", ()),
        (["--w-degeneracy-M", "-1e-2"],
         r"--w-degeneracy-M \(a loss weight\) must be >= 0; got -0\.01", ()),
        (["--features", "pendulum"], r"--features pendulum does not fit these data: feature "
         r"indices must lie in \[0, 2\] for a state of 3 variables; .* leave --features out",
         ()),
        (["--batch-size", "0"], r"--batch-size must be >= 1 \(pairs per optimiser step\); got 0",
         ()),
        (["--width", "0"], r"--width must be >= 1 .*; got 0", ()),
        (["--activation", "relu"], r"argument --activation: invalid choice: 'relu'", ("usage:",)),
        (["--eval-every", "-1"], r"--eval-every must be >= 1 .*; got -1", ()),
        (["--jacobi", "stochastic", "--jacobi-probes", "0"],
         r"--jacobi-probes must be >= 1 .*; got 0", ("JacobiPenalty", "StochasticJacobi")),
        (["--checkpoint-every", "0"], r"--checkpoint-every must be >= 1 .*; got 0", ()),
        (["--average-steps", "-1"], r"--average-steps must be an integer >= 0; got -1\. It "
         r"counts the optimiser steps that the running average of the parameters spans; 0 "
         r"turns it off\.", ()),
        (["--poisson", "canonical:2"],
         r"--poisson canonical:2 needs 2K <= n .* n=3 variables\. Use canonical:K with "
         r"1 <= K <= 1\.", ()),
        (["--poisson", "canonical:0"], r"canonical:K needs K >= 1 .*; got K=0\. Use "
                                       r"canonical:K with 1 <= K <= 1 for these n=3", ()),
        # a preset on other data: its structure is named as the preset's, not the user's
        (["--preset", "pendulum-energetic"], r"--preset pendulum-energetic \(its reference "
         r"experiment's settings: --poisson canonical:4 --entropy sum:8,9 \.\.\.\) does not fit "
         r"these data: .* Leave --preset out for other data\.", ()),
        (["--degeneracy", "exact", "--poisson", "lie-poisson"], r"--degeneracy exact builds a "
         r"learned L with L grad S = 0, which a Lie-Poisson L .* cannot be", ()),
        (["--entropy", "sum:"], r"--entropy sum:I,J,... names no variable; got ''\. Give at "
         r"least one index", ()),
        # argparse's own errors: one line, not the whole usage text
        (["--steps", "abc"], r"argument --steps: invalid int value: 'abc'\. See `metriplex "
         r"train --help`", ("usage:",)),
        (["--lr"], r"argument --lr: expected one argument", ("usage:",)),
        (["--no-such-option"], r"metriplex train: error: unrecognized arguments: "
         r"--no-such-option\. See `metriplex train --help`", ("usage:", "did you mean")),
        # a typo: the command's closest option is named
        (["--entorpy", "sum:2"], r"metriplex train: error: unrecognized arguments: --entorpy "
         r"sum:2 \(--entorpy is not an option; did you mean --entropy\?\)\. See `metriplex "
         r"train --help`", ("usage:",)),
    ],
)
def test_train_options(files, tmp_path, options, pattern, absent):
    res = run("train", files / "data.npz", "--out", tmp_path / "r", "--quiet", *options)
    refused(res, pattern, absent=absent)
    assert nothing_written(tmp_path / "r")


def test_canonical_bound_on_one_variable(files, tmp_path):
    """Not "use canonical:K with 1 <= K <= 0": there is no such K."""
    res = run("train", files / "one.npz", "--out", tmp_path / "r", "--poisson", "canonical:1")
    refused(res, r"--poisson canonical:1 needs at least one position and one momentum \(n >= 2 "
                 r"variables\), but the data have n=1\. Use --poisson zero", absent=("<= 0",))


def test_learned_poisson_on_one_variable(files, tmp_path):
    """The default (a learned L) on one variable: the message names the way out."""
    res = run("train", files / "one.npz", "--out", tmp_path / "r", "--quiet")
    refused(res, r"a learned Poisson bivector needs n >= 2 variables; got 1\. With one "
                 r"variable the only antisymmetric L is 0: pass --poisson zero")
    assert nothing_written(tmp_path / "r")


def test_simulate_seed(tmp_path):
    res = run("simulate", "rigid-body", "--trajectories", "1", "--steps", "2", "--dt", "0.1",
              "--seed", "-1", "--out", tmp_path / "s.npz")
    refused(res, r"--seed must be an integer from 0 to 4294967295; got -1\.")
    assert not (tmp_path / "s.npz").exists()


def test_generate_a_step_too_long_for_the_system(tmp_path):
    # 1e11 substeps of the system's accuracy limit would overflow the compiled loop's counter.
    res = run("generate", "rigid-body", "--trajectories", "2", "--steps", "5", "--dt", "1e9",
              "--out", tmp_path / "s.npz")
    refused(res, r"dt = 1e\+09 needs 1e\+11 substeps per recorded step: the rigid-body system "
                 r"is integrated in substeps of at most 0\.01 .* Give a dt of at most 10000 "
                 r"\(--dt\)")
    assert not (tmp_path / "s.npz").exists()


@pytest.mark.parametrize(
    "change,pattern",
    [
        (lambda h: h.pop("n"), r"field 'n' must be the number of state variables, a positive "
                               r"integer; it is missing"),
        (lambda h: h.update(n="3"), r"field 'n' must be .*; got '3'"),
        (lambda h: h.update(n=0), r"field 'n' must be .*; got 0"),
        (lambda h: h.update(n=True), r"field 'n' must be .*; got True"),
        (lambda h: h.pop("model"), r"field 'model' must be the architecture.*; it is missing"),
        (lambda h: h["model"].pop("poisson"), r"field 'model' must be the architecture"),
        (lambda h: h.update(dtype="float16"), r"field 'dtype' must be 'float32' or 'float64'; "
                                              r"got 'float16'"),
        (lambda h: h.update(names=["q", "p"]), r"field 'names' must be a list of 3 variable "
                                               r"names"),
        (lambda h: h["model"]["energy"].update(width="four"),
         r"describes no model this metriplex can build \(TypeError"),
        (lambda h: h["model"]["energy"].update(kind="weird"), r"unknown potential kind 'weird'"),
        (lambda h: [h], r"a JSON object is needed, got list"),
    ],
)
@pytest.mark.parametrize("command", ["evaluate", "rollout"])
def test_damaged_model_header(files, tmp_path, change, pattern, command):
    run_dir = with_header(files / "run" / "model.mpx", tmp_path / "run", change)
    extra = ["--out", tmp_path / "p.npz"] if command == "rollout" else ["--no-verdict"]
    refused(run(command, run_dir, files / "data.npz", *extra), pattern,
            absent=("KeyError", "TypeError: must be"))
    assert not (tmp_path / "p.npz").exists()


def test_trailing_bytes_after_the_weights(files, tmp_path):
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "model.mpx").write_bytes((files / "run" / "model.mpx").read_bytes()
                                                 + b"junk")
    refused(run("evaluate", tmp_path / "run", files / "data.npz", "--no-verdict"),
            r"is corrupted: 4 bytes follow the weights that its header describes")


@pytest.mark.parametrize("value", [np.nan, np.inf])
@pytest.mark.parametrize("command", ["evaluate", "rollout"])
def test_non_finite_weights(files, tmp_path, value, command):
    """Was: LinAlgError from the friction eigenvalues (evaluate), or "no trajectory could be
    rolled out" after six warnings about implicit steps (rollout)."""
    import equinox as eqx

    model = small_model()
    model = eqx.tree_at(lambda m: m.energy.out.weight, model,
                        model.energy.out.weight.at[0, 1].set(value))
    (tmp_path / "run").mkdir()
    mx.save(tmp_path / "run" / "model.mpx", model, n=3, names=("q", "p", "s"))
    extra = ["--out", tmp_path / "p.npz"] if command == "rollout" else []
    res = run(command, tmp_path / "run", files / "data.npz", *extra)
    refused(res, r"holds 1 non-finite weights \(NaN or infinite\) of \d+; .* re-train",
            absent=("LinAlgError", "warning"))
    with pytest.raises(mx.MetriplexError, match="non-finite weights"):
        mx.load(tmp_path / "run")


def blowing_up_model(rate: float) -> mx.GenericModel:
    r"""E = rate * q * p with canonical L: q grows like exp(rate t), which RK4 follows until the
    state overflows (a non-finite state, not a solver that did not converge)."""
    import equinox as eqx

    energy = mx.MLPPotential(2, width=2, depth=1, quadratic=True, key=jr.key(0))
    energy = eqx.tree_at(lambda e: (e.out.weight, e.out.bias, e.quadratic), energy,
                         (jnp.zeros_like(energy.out.weight), jnp.zeros_like(energy.out.bias),
                          jnp.array([[0.0, rate], [rate, 0.0]])))
    return mx.GenericModel(energy, mx.ZeroPotential(), mx.CanonicalPoisson(2, 1),
                           mx.ZeroFriction(2))


@pytest.fixture(scope="module")
def blow_up(files):
    t = np.arange(41) * 0.1
    data = mx.Trajectories.from_list([(t, np.ones((41, 2))), (t, np.full((41, 2), 2.0))],
                                     ("q", "p"))
    mx.write(files / "qp.npz", data)
    for name, rate in (("late", 1e7), ("at-once", 1e100)):
        (files / name).mkdir()
        mx.save(files / name / "model.mpx", blowing_up_model(rate), n=2, names=("q", "p"))
    return files


def test_rk4_failure_speaks_of_rk4(blow_up, tmp_path):
    """Was: "the implicit step to t=... did not converge" for an explicit RK4 rollout."""
    res = run("rollout", blow_up / "late", blow_up / "qp.npz", "--out", tmp_path / "p.npz",
              "--scheme", "rk4")
    assert res.returncode == 0, res.stderr
    warnings = res.stderr.strip().splitlines()
    assert len(warnings) == 2, res.stderr
    for w in warnings:
        assert re.match(r"warning: trajectory [01]: the explicit rk4 step from t=\S+ to t=\S+ "
                        r"gave a non-finite state: the model's vector field overflowed", w), w
        assert "implicit" not in w and "converge" not in w, w
    pred = mx.read(tmp_path / "p.npz")
    assert np.all(np.isfinite(pred.x)) and 2 <= len(pred.t) < 2 * 41


def test_rk4_failure_at_the_first_step(blow_up, tmp_path):
    res = run("rollout", blow_up / "at-once", blow_up / "qp.npz", "--out", tmp_path / "p.npz",
              "--scheme", "rk4")
    assert res.returncode == 2 and "Traceback" not in res.stderr, res.stderr
    *warnings, last = res.stderr.strip().splitlines()
    assert len(warnings) == 2 and all("explicit rk4 step" in w for w in warnings), res.stderr
    assert re.match(r"metriplex rollout: error: no trajectory could be rolled out past its "
                    r"first step with the rk4 scheme", last), last
    assert "implicit" not in res.stderr and "Try --scheme rk4" not in res.stderr
    assert not (tmp_path / "p.npz").exists()


def test_simulate_raises_in_the_words_of_the_scheme():
    model = blowing_up_model(1e7)
    ts = jnp.arange(41.0) * 0.1
    with pytest.raises(mx.RolloutFailure, match=r"the explicit rk4 step from t=\S+ to t=\S+ of "
                                                r"trajectory 0 gave a non-finite state") as e:
        mx.simulate(model, jnp.ones((2, 2)), ts, scheme=mx.RK4())  # the shapes of the CLI test
    assert "implicit" not in str(e.value) and "converge" not in str(e.value)
    assert np.all(np.isfinite(np.asarray(e.value.partial)))


# -- neighbours: data, outputs, the other commands ---------------------------------------------

def test_data_files(files, tmp_path):
    refused(run("train", tmp_path / "missing.npz", "--out", tmp_path / "r"),
            r"data file '.*missing\.npz' does not exist; check the path")
    np.savez(tmp_path / "empty.npz", trajectory=np.zeros(0, int), t=np.zeros(0),
             x=np.zeros((0, 2)))
    refused(run("train", tmp_path / "empty.npz", "--out", tmp_path / "r"), r"hold no rows")
    (tmp_path / "header.csv").write_text("trajectory,time,q\n0,0,1\n0,1,2\n")
    refused(run("train", tmp_path / "header.csv", "--out", tmp_path / "r"),
            r"must start with the header `trajectory,t,<name_1>,...`.*got 'trajectory,time,q'")
    (tmp_path / "folder.npz").mkdir()
    refused(run("train", tmp_path / "folder.npz", "--out", tmp_path / "r"), r"is a folder")
    assert nothing_written(tmp_path / "r")


def test_wrong_columns(files, tmp_path):
    data = mx.read(files / "data.npz")
    mx.write(tmp_path / "renamed.npz", data.with_names(("q", "p", "entropy")))
    refused(run("rollout", files / "run", tmp_path / "renamed.npz", "--out", tmp_path / "p.npz"),
            r"columns \(q, p, entropy\) differ from the model's \(q, p, s\); unknown: entropy")
    refused(run("evaluate", files / "run", files / "one.npz", "--no-verdict"),
            r"the data have 1 state variables but the model .* was trained on 3")


def test_outputs_are_checked_before_any_work(files, tmp_path):
    """An output that cannot be written is refused at once: before the data are read, before a
    model is loaded (here: data and models that would fail later, for another reason)."""
    (tmp_path / "file").write_text("x")
    missing = tmp_path / "missing.npz"
    refused(run("train", missing, "--out", tmp_path / "file"),
            r"--out '.*file' is a file, not a folder; --out names a folder")
    refused(run("train", missing, "--out", tmp_path / "file" / "run"),
            r"cannot write --out '.*file/run': '.*file' is a file, not a folder")
    refused(run("rollout", tmp_path / "nomodel", missing, "--out", tmp_path),
            r"--out '.*' is a folder; --out takes a file name")
    refused(run("rollout", tmp_path / "nomodel", missing, "--out", tmp_path / "p.txt"),
            r"cannot write '.*p\.txt': unknown extension '\.txt'\. Trajectories are written as "
            r"\.csv, .*\.npz")
    refused(run("rollout", tmp_path / "nomodel", missing, "--out", tmp_path / "file" / "p.npz"),
            r"'.*file' is a file, not a folder")
    refused(run("evaluate", tmp_path / "nomodel", missing, "--out", files / "existing.json"),
            r"output file '.*existing\.json' exists; refusing to overwrite it")
    refused(run("evaluate", tmp_path / "nomodel", missing, "--out", tmp_path),
            r"--out '.*' is a folder")
    refused(run("evaluate", tmp_path / "nomodel", missing, "--figures", tmp_path / "file"),
            r"--figures '.*file' is a file, not a folder")
    refused(run("simulate", "rigid-body", "--trajectories", "1", "--steps", "2", "--dt", "0.1",
                "--out", tmp_path / "s.xyz"), r"unknown extension '\.xyz'")
    refused(run("reproduce", "rigid-body", "--quick", "--out", tmp_path / "file"),
            r"--out '.*file' is a file, not a folder")
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "old.txt").write_text("x")
    refused(run("reproduce", "rigid-body", "--quick", "--out", tmp_path / "full"),
            r"output folder '.*full' exists and is not empty; refusing to overwrite it")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file", "full"]


@pytest.mark.skipif(hasattr(os, "geteuid") and os.geteuid() == 0,
                    reason="root writes into read-only folders")
def test_read_only_folder(files, tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        refused(run("train", files / "data.npz", "--out", ro / "run"),
                r"cannot write --out '.*ro/run': the folder '.*ro' is not writable")
        refused(run("rollout", files / "run", files / "data.npz", "--out", ro / "p.npz"),
                r"the folder '.*ro' is not writable")
    finally:
        ro.chmod(0o755)


def test_unwritable_folder_as_any_user(files, tmp_path, monkeypatch):
    """The same check where the test runs as root: the folder reports itself unwritable."""
    ro = tmp_path / "ro"
    ro.mkdir()
    real = os.access
    monkeypatch.setattr(os, "access",
                        lambda p, mode, **kw: False if str(p) == str(ro) else real(p, mode, **kw))
    refused(run("train", files / "missing.npz", "--out", ro / "a" / "run"),
            r"cannot write --out '.*ro/a/run': the folder '.*ro' is not writable \(permission "
            r"denied or a read-only file system\)\. Choose another --out")
    refused(run("evaluate", files / "run", files / "missing.npz", "--figures", ro / "f"),
            r"cannot write --figures '.*ro/f': the folder '.*ro' is not writable")
    refused(run("simulate", "rigid-body", "--trajectories", "1", "--steps", "2", "--dt", "0.1",
                "--out", ro / "s.npz"), r"the folder '.*ro' is not writable")
    assert list(ro.iterdir()) == []


def test_run_and_data_swapped(files, tmp_path):
    res = run("evaluate", files / "data.npz", files / "data.npz", "--out", tmp_path / "m.json")
    refused(res, r"is not a metriplex model file .* Its name is that of a data file: the "
                 r"commands take the run folder \(or model file\) first")


def test_evaluate_options(files, tmp_path):
    refused(run("evaluate", files / "run", files / "data.npz", "--verdict-steps", "0"),
            r"--verdict-steps must be >= 1 .*; got 0\. Pass --no-verdict")
    refused(run("evaluate", files / "run", files / "data.npz", "--every", "0"),
            r"--every must be a whole number >= 1 \(1: every sample\); got 0\.")
    refused(run("evaluate", files / "run", files / "data.npz", "--horizon", "-1"),
            r"--horizon must be a positive finite number; got -1\.0")
    refused(run("evaluate", files / "run", files / "data.npz", "--horizon", "nan"),
            r"--horizon must be a positive finite number; got nan")


def test_damaged_config_json(files, tmp_path):
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "model.mpx").write_bytes((files / "run" / "model.mpx").read_bytes())
    (tmp_path / "run" / "config.json").write_text("{not json")
    refused(run("evaluate", tmp_path / "run", files / "data.npz", "--no-verdict"),
            r"config\.json' is not valid JSON .*; the run folder is damaged")
    (tmp_path / "run" / "config.json").write_text("[1, 2]")
    refused(run("rollout", tmp_path / "run", files / "data.npz", "--out", tmp_path / "p.npz"),
            r"does not hold a run configuration")


def test_resume_without_config_json(files, tmp_path):
    (tmp_path / "r").mkdir()
    (tmp_path / "r" / "checkpoint.ckpt").write_bytes(b"")
    refused(run("train", files / "data.npz", "--out", tmp_path / "r", "--resume"),
            r"cannot resume: '.*config\.json' is missing")
    assert sorted(p.name for p in (tmp_path / "r").iterdir()) == ["checkpoint.ckpt"]
    refused(run("train", files / "data.npz", "--out", tmp_path / "r", "--resume",
                "--overwrite"), r"--resume continues .* --overwrite replaces it; got both")
    assert sorted(p.name for p in (tmp_path / "r").iterdir()) == ["checkpoint.ckpt"]


def test_no_command():
    refused(run(), r"metriplex: error: the following arguments are required: COMMAND")


@pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="needs Linux's /proc")
def test_a_folder_that_os_access_calls_writable_but_is_not():
    # /proc says it is writable to root through os.access but refuses new files: the probe file
    # finds out before any work, where the atomic write found out after all of it.
    from metriplex.io import check_output_file

    with pytest.raises(mx.MetriplexError, match=r"cannot write --out '/proc/m\.json': the "
                                                r"folder '/proc' is not writable"):
        check_output_file("/proc/m.json")


def test_outputs_never_replace_what_the_command_reads(files, tmp_path):
    # Even with --overwrite (which replaces earlier outputs, not inputs): the data file, a
    # file of the run folder; and evaluate's figures without --overwrite.
    data_copy = tmp_path / "data.npz"
    data_copy.write_bytes((files / "data.npz").read_bytes())
    before = data_copy.read_bytes()
    for cmd in ("rollout", "evaluate"):
        refused(run(cmd, files / "run", data_copy, "--out", data_copy, "--overwrite"),
                r"--out '.*data\.npz' is the data file this command reads; writing there would "
                r"replace your data")
    refused(run("evaluate", files / "run", data_copy, "--out", files / "run" / "config.json",
                "--overwrite"), r"is a file of the run folder .* which this command reads")
    refused(run("evaluate", files / "run", data_copy, "--out", tmp_path / "m.csv"),
            r"unknown extension '\.csv'\. Metrics are written as \.json\.")
    assert data_copy.read_bytes() == before
    assert not (files / "run" / "config.json").exists()
    figures = tmp_path / "figs"
    figures.mkdir()
    (figures / "error.png").write_text("mine")
    refused(run("evaluate", files / "run", data_copy, "--figures", figures, "--no-verdict"),
            r"--figures '.*figs' already holds error\.png; refusing to overwrite them\. Pass "
            r"--overwrite")
    assert (figures / "error.png").read_text() == "mine"

# -- the Python API: wrong arguments are named, no file is written that load would refuse -----
# (found by a new-user check of the API; the model and data of the CLI cases above, so that
# their compiled programs serve here too)

def test_save_refuses_what_load_would_refuse(tmp_path):
    model = small_model()
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


def test_solve_and_evaluate_name_a_wrong_argument():
    data, model = oscillator_data(), small_model()
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
    # The data's width, said as such (it was "x0 has 3 state variables", of no x0 passed).
    with pytest.raises(mx.MetriplexError, match="the data have 3 state variables but the model "
                       "expects 4"):
        mx.evaluate(small_model(4), data)


def test_integer_states_and_states_narrower_than_the_model_roll_out():
    data, model = oscillator_data(), small_model()
    t, x = next(iter(data))
    ints = mx.simulate(model, [1, 0, 0], t)  # integers: in the model's float dtype
    floats = mx.simulate(model, np.asarray([1.0, 0.0, 0.0]), t)
    np.testing.assert_array_equal(np.asarray(ints), np.asarray(floats))
    wide = model  # float64 in the tests; float32 states are raised to its precision
    narrow = mx.simulate(wide, jnp.asarray(x[0], jnp.float32), t)
    assert narrow.dtype == jnp.float64


def test_a_horizon_without_a_step_is_null_not_zero():
    data, model = oscillator_data(), small_model()
    short = mx.evaluate(model, data, horizon=1e-9, step_check=False)
    assert short["rollout_error_to_horizon_mean"] is None
    assert short["constant_prediction_error_to_horizon_mean"] is None
    assert "no step within the horizon" in short["null_reasons"]["rollout_error_to_horizon_mean"]


def test_a_generic_model_of_blocks_that_do_not_fit_is_refused():
    k1, k2 = jr.split(jr.key(0))
    energy, friction = mx.MLPPotential(3, width=4, depth=1, key=k1), mx.ZeroFriction(3)
    with pytest.raises(mx.MetriplexError, match=r"poisson must be an AbstractPoisson block .*"
                       r"got CholeskyFriction"):
        mx.GenericModel(energy, mx.SumOf((2,)), mx.CholeskyFriction(3, width=4, key=k2),
                        friction)
    with pytest.raises(mx.MetriplexError, match=r"different numbers of state variables: "
                       r"\{'poisson': 4, 'friction': 3"):
        mx.GenericModel(energy, mx.SumOf((2,)), mx.CanonicalPoisson(4, 1), friction)
    with pytest.raises(mx.MetriplexError, match=r"SumOf\(5,\) names variables outside \[0, 2\]"):
        mx.GenericModel(energy, mx.SumOf((5,)), mx.CanonicalPoisson(3, 1), friction)
    with pytest.raises(mx.MetriplexError, match="poisson must be an AbstractPoisson block"):
        mx.GenericModel(energy, mx.SumOf((2,)), None, friction)


def test_selecting_ids_that_the_data_lack_says_which_ids_there_are():
    data = oscillator_data()
    with pytest.raises(mx.MetriplexError, match=r"none of the ids \[99\] is in these data, whose "
                       r"4 trajectories have ids 0 to 3"):
        data.select([99])
    assert list(data.select([1, 99]).ids) == [1]  # ids the data lack are ignored, as documented


def test_fit_refuses_a_dtype_or_checkpoint_it_cannot_use_before_training(tmp_path):
    data, model = oscillator_data(), small_model()
    for dtype in (jnp.float16, jnp.int32, "complex64"):
        with pytest.raises(mx.MetriplexError, match="dtype= must be float32 or float64"):
            mx.fit(model, data, steps=5, dtype=dtype, progress=False, key=jr.key(0))
    with jax.enable_x64(False), pytest.raises(mx.MetriplexError,
                                              match="dtype=float64 needs JAX's x64 mode"):
        mx.fit(model, data, steps=5, dtype="float64", progress=False, key=jr.key(0))
    # A folder as the checkpoint's file used to fail at the first write, after the training.
    with pytest.raises(mx.MetriplexError, match=r"path must name a file; .* is a folder\. "
                       r"Example: Checkpoint\(.*checkpoint\.ckpt'\)"):
        mx.fit(model, data, steps=5, progress=False, key=jr.key(0),
               checkpoint=mx.Checkpoint(tmp_path))


@pytest.mark.parametrize("pieces,pattern", [
    ([(np.arange(5.0), np.zeros((5, 3))), (np.arange(5.0), np.zeros((5, 4)))],
     "trajectory 0 has 3 and trajectory 1 has 4"),
    ([(np.arange(5.0), np.zeros((6, 3)))], r"shape \(5, n\) for its 5 times; got shape \(6, 3\)"),
    ([(np.arange(5.0), np.zeros((5, 3, 2)))], r"got shape \(5, 3, 2\)"),  # was flattened to 6
    ([np.zeros((5, 3))], r"one \(t, x\) pair per trajectory; item 0 is ndarray \(5, 3\)"),
])
def test_trajectories_from_a_list_of_the_wrong_shape_are_refused(pieces, pattern):
    with pytest.raises(mx.MetriplexError, match=pattern):
        mx.Trajectories.from_list(pieces)


def test_trajectories_from_arrays_of_the_wrong_shape_are_refused():
    with pytest.raises(mx.MetriplexError, match=r"xs \(2, 6, 3\) and ts \(5,\)"):
        mx.Trajectories.from_arrays(np.arange(5.0), np.zeros((2, 6, 3)))
    data = mx.Trajectories.from_arrays(np.arange(6.0), np.zeros((2, 6, 3)))
    assert len(data) == 2 and data.n == 3


def test_a_history_prints_as_a_summary_not_its_lists():
    from metriplex.train import History

    history = History(step=list(range(0, 50_000, 10)), train={"total": [0.1] * 5_000},
                      best_step=4_200, best_valid=1.5e-3, stopped="converged")
    text = repr(history)
    assert len(text) < 300, text  # the lists made 86 KB
    assert "5000 evaluations to step 49990" in text and "best_step=4200" in text


def test_a_block_given_data_of_another_width_is_refused():
    states = np.zeros((5, 4))  # four columns for a three-variable block: accepted before
    with pytest.raises(mx.MetriplexError, match=r"data= must be states of shape \(N, 3\).*got "
                       r"shape \(5, 4\)"):
        mx.MLPPotential(3, data=states, key=jr.key(0))
    # With features, the states are checked before the features read them.
    from metriplex.config import FEATURES

    for block in (mx.MLPPotential, mx.CholeskyFriction):
        with pytest.raises(mx.MetriplexError, match=r"shape \(N, 10\).*got shape \(5, 4\)"):
            block(10, features=FEATURES["pendulum"], data=states, key=jr.key(0))


def test_root_finder_tolerances_below_the_states_rounding_are_refused():
    # Every step failed with "did not converge ... try a smaller time step" (found by the
    # new-user check of the API); float64 states meet the same tolerances.
    from metriplex._model import with_dtype

    model, (t, x) = with_dtype(small_model(), jnp.float32), next(iter(oscillator_data()))
    tight = mx.CrankNicolson(root_finder=mx.Newton(rtol=1e-13, atol=1e-13))
    with pytest.raises(mx.MetriplexError, match=r"rtol=1e-13 and atol=1e-13 are below what "
                       r"float32 states resolve \(2 machine epsilons"):
        mx.simulate(model, jnp.asarray(x[0], jnp.float32), t[:3], scheme=tight)
