"""The README's Python example runs as written (on a small oscillator-bath data set, with a short
step cap so the test stays fast)."""

import re
from pathlib import Path

import numpy as np

import metriplex as mx
from metriplex.systems import generate

ROOT = Path(__file__).resolve().parents[1]


def _python_example() -> str:
    text = (ROOT / "README.md").read_text()
    block = re.search(r"## In Python\n\n```python\n(.*?)```", text, re.S).group(1)
    assert "mx.fit(" in block
    return block


def test_readme_python_example_runs(tmp_path, monkeypatch):
    data = generate("oscillator-bath", trajectories=6, steps=60, dt=0.022, seed=0)
    mx.write(tmp_path / "data.npz", data)
    monkeypatch.chdir(tmp_path)
    # 100 steps: the held-out loss falls 47x (5.2 -> 0.11) by step 100, its best evaluation.
    code = _python_example().replace("key=jr.key(1))", "steps=100, progress=False, key=jr.key(1))")
    scope: dict = {}
    exec(compile(code, "README.md", "exec"), scope)
    assert (tmp_path / "model.mpx").exists()
    assert scope["pred"].shape == (61, 3) and len(scope["test"]) == 1 and len(scope["data"]) == 5
    assert np.all(np.isfinite(np.asarray(scope["pred"])))
    assert np.isfinite(scope["report"]["rollout_error_mean"])
    history = scope["history"]
    assert history.valid["total"][-1] < history.valid["total"][0]
