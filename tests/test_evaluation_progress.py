"""Progress during evaluation (issue 14): `train`'s evaluation of the validation trajectories
and `evaluate`'s rollouts show a progress bar over batches of trajectories (none with
`--quiet`); the batches give the rollouts of one call, and `evaluate` rolls out once for the
metrics and the figures.

Batches start above `diagnostics.ROLLOUT_BATCH_STATES` states; the tests lower it so that tiny
data are rolled out in several batches. No test trains a model.
"""

import contextlib
import io
import json
import subprocess

import equinox as eqx
import jax.numpy as jnp
import jax.random as jr
import numpy as np
import pytest

import metriplex as mx
from metriplex import _progress, _sensitivity
from metriplex import diagnostics
from metriplex.cli import main
from metriplex.app.config import scheme_from_name
from helpers import damped_oscillator, make_data, oscillator_x0


def run(*args):
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main([str(a) for a in args])
        except SystemExit as e:
            code = e.code
    return subprocess.CompletedProcess(args, code, out.getvalue(), err.getvalue())


def blowing_up_model(rate: float) -> mx.GenericModel:
    """E = rate * q * p: RK4 overflows after a number of steps that depends on the start."""
    energy = mx.MLPPotential(2, width=2, depth=1, quadratic=True, key=jr.key(0))
    energy = eqx.tree_at(lambda e: (e.out.weight, e.out.bias, e.quadratic), energy,
                         (jnp.zeros_like(energy.out.weight), jnp.zeros_like(energy.out.bias),
                          jnp.array([[0.0, rate], [rate, 0.0]])))
    return mx.GenericModel(energy, mx.ZeroPotential(), mx.CanonicalPoisson(2, 1),
                           mx.ZeroFriction(2))


def _rollouts(model, data, scheme, states):
    diagnostics.ROLLOUT_BATCH_STATES = states
    diagnostics.ROLLOUT_BATCHES = 3  # 5 trajectories: 2 + 2 + 1 (padded to 2)
    out, xs, lengths = diagnostics.rollout_data(model, data, scheme=scheme_from_name(scheme))
    return [np.asarray(v) for v in out], xs, lengths


@pytest.mark.parametrize("case", ["oscillator", "failing"])
def test_batches_give_the_rollouts_of_one_call(monkeypatch, case):
    monkeypatch.setattr(diagnostics, "ROLLOUT_BATCH_STATES", diagnostics.ROLLOUT_BATCH_STATES)
    monkeypatch.setattr(diagnostics, "ROLLOUT_BATCHES", diagnostics.ROLLOUT_BATCHES)
    if case == "oscillator":  # ragged: the padded grid repeats each trajectory's last time
        model, scheme = damped_oscillator(), "cn"
        full = make_data(model, oscillator_x0(5), 0.1, 10, names=("q", "p", "s"))
        data = mx.Trajectories.from_list([(t[: 6 + k], x[: 6 + k]) for k, (t, x)
                                          in enumerate(full)], full.names)
    else:  # rollouts that fail at different steps
        model, scheme = blowing_up_model(1e4), "rk4"
        t = np.arange(41) * 0.1
        data = mx.Trajectories.from_list(
            [(t, np.full((41, 2), a)) for a in (1.0, 1e50, 1e100, 1e150, 1e200)], ("q", "p"))
    one, xs, lengths = _rollouts(model, data, scheme, 10**9)
    batched, xs_b, lengths_b = _rollouts(model, data, scheme, 0)
    assert [a.shape for a in batched] == [a.shape for a in one]
    np.testing.assert_array_equal(batched[2], one[2])  # failed_step
    np.testing.assert_allclose(batched[1], one[1], rtol=1e-12, atol=1e-12, equal_nan=True)
    np.testing.assert_array_equal(batched[0], one[0])  # the time grids
    if case == "failing":
        assert len(set(one[2].tolist())) >= 3 and np.all(one[2] > 0), one[2]


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("progress")
    model = damped_oscillator()
    data = make_data(model, oscillator_x0(6), 0.1, 10, names=("q", "p", "s"))
    mx.write(tmp / "data.npz", data)
    (tmp / "run").mkdir()
    learned = mx.GenericModel(mx.MLPPotential(3, width=4, depth=1, key=jr.key(0)),
                              mx.SumOf((2,)), mx.CanonicalPoisson(3, 1), mx.ZeroFriction(3))
    mx.save(tmp / "run" / "model.mpx", learned, n=3, names=data.names)
    return tmp


