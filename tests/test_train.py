"""Training: fit recovers known dynamics; validation is split by trajectory; resume; divergence."""

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np
import optax
import pytest

import metriplex as mx
from helpers import (TRAINED_RUN_OPTIONS, damped_oscillator, make_data, oscillator_x0, rigid_body,
                     rigid_x0)

ROOT = Path(__file__).resolve().parents[1]


def _rollout_error(model, data):
    return mx.diagnostics.evaluate(model, data)["rollout_error_mean"]


@eqx.filter_jit
def _fields(model, xs):
    """The model's vector field at the states ``xs``, one compiled call (op by op, each
    operation of the model would compile on its own)."""
    return jax.vmap(model.vector_field)(xs)


# 2000 steps of a width-32 model: an accuracy run (about 40 CPU-s, most of it training). The
# default run keeps the check that a short fit learns in
# test_units.py::test_training_is_the_same_in_other_units (validation loss down 20x in 300 steps).
@pytest.mark.slow
def test_fit_learns_damped_oscillator_far_better_than_untrained():
    # 24 training trajectories of 40 steps and 3 test trajectories of 60 steps from other
    # initial states, simulated together (one compiled rollout of the true model, not two).
    ts = np.arange(61) * 0.1
    x0 = np.concatenate([oscillator_x0(24), oscillator_x0(3, seed=9)])
    xs = np.asarray(mx.simulate(damped_oscillator(), jnp.asarray(x0), jnp.asarray(ts)))
    data = mx.Trajectories.from_arrays(ts[:41], xs[:24, :41], ("q", "p", "s"))
    test = mx.Trajectories.from_arrays(ts, xs[24:], ("q", "p", "s"))
    k = jr.split(jr.key(0), 2)
    model = mx.GenericModel(
        mx.MLPPotential(3, width=32, data=data.x, key=k[0]),
        mx.SumOf((2,)),
        mx.CanonicalPoisson(3, 1),
        mx.CholeskyFriction(3, width=32, key=k[1]),
    )
    before = _rollout_error(model, test)
    loss = mx.CrankNicolsonResidual() + 10.0 * mx.FrictionDegeneracy()
    trained, history = mx.fit(model, data, loss=loss, steps=2000, batch_size=256,
                              learning_rate=1e-2, progress=False, key=jr.key(1))
    after = _rollout_error(trained, test)
    # A short budget on 24 short trajectories; longer training goes on improving (see README).
    assert after < 0.05, after
    assert after < before / 10, (before, after)
    assert history.train["residual"][-1] < history.train["residual"][0] / 100
    assert set(history.valid) >= {"residual", "degeneracy_M", "total"}
    assert history.best_step > 0


def test_validation_is_split_by_trajectory():
    data = make_data(rigid_body(), rigid_x0(10), 0.1, 5)
    train, valid = data.split(0.2, seed=0)
    assert len(valid) == 2 and len(train) == 8
    assert not set(train.ids) & set(valid.ids)
    assert len(train.pairs()) + len(valid.pairs()) == len(data.pairs())


def test_fit_rejects_bad_input():
    model = mx.GenericModel(mx.MLPPotential(3, width=4, key=jr.key(0)), mx.ZeroPotential(),
                            mx.SkewMLPPoisson(3, width=4, key=jr.key(1)), mx.ZeroFriction(3))
    data = make_data(rigid_body(), rigid_x0(2), 0.1, 5)
    wide = mx.Trajectories(data.trajectory, data.t, np.c_[data.x, data.x[:, :1]])
    with pytest.raises(mx.MetriplexError, match="data have 4 state variables but the model expects 3"):
        mx.fit(model, wide, steps=1, progress=False, key=jr.key(0))
    with pytest.raises(mx.MetriplexError, match="every dt must be finite and > 0"):
        p = data.pairs()
        mx.fit(model, (p.x0, p.x1, -p.dt), steps=1, progress=False, key=jr.key(0))
    with pytest.raises(mx.MetriplexError, match="need steps >= 0"):
        mx.fit(model, data, steps=-1, progress=False, key=jr.key(0))


