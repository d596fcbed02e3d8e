"""Tests run in float64 with JAX's strict rank and dtype promotion; warnings are errors."""

import contextlib
import io
import os
import time

os.environ.setdefault("XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1")

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_rank_promotion", "raise")
jax.config.update("jax_numpy_dtype_promotion", "strict")

import matplotlib  # noqa: E402

matplotlib.use("Agg")

import pytest  # noqa: E402

#: Entries of the compilation cache older than this are deleted at the start of a run.
COMPILATION_CACHE_DAYS = 3


def pytest_configure(config):
    """Keep XLA's compiled programs between runs in pytest's cache folder
    (``.pytest_cache/d/jax-compilation-cache``; none with ``-p no:cacheprovider``).

    Compiling is most of the suite's time, and a test compiles the same programs on every run.
    A cache hit returns the executable that compiling the same program gives, so no result
    depends on the cache, nor on which tests ran before. Both xdist workers share it, and so do
    the processes that tests start (through the environment; the benchmark test removes it, as
    it times compilation). An entry read while another process writes it is a miss (see the
    warning filters in pyproject.toml).
    """
    cache = getattr(config, "cache", None)
    if cache is None:
        return
    folder = cache.mkdir("jax-compilation-cache")
    if not hasattr(config, "workerinput"):  # the controller, before any worker starts
        too_old = time.time() - COMPILATION_CACHE_DAYS * 86400
        for entry in folder.iterdir():
            try:
                if entry.stat().st_mtime < too_old:
                    entry.unlink()
            except OSError:
                pass
    jax.config.update("jax_compilation_cache_dir", str(folder))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    os.environ["JAX_COMPILATION_CACHE_DIR"] = str(folder)
    os.environ["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"] = "0"


# -- one training run that the command-line tests share ----------------------------------------

#: The options of the shared run (``trained_run``): 20 steps on 6 of the 8 trajectories, 4 and 5
#: validating.
TRAINED_RUN_OPTIONS = ("--entropy", "sum:2", "--poisson", "canonical:1", "--width", "8",
                       "--steps", "20", "--trajectories", "0-5", "--validation-ids", "4,5",
                       "--quiet")


@pytest.fixture(scope="session")
def trained_run(tmp_path_factory):
    """A folder with ``data.npz`` (``helpers.oscillator_data()``: 8 trajectories of 21 states,
    ids 0-7) and ``run/``, what ``metriplex train data.npz --out run`` with
    TRAINED_RUN_OPTIONS wrote. Tests only read it (they write their outputs elsewhere).

    A training costs a minute of compiling and figures on a busy CPU, so the command-line tests
    that need a run folder share this one; they all go to one xdist worker (see
    ``pytest_collection_modifyitems``), which trains it once.
    """
    from helpers import oscillator_data
    from metriplex.cli import main
    from metriplex.io import write

    folder = tmp_path_factory.mktemp("trained")
    write(folder / "data.npz", oscillator_data())
    err = io.StringIO()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
        code = main(["train", str(folder / "data.npz"), "--out", str(folder / "run"),
                     *TRAINED_RUN_OPTIONS])
    assert code == 0, err.getvalue()
    return folder


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config, items):
    """Tests that share the session's training run go to one xdist worker (``--dist
    loadgroup``, pyproject.toml), which then trains it once, not once per worker."""
    for item in items:
        if "trained_run" in getattr(item, "fixturenames", ()):
            item.add_marker(pytest.mark.xdist_group("trained_run"))
