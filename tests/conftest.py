"""Tests run in float64 with JAX's strict rank and dtype promotion; warnings are errors."""

import contextlib
import io
import os
import shutil
import tempfile
import time

os.environ.setdefault("XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1")
# Compiling is most of the suite's time, and the tests' programs are small and short: XLA's
# backend optimisations (LLVM at -O0, no expensive passes) cost more than they save. They change
# no semantics (no fast math either way). Inherited by the processes that tests start; set
# JAX_DISABLE_MOST_OPTIMIZATIONS=0 to test the optimised programs.
os.environ.setdefault("JAX_DISABLE_MOST_OPTIMIZATIONS", "1")

import jax  # noqa: E402

jax.config.update("jax_disable_most_optimizations",
                  os.environ["JAX_DISABLE_MOST_OPTIMIZATIONS"].lower() not in ("0", "false"))
jax.config.update("jax_enable_x64", True)
jax.config.update("jax_numpy_rank_promotion", "raise")
jax.config.update("jax_numpy_dtype_promotion", "strict")

import matplotlib  # noqa: E402

matplotlib.use("Agg")

import pytest  # noqa: E402

#: Entries of the compilation cache older than this are deleted at the start of a run.
COMPILATION_CACHE_DAYS = 3
#: Where the controller tells the xdist workers its compilation cache for this run (without
#: pytest's cache folder, ``-p no:cacheprovider``).
RUN_CACHE_VARIABLE = "METRIPLEX_TESTS_RUN_JAX_CACHE"


def pytest_configure(config):
    """Keep XLA's compiled programs between runs in pytest's cache folder
    (``.pytest_cache/d/jax-compilation-cache``); with ``-p no:cacheprovider``, for this run
    only, in a temporary folder that the run removes at its end (it starts cold, as on a fresh
    clone), unless ``JAX_COMPILATION_CACHE_DIR`` names one. ``JAX_ENABLE_COMPILATION_CACHE=0``
    turns caching off.

    Compiling is most of the suite's time, and a test compiles the same programs on every run.
    A cache hit returns the executable that compiling the same program gives, so no result
    depends on the cache, nor on which tests ran before. Both xdist workers share it, and so do
    the processes that tests start (through the environment; the benchmark test removes it, as
    it times compilation): within one run, these compile many of the programs that another
    process has compiled already. An entry read while another process writes it is a miss (see
    the warning filters in pyproject.toml).
    """
    if os.environ.get("JAX_ENABLE_COMPILATION_CACHE", "1").lower() in ("0", "false"):
        return
    cache = getattr(config, "cache", None)
    if cache is not None:
        folder = cache.mkdir("jax-compilation-cache")
        if not hasattr(config, "workerinput"):  # the controller, before any worker starts
            too_old = time.time() - COMPILATION_CACHE_DAYS * 86400
            for entry in folder.iterdir():
                try:
                    if entry.stat().st_mtime < too_old:
                        entry.unlink()
                except OSError:
                    pass
    elif hasattr(config, "workerinput"):  # the controller's folder for this run
        folder = os.environ.get(RUN_CACHE_VARIABLE)
        if folder is None:
            return
    elif "JAX_COMPILATION_CACHE_DIR" in os.environ:  # the user's own cache
        return
    else:  # the controller, or a run without xdist: a folder for this run
        folder = tempfile.mkdtemp(prefix="metriplex-tests-jax-cache-")
        os.environ[RUN_CACHE_VARIABLE] = folder
        config.add_cleanup(lambda: shutil.rmtree(folder, ignore_errors=True))
    jax.config.update("jax_compilation_cache_dir", str(folder))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    os.environ["JAX_COMPILATION_CACHE_DIR"] = str(folder)
    os.environ["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"] = "0"


# -- one training run that the command-line tests share ----------------------------------------

@pytest.fixture(scope="session")
def trained_run(tmp_path_factory):
    """A folder with ``data.npz`` (``helpers.oscillator_data()``: 8 trajectories of 21 states,
    ids 0-7) and ``run/``, what ``metriplex train data.npz --out run`` with
    ``helpers.TRAINED_RUN_OPTIONS`` wrote. Tests only read it (their outputs go elsewhere).

    A training costs a minute of compiling and figures on a busy CPU, so the command-line tests
    that need a run folder share this one; they all go to one xdist worker (SHARED_TRAININGS),
    which trains it once.
    """
    from helpers import TRAINED_RUN_OPTIONS, oscillator_data
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


# -- one cosine-schedule training with an L-BFGS finish ----------------------------------------

#: The run of ``cosine_lbfgs_run``: 300 Adam steps on a cosine schedule, then 100 L-BFGS
#: iterations, evaluated every 50. One stage: with a first stage (the default here since
#: 2026-11-27) the Adam stage ends elsewhere, and seed 0's finish then lowered the loss to
#: 0.61 of Adam's instead of 0.33; the first stage has tests of its own.
COSINE_LBFGS_CONFIG = dict(entropy="sum:2", poisson="canonical:1", width=8, steps=300,
                           eval_every=50, schedule="cosine", float64=True, lbfgs_steps=100,
                           reversible_first=False)