def test_divergence_is_reported_and_best_model_kept():
    truth = damped_oscillator()
    data = make_data(truth, oscillator_x0(6), 0.1, 30)
    model = mx.GenericModel(mx.MLPPotential(3, width=8, key=jr.key(0)), mx.SumOf((2,)),
                            mx.CanonicalPoisson(3, 1), mx.CholeskyFriction(3, width=8, key=jr.key(1)))
    # Without held-out rollouts (the best model is then the one of the lowest validation
    # loss): none is compiled for the one evaluation before the divergence. The CLI test below
    # diverges with them.
    with pytest.raises(mx.TrainingDiverged, match=r"training diverged at step \d+.*non-finite") as e:
        mx.fit(model, data, optimizer=optax.sgd(1e12), steps=300, eval_every=10,
               rollout_check=None, progress=False, key=jr.key(0))
    best = e.value.model
    assert best is not None
    x = jnp.asarray(data.x[:5])
    assert np.all(np.isfinite(np.asarray(_fields(best, x))))


# The interrupted run: `metriplex train` whose process SIGKILLs itself right after its first
# stage (--reversible-first, on by default for RUN_OPTS) writes its checkpoint at step KILL_AT
# (of STEPS): a real kill in mid-run (no cleanup, the lock left behind, no model), at a step
# fixed in advance rather than after a guessed sleep.
STEPS, KILL_AT = 400, 200
KILLED_TRAIN = textwrap.dedent(
    f"""
    import os, signal, sys
    import metriplex._checkpoint as checkpoint
    from metriplex.cli import main

    write = checkpoint.save

    def write_then_die(path, tree, meta):
        write(path, tree, meta)
        if os.path.basename(path) == "first-stage.ckpt" and meta["done"] >= {KILL_AT}:
            os.kill(os.getpid(), signal.SIGKILL)

    checkpoint.save = write_then_die
    sys.exit(main(sys.argv[1:]))
    """
)

#: The runs of the resume and Ctrl-C tests: the same data and options, so that they compile the
#: same programs (shared through the suite's compilation cache, see conftest.py).
RUN_OPTS = ["--entropy", "sum:2", "--poisson", "canonical:1", "--eval-every", "50",
            "--checkpoint-every", "1", "--width", "8", "--batch-size", "64", "--float64"]


def _run_data(tmp_path):
    data = make_data(damped_oscillator(), oscillator_x0(6), 0.1, 40)
    mx.write(tmp_path / "d.npz", data)
    return data


def _checkpoint_step(path) -> int:
    with open(path, "rb") as f:
        f.readline()  # the magic line
        return json.loads(f.readline())["done"]


