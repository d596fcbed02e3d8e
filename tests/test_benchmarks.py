"""The benchmark suite must keep running: `benchmarks/run.py --quick` in a subprocess.

No timing is asserted (the machines are shared and noisy); only that the suite exits 0, prints
its tables and writes its JSON.
"""

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_benchmark_suite_quick(tmp_path):
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
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