@pytest.fixture(scope="session")
def cosine_lbfgs_run(tmp_path_factory):
    """``(config, history)`` of ``train_run`` with COSINE_LBFGS_CONFIG on
    ``make_data(damped_oscillator(), oscillator_x0(6), 0.1, 20)``: its Adam stage is the cosine
    schedule's test (test_schedule.py), its finish the L-BFGS test (test_lbfgs.py)."""
    from helpers import damped_oscillator, make_data, oscillator_x0
    from metriplex.config import RunConfig
    from metriplex.runs import train_run

    data = make_data(damped_oscillator(), oscillator_x0(6), 0.1, 20, names=("q", "p", "s"))
    config = RunConfig(**COSINE_LBFGS_CONFIG)
    _, history, *_ = train_run(data, config, tmp_path_factory.mktemp("cosine") / "run",
                               progress=False)
    return config, history


# -- how xdist hands out the tests -------------------------------------------------------------
#
# Most of the suite's time is compiling, and a worker compiles a program once: the tests of a
# file share their module fixtures, caches and compiled functions when they run on one worker.
# So with ``-n`` a file's tests go to one worker together (as with ``--dist loadfile``), and so
# do the tests of a session training (SHARED_TRAININGS), which is then trained once; the tests
# of SPLIT_FILES, long and independent, are handed out one by one. The long work goes first
# (LONG_FIRST), so that the workers do not end waiting on one long file.

#: The session fixtures that train, with the tests that use them (nodeid prefixes).
SHARED_TRAININGS = {
    "trained_run": ("tests/test_cli.py::", "tests/test_rollout_ids.py::",
                    "tests/test_trajectory_selection.py::",
                    "tests/test_train.py::test_cli_divergence_keeps_the_best_model",
                    "tests/test_repeats.py::test_a_run_trains_again"),
    "cosine_lbfgs_run": ("tests/test_lbfgs.py::", "tests/test_schedule.py::"),
}

#: Files whose tests are scheduled one by one (each long, nothing shared between them).
SPLIT_FILES = ("tests/test_train.py",)

#: Nodeid prefixes of the long work (measured time on the 2-core VM, 2026-11-29), longest
#: first, so that no long scope is handed out last; order only: what is not listed follows in
#: collection order.
LONG_FIRST = (
    "tests/test_reversible_first.py::",
    "tests/test_local_blocks.py::",
    "tests/test_experiments.py::test_experiment_pipeline_writes_everything",
    "tests/test_integrate.py::",
    "tests/test_cli.py::",  # the trained_run group
    "tests/test_results.py::",
    "tests/test_train.py::test_resume_after_sigkill_matches_uninterrupted_run",
    "tests/test_discrete_gradient.py::",
    "tests/test_verdict.py::",
    "tests/test_train.py::test_ctrl_c_in_train_saves_a_checkpoint_and_the_run_resumes",
    "tests/test_pair_store.py::",
    "tests/test_starts.py::",
    "tests/test_readme.py::",
    "tests/test_units.py::",
    "tests/test_systems.py::",
    "tests/test_exact_structure.py::",
    "tests/test_constant_variables.py::",
    "tests/test_exchange_friction.py::",
    "tests/test_confinement.py::",
    "tests/test_plots.py::",
    "tests/test_zoo_a.py::",
    "tests/test_evaluation_progress.py::",
    "tests/test_zoo_b.py::",
    "tests/test_losses.py::",
    "tests/test_structure.py::",
    "tests/test_run_folder.py::",
    "tests/test_lbfgs.py::",  # the cosine_lbfgs_run group
    "tests/test_train.py::test_divergence_is_reported_and_best_model_kept",
    "tests/test_train.py::test_ctrl_c_saves_a_checkpoint_and_the_run_resumes",
)


def _shared_training(nodeid: str) -> str | None:
    for fixture, prefixes in SHARED_TRAININGS.items():
        if nodeid.startswith(prefixes):
            return fixture
    return None


def _scope(nodeid: str) -> str:
    """The unit of work that one worker runs: a shared training's tests, one test of
    SPLIT_FILES, or a file."""
    path = nodeid.split("::", 1)[0]
    return _shared_training(nodeid) or (nodeid if path in SPLIT_FILES else path)


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config, log):
    """With ``-n`` (xdist's ``load``): the scopes of ``_scope``, handed out in the workers'
    collection order (``pytest_collection_modifyitems``). (xdist's ``--dist loadgroup`` would
    group by ``xdist_group`` marks, but xdist 3.8 cannot rename pytest 9's node ids.)"""
    if config.getvalue("dist") != "load":
        return None
    from xdist.scheduler import LoadScopeScheduling

    class SharedWorkScheduling(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            return _scope(nodeid)

    # In collection order, not by the number of tests in a scope.
    config.option.loadscopereorder = False
    return SharedWorkScheduling(config, log)


def _rank(item) -> int:
    ranks = [i for i, prefix in enumerate(LONG_FIRST) if _scope(prefix) == _scope(item.nodeid)]
    return min(ranks, default=len(LONG_FIRST))


def pytest_collection_modifyitems(config, items):
    """A test that uses a shared training must be listed with it in SHARED_TRAININGS. In an
    xdist worker, the scopes of LONG_FIRST come first (every worker orders its collection
    alike, and the scheduler hands the scopes out in that order)."""
    if hasattr(config, "workerinput"):
        items.sort(key=_rank)  # stable: collection order otherwise
    for item in items:
        for fixture in SHARED_TRAININGS:
            if (fixture in getattr(item, "fixturenames", ())
                    and _shared_training(item.nodeid) != fixture):
                raise pytest.UsageError(
                    f"{item.nodeid} uses the session fixture {fixture!r}: add it to "
                    "SHARED_TRAININGS in tests/conftest.py, so that the tests sharing that "
                    "training run on one xdist worker"
                )