def test_resume_after_sigkill_matches_uninterrupted_run(tmp_path, monkeypatch, capsys):
    """Killed in the first stage, then interrupted in the main one: each resumed from its own
    checkpoint, the run ends with the model and history of the uninterrupted one."""
    from metriplex._fit_loop import FitLoop
    from metriplex.config import RunConfig
    from metriplex.runs import train_run

    data = _run_data(tmp_path)
    opts = [*RUN_OPTS, "--steps", str(STEPS), "--quiet"]
    # Only the interrupted run needs a process of its own (to be killed); the uninterrupted run
    # and the resumed one run here. The killed process compiles the programs that this one
    # does: a compilation cache (the suite's, see conftest.py, else one in this test's folder)
    # spares it the compiling; results do not depend on it.
    env = dict(os.environ)
    if "JAX_COMPILATION_CACHE_DIR" not in env:
        env.update(JAX_COMPILATION_CACHE_DIR=str(tmp_path / "jax-cache"),
                   JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS="0")
    # The uninterrupted run is the training that `train` runs (RUN_OPTS, as a RunConfig; checked
    # against the killed run's config.json below), without the evaluation and figures after it.
    full = RunConfig(entropy="sum:2", poisson="canonical:1", eval_every=50, checkpoint_every=1,
                     width=8, batch_size=64, float64=True, steps=STEPS)
    train_run(data, full, tmp_path / "full", progress=False)
    assert not list((tmp_path / "full").glob("first-stage*"))  # removed when the run ends
    cut = subprocess.run([sys.executable, "-c", KILLED_TRAIN, "train", str(tmp_path / "d.npz"),
                          "--out", str(tmp_path / "cut"), *opts],
                         capture_output=True, text=True, env=env, timeout=600)
    assert cut.returncode == -signal.SIGKILL, (cut.returncode, cut.stderr)
    assert not (tmp_path / "cut" / "model.mpx").exists(), "the run finished before the kill"
    assert not (tmp_path / "cut" / "checkpoint.ckpt").exists(), "killed after the first stage"
    assert _checkpoint_step(tmp_path / "cut" / "first-stage.ckpt") == KILL_AT
    assert (json.loads((tmp_path / "cut" / "config.json").read_text())["config"]
            == json.loads((tmp_path / "full" / "config.json").read_text())["config"])
    # Resumed here by the training that `train --resume` runs (its command line's resume:
    # test_ctrl_c_in_train_saves_a_checkpoint_and_the_run_resumes), without the evaluation
    # and figures after it; interrupted in the main stage right after the chunk of steps that
    # ends at KILL_AT, before its evaluation: where a Ctrl-C pressed during a chunk stops the
    # loop (its evaluation is then made by the resumed run, so the history misses no step).
    chunk, pressed = FitLoop.next_chunk, []

    def chunk_then_interrupt(self):
        chunk(self)
        if Path(self.checkpoint.path).name == "checkpoint.ckpt" and self.state.done == KILL_AT \
                and not pressed:
            pressed.append(KILL_AT)
            raise KeyboardInterrupt

    monkeypatch.setattr(FitLoop, "next_chunk", chunk_then_interrupt)
    _, h, *_ = train_run(data, full, tmp_path / "cut", resume=True, progress=False)
    assert h.stopped == f"interrupted at step {KILL_AT}" and KILL_AT not in h.step
    assert _checkpoint_step(tmp_path / "cut" / "checkpoint.ckpt") == KILL_AT
    monkeypatch.setattr(FitLoop, "next_chunk", chunk)
    train_run(data, full, tmp_path / "cut", resume=True, progress=False)
    assert "resuming training 1 from its checkpoint at step 200" in capsys.readouterr().err
    a = mx.load(tmp_path / "full")
    b = mx.load(tmp_path / "cut")
    x = jnp.asarray(data.x[:10])
    fa, fb = np.asarray(_fields(a, x)), np.asarray(_fields(b, x))
    np.testing.assert_allclose(fa, fb, rtol=1e-9, atol=1e-12)
    ha = json.loads((tmp_path / "full" / "history.json").read_text())
    hb = json.loads((tmp_path / "cut" / "history.json").read_text())
    assert ha["step"] == hb["step"] and ha["step"][-1] == STEPS
    np.testing.assert_allclose(ha["valid"]["total"], hb["valid"]["total"], rtol=1e-9)
    assert not list((tmp_path / "cut").glob("first-stage*"))


def test_ctrl_c_in_train_saves_a_checkpoint_and_the_run_resumes(tmp_path, monkeypatch, capsys):
    """Ctrl-C pressed during `metriplex train`, in this process: the command's own handling
    (exit status 130, what it says, the checkpoint, model and history it keeps, the resumed run
    continuing that history). The press is sent right after the main training's first
    checkpoint is written, so the run is inside its training loop (a kill in the first stage:
    test_resume_after_sigkill_matches_uninterrupted_run). The same through a real process and an
    asynchronous signal: ``test_ctrl_c_saves_a_checkpoint_and_the_run_resumes`` (slow); the
    handler itself: tests/test_interrupt.py."""
    import metriplex._checkpoint as checkpoint
    from metriplex.cli import main

    _run_data(tmp_path)
    write, pressed = checkpoint.save, []

    def write_then_press(path, tree, meta):
        write(path, tree, meta)
        if not pressed and Path(path).name == "checkpoint.ckpt":  # in the main training
            pressed.append(meta["done"])
            os.kill(os.getpid(), signal.SIGINT)

    monkeypatch.setattr(checkpoint, "save", write_then_press)
    # pytest-xdist workers ignore SIGINT; a terminal's Python has the default handler. The
    # first run's cap of 5 minutes only keeps a broken interrupt from hanging the suite.
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        code = main(["train", str(tmp_path / "d.npz"), "--out", str(tmp_path / "run"),
                     *RUN_OPTS, "--steps", "50000000", "--quiet", "--max-minutes", "5"])
    finally:
        signal.signal(signal.SIGINT, previous)
    err = capsys.readouterr().err
    assert code == 130, err
    assert len(pressed) == 1  # pressed once, after the first checkpoint
    assert "interrupted" in err and "--resume" in err and "Traceback" not in err
    assert (tmp_path / "run" / "checkpoint.ckpt").exists()
    assert (tmp_path / "run" / "model.mpx").exists()
    h = json.loads((tmp_path / "run" / "history.json").read_text())
    assert h["stopped"].startswith("interrupted at step") and len(h["step"]) >= 1
    monkeypatch.setattr(checkpoint, "save", write)
    assert main(["train", str(tmp_path / "d.npz"), "--out", str(tmp_path / "run"), *RUN_OPTS,
                 "--steps", "50000000", "--quiet", "--resume", "--max-minutes", "0.001"]) == 0
    resumed = json.loads((tmp_path / "run" / "history.json").read_text())
    assert resumed["step"][:len(h["step"])] == h["step"]  # the interrupted history, continued
    assert resumed["step"][-1] > h["step"][-1]
    assert resumed["stopped"].startswith("time budget reached"), resumed["stopped"]


