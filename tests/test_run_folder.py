"""The run folder: one training owns it at a time (a lock that a crashed run does not leave
stuck), files get the user's umask, and a model file's dtype is honoured by every command.

Nothing here waits on a clock: a helper process says when it holds the lock (a line on its
stdout) and dies when told (a line on its stdin).
"""

import contextlib
import io
import json
import os
import re
import signal
import subprocess
import sys
import threading

import jax.numpy as jnp
import jax.random as jr
import numpy as np
import pytest

import metriplex as mx
from metriplex.app import _lock
from metriplex.app._lock import LOCK_NAME, RunFolderInUse, RunLock
from metriplex.cli import main

posix_only = pytest.mark.skipif(os.name != "posix", reason="POSIX locks and signals")


def run(*args):
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main([str(a) for a in args])
        except SystemExit as e:
            code = e.code
    return subprocess.CompletedProcess(args, code, out.getvalue(), err.getvalue())


def data_file(folder):
    t = np.arange(11) * 0.1
    data = mx.Trajectories.from_list(
        [(t, np.c_[np.cos(t + j), -np.sin(t + j), 0.01 * t]) for j in range(3)], ("q", "p", "s"))
    mx.write(folder / "data.npz", data)
    return folder / "data.npz"


HOLDER = """
import os, signal, sys
from metriplex.app._lock import RunLock
RunLock(sys.argv[1]).acquire()
print("holding", flush=True)
sys.stdin.readline()
os.kill(os.getpid(), signal.SIGKILL)  # a crash: no cleanup, the lock file stays behind
"""


@posix_only
def test_one_training_per_folder_and_a_killed_one_does_not_block(tmp_path):
    data = data_file(tmp_path)
    run_dir = tmp_path / "run"
    with subprocess.Popen([sys.executable, "-c", HOLDER, str(run_dir)], text=True,
                          stdin=subprocess.PIPE, stdout=subprocess.PIPE) as holder:
        assert holder.stdout.readline().strip() == "holding"
        owner = json.loads((run_dir / LOCK_NAME).read_text())
        assert owner["pid"] == holder.pid
        (run_dir / "checkpoint.ckpt").write_bytes(b"")
        before = sorted(p.name for p in run_dir.iterdir())
        for extra in ([], ["--overwrite"], ["--resume"]):
            res = run("train", data, "--out", run_dir, "--steps", "1", "--quiet", *extra)
            assert res.returncode == 2, res.stderr
            assert "Traceback" not in res.stderr
            assert re.fullmatch(
                rf"metriplex train: error: run folder '.*run' is in use by another training "
                rf"\(process {holder.pid} on host .*\); a run folder is written by one training "
                rf"at a time\. Wait for it to end, or choose another --out\. If no training runs "
                rf"there any more, delete '.*{re.escape(LOCK_NAME)}'\.\n", res.stderr), res.stderr
        res = run("reproduce", "rigid-body", "--quick", "--out", run_dir, "--overwrite")
        assert res.returncode == 2 and "is in use by another training" in res.stderr, res.stderr
        assert sorted(p.name for p in run_dir.iterdir()) == before
        holder.stdin.write("die\n")  # leaving the with-block closes the pipes and waits
    assert holder.returncode == -signal.SIGKILL
    assert (run_dir / LOCK_NAME).exists()  # left behind by the crash...
    # ...and taken over, with a note, by the next training (which then stops for another
    # reason: --resume finds no config.json; no training is needed to see the lock change hands).
    res = run("train", data, "--out", run_dir, "--resume", "--quiet")
    assert res.returncode == 2, res.stderr
    note, error = res.stderr.strip().splitlines()
    assert re.fullmatch(rf"note: took over the lock of run folder '.*run' from process "
                        rf"{holder.pid} on host .*, which is no longer running \(it crashed or "
                        r"was killed; its files there may be incomplete\)\.", note), note
    assert "cannot resume" in error and "config.json' is missing" in error
    assert not (run_dir / LOCK_NAME).exists()  # released when the command ended
    with RunLock(run_dir) as lock:
        assert lock.note is None


def test_threads_and_nesting(tmp_path):
    folder = tmp_path / "run"
    errors = []

    def other_thread():
        try:
            with RunLock(folder):
                pass
        except RunFolderInUse as e:
            errors.append(str(e))

    with RunLock(folder) as outer:
        assert outer.held and (folder / LOCK_NAME).exists()
        with RunLock(folder) as inner:  # the same thread: nested, e.g. cli around train_run
            assert inner.held and inner.note is None
        assert (folder / LOCK_NAME).exists()  # the inner release kept the outer hold
        t = threading.Thread(target=other_thread)
        t.start()
        t.join()
        assert len(errors) == 1 and f"process {os.getpid()} on host" in errors[0], errors
    assert not (folder / LOCK_NAME).exists()
    t = threading.Thread(target=other_thread)
    t.start()
    t.join()
    assert len(errors) == 1  # free again
    assert sorted(p.name for p in folder.iterdir()) == []


def _dead_pid():
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


