"""benchmarks/plain_reference.py: its plain JAX step computes metriplex's loss, and --quick runs.

No timing is asserted (the machines are shared and noisy).
"""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]


def _script():
    sys.path.insert(0, str(ROOT / "benchmarks"))
    try:
        import plain_reference
    finally:
        sys.path.pop(0)
    return plain_reference


# fully-learned+jacobi holds every learned block of fully-learned plus the Jacobi term.
@pytest.mark.slow
@pytest.mark.parametrize("name", ["fully-learned+jacobi", "pendulum-energetic",
                                  "pendulum-energetic+runs"])
def test_plain_loss_is_metriplex_loss(tmp_path, name):
    from metriplex.io import write
    from metriplex.systems import generate

    pr = _script()
    path = tmp_path / "pendulum.npz"
    write(path, generate("pendulum-energetic", trajectories=3, steps=30, dt=0.1, seed=0))
    model, loss, params, consts, train, config = pr.setup(name, path, 16)
    pairs = train.pairs()
    assert ("jacobi" in consts["weights"]) == pr.CONFIGS[name][1]
    ours, plain = pr.check_same_loss(model, loss, params, consts, pairs, consts["rate"])
    assert np.isfinite(ours) and ours > 0
    step = pr.PlainStep(params, consts, pairs, 16, config.lr)
    assert step.run(2) > 0
    assert config.consecutive == (8 if name.endswith("+runs") else 1)
    chunk = pr.FitChunk(model, loss, train, consts["rate"], 16, config.lr, length=2,
                        consecutive=config.consecutive)
    assert chunk.run(2)[1] == 2


@pytest.mark.slow
def test_quick_mode(tmp_path):
    env = {k: v for k, v in os.environ.items()
           if k not in ("XLA_FLAGS", "JAX_DISABLE_MOST_OPTIMIZATIONS")}  # it times the steps
    out = tmp_path / "rows.json"
    proc = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "plain_reference.py"), "--quick",
         "--code", "tree", "--out", str(out)],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=900,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "| configuration | batch | metriplex ms/step (wall) |" in proc.stdout
    assert "load average before" in proc.stdout
    rows = json.loads(out.read_text())["rows"]
    assert len(rows) == 1 and rows[0]["batch"] == 256 and rows[0]["plain_ms"] > 0