def test_evaluate_shows_progress_and_rolls_out_once(files, tmp_path, monkeypatch):
    # As in a terminal (the captured stderr is not one), with every frame drawn: at tqdm's
    # own 0.1 s between frames a bar's last one was skipped where the phases ran fast (a warm
    # compilation cache), and the test failed on timing.
    monkeypatch.setattr(_progress, "_terminal", lambda stream=None: True)
    tqdm = _progress.tqdm
    monkeypatch.setattr(_progress, "tqdm",
                        lambda **k: tqdm(**{"mininterval": 0, "miniters": 1, **k}))
    monkeypatch.setattr(diagnostics, "ROLLOUT_BATCH_STATES", 0)
    monkeypatch.setattr(diagnostics, "ROLLOUT_BATCHES", 3)  # 6 trajectories: 2 a batch
    calls = []
    solve = diagnostics.solve
    for module in (diagnostics, _sensitivity):
        monkeypatch.setattr(module, "solve",
                            lambda *a, **k: calls.append(a[2].shape) or solve(*a, **k))
    res = run("evaluate", files / "run", files / "data.npz", "--no-verdict", "--figures",
              tmp_path / "fig", "--out", tmp_path / "m.json")
    assert res.returncode == 0, res.stderr
    assert "rollouts:" in res.stderr and "/6 [" in res.stderr, res.stderr  # a bar of 6
    # and one over what follows them (seconds on large data), naming each phase
    assert "diagnostics:" in res.stderr and "3/3 [" in res.stderr, res.stderr
    assert "structure residuals" in res.stderr, res.stderr
    # Three batches, once for the metrics and the figures together; then the step check's
    # rollout with every interval in four, as four rollouts of the data grid's shape, one
    # after another (the data-grid rollout itself is reused, not repeated); last, the twins
    # from nearby states (initial_state_sensitivity), of the same shape.
    assert calls == [(2, 11)] * 3 + [(6, 11)] * 5, calls
    assert json.loads((tmp_path / "m.json").read_text())["trajectory_ids"] == list(range(6))
    assert (tmp_path / "fig" / "error.png").exists()
    quiet = run("evaluate", files / "run", files / "data.npz", "--no-verdict", "--quiet")
    assert quiet.returncode == 0, quiet.stderr
    # --quiet removes the progress, not what the results say (here that this untrained model
    # does not beat predicting no motion): every line left is such a warning.
    assert all(line.startswith("warning: ") for line in quiet.stderr.splitlines()), quiet.stderr
    assert "rollouts:" not in quiet.stderr and "diagnostics:" not in quiet.stderr
    # rollout too
    res = run("rollout", files / "run", files / "data.npz", "--out", tmp_path / "p.npz")
    assert res.returncode == 0 and "rollouts" in res.stderr, res.stderr
    res = run("rollout", files / "run", files / "data.npz", "--out", tmp_path / "q.npz",
              "--quiet")
    assert res.returncode == 0 and "rollouts" not in res.stderr, res.stderr


def test_bars_written_to_a_file_or_pipe_are_redrawn_rarely(monkeypatch):
    # A log file or a pipe would fill with frames ten times a second: there a bar is redrawn
    # at most every PIPED_INTERVAL seconds, unless the environment says otherwise.
    import io as _io

    monkeypatch.delenv("TQDM_MININTERVAL", raising=False)
    monkeypatch.setattr(_progress, "_terminal", lambda stream=None: False)
    assert _progress.progress_bar(total=1, file=_io.StringIO()).mininterval == \
        _progress.PIPED_INTERVAL
    monkeypatch.setattr(_progress, "_terminal", lambda stream=None: True)
    assert _progress.progress_bar(total=1, file=_io.StringIO()).mininterval < 1
    monkeypatch.setattr(_progress, "_terminal", lambda stream=None: False)
    monkeypatch.setenv("TQDM_MININTERVAL", "0.5")
    assert _progress.progress_bar(total=1, file=_io.StringIO()).mininterval < 1


@pytest.mark.parametrize("quiet", [False, True])
def test_train_shows_progress_while_it_evaluates(files, tmp_path, monkeypatch, quiet):
    """The evaluation after training, with the training itself replaced (it has its own bar)."""
    from metriplex import runs
    from metriplex.train import History

    monkeypatch.setattr(diagnostics, "ROLLOUT_BATCH_STATES", 0)
    monkeypatch.setattr(diagnostics, "ROLLOUT_BATCHES", 3)
    model = mx.load(files / "run")

    def trained(parts, config, out, **kw):
        out.mkdir(parents=True, exist_ok=True)
        history = History(step=[10], stopped="step budget reached", best_step=10)
        data = mx.read(files / "data.npz")
        return model, history, data.select(data.ids[:1]), data.select(data.ids[1:]), 0.1

    # metriplex train splits the data first (runs.RunData), then trains on the parts.
    monkeypatch.setattr(runs, "train_parts", trained)
    options = ["--quiet"] if quiet else []
    res = run("train", files / "data.npz", "--out", tmp_path / "r", "--entropy", "sum:2",
              "--poisson", "canonical:1", *options)
    assert res.returncode == 0, res.stderr
    assert ("rollouts" in res.stderr) is not quiet, res.stderr
    metrics = json.loads((tmp_path / "r" / "metrics.json").read_text())
    assert metrics["trajectory_ids"] == [1, 2, 3, 4, 5]


def test_energy_and_entropy_in_one_pass_are_those_of_one_potential_at_a_time():
    # The metrics and the report compute E and S together (one program to compile): the
    # values must be the bits that each potential alone gives.
    model = mx.GenericModel(mx.MLPPotential(3, width=8, depth=2, key=jr.key(0)),
                            mx.MLPPotential(3, width=8, depth=2, key=jr.key(1)),
                            mx.CanonicalPoisson(3, 1), mx.ZeroFriction(3))
    xs = np.random.default_rng(0).normal(size=(4, 9, 3))
    E, S = diagnostics.energy_entropy_along(model, xs)
    assert E.shape == S.shape == (4, 9) and E.dtype == S.dtype == np.float64
    np.testing.assert_array_equal(E, diagnostics.potential_along(model, model.energy, xs))
    np.testing.assert_array_equal(S, diagnostics.potential_along(model, model.entropy, xs))
    assert not np.array_equal(E, S)