@pytest.mark.parametrize("os_locks", [True, False])
def test_stale_lock_file(tmp_path, monkeypatch, os_locks):
    """A lock file whose process is gone is taken over, with or without OS locks (without them,
    by the process id, on this host only)."""
    if not os_locks:
        monkeypatch.setattr(_lock, "_os_lock", lambda fd: None)
    folder = tmp_path / "run"
    folder.mkdir()
    pid = _dead_pid()
    (folder / LOCK_NAME).write_text(json.dumps(
        {"pid": pid, "host": _lock.socket.gethostname(), "started": "then", "command": "x"}))
    with RunLock(folder) as lock:
        assert lock.note is not None and f"from process {pid} on host" in lock.note
        assert json.loads((folder / LOCK_NAME).read_text())["pid"] == os.getpid()
    assert not (folder / LOCK_NAME).exists()


@pytest.mark.parametrize("owner", ["alive here", "elsewhere"])
def test_without_os_locks_a_live_or_remote_owner_holds(tmp_path, monkeypatch, owner):
    monkeypatch.setattr(_lock, "_os_lock", lambda fd: None)
    folder = tmp_path / "run"
    folder.mkdir()
    host = _lock.socket.gethostname() if owner == "alive here" else "another-host"
    (folder / LOCK_NAME).write_text(json.dumps({"pid": os.getppid(), "host": host}))
    before = (folder / LOCK_NAME).read_text()
    with pytest.raises(RunFolderInUse, match=rf"in use by another training \(process "
                                             rf"{os.getppid()} on host {host}"):
        RunLock(folder).acquire()
    assert (folder / LOCK_NAME).read_text() == before


def test_files_get_the_users_umask(tmp_path):
    from metriplex import _checkpoint
    from metriplex.io import write_json

    data = mx.Trajectories.from_list([(np.arange(3.0), np.ones((3, 2)))], ("a", "b"))
    model = mx.GenericModel(mx.SumOf((0,)), mx.ZeroPotential(), mx.CanonicalPoisson(2, 1),
                            mx.ZeroFriction(2))
    for mask in (0o027, 0o002):
        previous = os.umask(mask)
        try:
            folder = tmp_path / oct(mask)
            for suffix in (".npz", ".csv", ".h5", ".mat"):
                mx.write(folder / f"data{suffix}", data)
            mx.save(folder / "model.mpx", model, n=2)
            write_json(folder / "metrics.json", {"a": 1.0})
            _checkpoint.save(folder / "checkpoint.ckpt", {"w": jnp.ones(2)}, {"step": 1})
        finally:
            os.umask(previous)
        modes = {p.name: p.stat().st_mode & 0o777 for p in folder.iterdir()}
        assert len(modes) == 7, modes  # no temporary file left behind
        assert set(modes.values()) == {0o666 & ~mask}, {k: oct(v) for k, v in modes.items()}


def test_a_float64_model_is_read_as_float64_without_x64_in_the_environment(tmp_path):
    """The model file says float64: rollout enables x64 itself (was: "enable jax_enable_x64")."""
    from metriplex._model import with_dtype

    data = mx.read(data_file(tmp_path))
    model = mx.GenericModel(mx.MLPPotential(3, width=4, depth=1, key=jr.key(1)),
                            mx.SumOf((2,)), mx.CanonicalPoisson(3, 1), mx.ZeroFriction(3))
    model = with_dtype(model, jnp.float64)
    (tmp_path / "run").mkdir()
    mx.save(tmp_path / "run" / "model.mpx", model, n=3, names=data.names)
    env = {k: v for k, v in os.environ.items() if k != "JAX_ENABLE_X64"}
    res = subprocess.run([sys.executable, "-m", "metriplex", "rollout", str(tmp_path / "run"),
                          str(tmp_path / "data.npz"), "--out", str(tmp_path / "pred.npz"),
                          "--scheme", "rk4"], capture_output=True, text=True, env=env,
                         timeout=300)
    assert res.returncode == 0, res.stderr
    assert "x64" not in res.stderr
    pred = mx.read(tmp_path / "pred.npz")
    ts, xs, _ = data.padded()
    here = mx.solve(model, jnp.asarray(xs[:, 0]), jnp.asarray(ts), scheme=mx.RK4())
    # float32 would differ at ~1e-7; float64 agrees to rounding
    np.testing.assert_allclose(pred.x, np.asarray(here.xs).reshape(-1, 3), rtol=1e-12,
                               atol=1e-13)


@posix_only
@pytest.mark.parametrize("held", [False, True])
def test_another_users_lock_file(tmp_path, monkeypatch, held):
    """A lock file this user may not write (another user's, in a shared folder): refused while
    its owner holds it, removed and replaced when stale."""
    import fcntl

    folder = tmp_path / "run"
    folder.mkdir()
    lock = folder / LOCK_NAME
    lock.write_text(json.dumps({"pid": 4242, "host": "elsewhere"}))
    holder = os.open(lock, os.O_RDONLY)
    if held:
        fcntl.flock(holder, fcntl.LOCK_EX)
    real_open = os.open

    def open_(path, flags, *args, **kw):
        if str(path) == str(lock) and flags & os.O_ACCMODE == os.O_RDWR \
                and not flags & os.O_CREAT:
            raise PermissionError(13, "Permission denied", str(path))
        return real_open(path, flags, *args, **kw)

    monkeypatch.setattr(_lock.os, "open", open_)
    try:
        if held:
            with pytest.raises(RunFolderInUse, match=r"process 4242 on host elsewhere"):
                RunLock(folder).acquire()
            assert json.loads(lock.read_text())["pid"] == 4242
        else:
            with RunLock(folder) as taken:
                assert "from process 4242 on host elsewhere" in taken.note
                assert json.loads(lock.read_text())["pid"] == os.getpid()
            assert not lock.exists()
    finally:
        os.close(holder)
