"""The benchmark suite must keep running: `benchmarks/run.py --quick` in a subprocess.

No timing is asserted (the machines are shared and noisy); only that the suite exits 0, prints
its tables and writes its JSON.
"""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow
def test_benchmark_suite_quick(tmp_path):
    # The suite's own settings: its thread pinning, optimised programs, and no compilation cache
    # (it times compiling).
    env = {k: v for k, v in os.environ.items()
           if k not in ("XLA_FLAGS", "JAX_COMPILATION_CACHE_DIR",
                        "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS",
                        "JAX_DISABLE_MOST_OPTIMIZATIONS")}
    env["PYTHONWARNINGS"] = "error"
    proc = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "run.py"), "--quick", "--out", str(tmp_path),
         "--runs", str(tmp_path / "no-runs")],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=300,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = proc.stdout
    for header in ("### Machine", "### Training step", "| dtype | batch | Jacobi | cpu ms/step",
                   "### Rollouts", "| model | trajectories × steps | solver | cpu s", "### Memory",
                   "### Time to accuracy"):
        assert header in out, f"missing {header!r} in:\n{out}"
    results = json.loads((tmp_path / "results.json").read_text())
    assert results["quick"] is True
    assert results["training"] and results["rollout"]
    assert all(r["cpu_ms"] > 0 for r in results["training"])
    assert all(r["ok"] for r in results["rollout"])
    assert not (tmp_path / "performance.md").exists()  # --quick writes no docs


def test_merge_keeps_the_rows_not_re_measured():
    sys.path.insert(0, str(ROOT / "benchmarks"))
    try:
        import run as suite
    finally:
        sys.path.pop(0)
    earlier = {
        "machine": {"date": "then"},
        "training": [{"model": "a", "jacobi": "none", "batch": 256, "dtype": "float32", "x": 1},
                     {"model": "b", "jacobi": "none", "batch": 256, "dtype": "float32", "x": 2}],
        "rollout": [{"model": "m", "trajectories": 64, "steps": 1000, "x": 3}],
    }
    now = {
        "machine": {"date": "now"}, "command": "run.py",
        "training": [{"model": "b", "jacobi": "none", "batch": 256, "dtype": "float32", "x": 9,
                      "run": "now"}],
        "rollout": [{"model": "m", "trajectories": 64, "steps": 1000, "solver": "auto", "x": 4,
                     "run": "now"}],
    }
    suite.merge(now, earlier)
    assert [(r["model"], r["x"], r["run"]) for r in now["training"]] == [
        ("a", 1, "then"), ("b", 9, "now")]
    # The earlier rollout row (Newton, from before solvers were recorded) is kept beside the
    # new auto row.
    assert [(r.get("solver"), r["x"]) for r in now["rollout"]] == [(None, 3), ("auto", 4)]
    assert now["merged_from"] == ["then"] and "then" in now["command"]