@pytest.mark.slow
def test_ctrl_c_saves_a_checkpoint_and_the_run_resumes(tmp_path):
    _run_data(tmp_path)
    opts = [*RUN_OPTS, "--steps", "50000000"]
    # pytest-xdist workers ignore SIGINT, and a child inherits an ignored signal: start the
    # training process with the default disposition, so it gets Python's KeyboardInterrupt as
    # in a terminal.
    previous = signal.signal(signal.SIGINT, signal.SIG_DFL)
    try:
        proc = subprocess.Popen([sys.executable, "-m", "metriplex", "train",
                                 str(tmp_path / "d.npz"), "--out", str(tmp_path / "run"), *opts,
                                 "--quiet"],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    finally:
        signal.signal(signal.SIGINT, previous)
    # The first checkpoint is written after the first evaluation: from then on the run is
    # inside the training loop, however slow the machine (no sleeping on a guess).
    ckpt = tmp_path / "run" / "checkpoint.ckpt"
    deadline = time.time() + 300
    while time.time() < deadline and not (ckpt.exists() and ckpt.stat().st_size > 0):
        assert proc.poll() is None, proc.communicate()
        time.sleep(0.1)
    proc.send_signal(signal.SIGINT)
    try:
        _, err = proc.communicate(timeout=300)
    except subprocess.TimeoutExpired:
        proc.kill()
        raise
    assert proc.returncode == 130, err
    assert "interrupted" in err and "--resume" in err and "Traceback" not in err
    assert (tmp_path / "run" / "checkpoint.ckpt").exists()
    assert (tmp_path / "run" / "model.mpx").exists()
    h = json.loads((tmp_path / "run" / "history.json").read_text())
    assert h["stopped"].startswith("interrupted at step") and len(h["step"]) >= 1
    # The run resumes with the same options; only the wall-time cap may change, so that this
    # step budget of 5e7 ends at once (the budget counts the interrupted run's time too).
    res = subprocess.run([sys.executable, "-m", "metriplex", "train", str(tmp_path / "d.npz"),
                          "--out", str(tmp_path / "run"), *opts, "--quiet", "--resume",
                          "--max-minutes", "0.001"], capture_output=True, text=True,
                         timeout=600)
    assert res.returncode == 0, res.stderr
    resumed = json.loads((tmp_path / "run" / "history.json").read_text())
    assert resumed["step"][:len(h["step"])] == h["step"]  # the interrupted history, continued
    assert resumed["step"][-1] > h["step"][-1]
    assert resumed["stopped"].startswith("time budget reached"), resumed["stopped"]


def test_cli_divergence_keeps_the_best_model(trained_run, tmp_path):
    from metriplex.cli import main

    # The data and options of the session's shared run (tests/conftest.py), whose worker has
    # compiled its rollouts and model already; here with a learning rate that diverges at once.
    # Two trainings, not the default's four: the second from another initialisation diverges
    # too, and the run keeps the best model of either (each training costs seconds here).
    data = mx.read(trained_run / "data.npz")
    options = list(TRAINED_RUN_OPTIONS)
    options[options.index("--steps") + 1] = "400"
    code = main(["train", str(trained_run / "data.npz"), "--out", str(tmp_path / "run"),
                 *options, "--lr", "1e12", "--eval-every", "20", "--repeats", "2"])
    assert code == 2
    assert (tmp_path / "run" / "model.mpx").exists()
    h = json.loads((tmp_path / "run" / "history.json").read_text())
    assert h["stopped"].startswith("diverged at step")
    model = mx.load(tmp_path / "run")
    f = np.asarray(model.vector_field(jnp.asarray(data.x[0], jnp.float32)))
    assert np.all(np.isfinite(f))
