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
    block = re.search(r"\*\*The low-level path: one `fit`\.\*\*.*?```python\n(.*?)```", text,
                      re.S).group(1)
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


def test_readme_train_defaults_from_python_call_the_api_as_it_is(tmp_path, monkeypatch):
    # The first Python block trains as `metriplex train` does (a full training: too long for
    # the default run), so its calls are bound to the real signatures without running them.
    import inspect

    from metriplex import runs

    mx.write(tmp_path / "data.npz", generate("oscillator-bath", trajectories=5, steps=10,
                                             dt=0.022, seed=0))
    monkeypatch.chdir(tmp_path)

    text = (ROOT / "README.md").read_text()
    block = re.search(r"## In Python\n\n.*?```python\n(.*?)```", text, re.S).group(1)
    imports = "from metriplex.runs import evaluate_run, run_config, train_run, trained_scheme\n"
    assert imports in block

    def checked(name, result):
        def call(*args, **kwargs):
            inspect.signature(getattr(runs, name)).bind(*args, **kwargs)
            return result
        return call

    scope = {"train_run": checked("train_run", (None,) * 5),
             "evaluate_run": checked("evaluate_run", {}), "run_config": checked("run_config", {}),
             "trained_scheme": checked("trained_scheme", "cn")}
    exec(compile(block.replace(imports, ""), "README.md", "exec"), scope)
    assert scope["config"].poisson == "canonical:1" and scope["config"].entropy == "sum:2"
    assert len(scope["data"]) == 4 and len(scope["test"]) == 1


def test_readme_trained_run_in_python_runs(tmp_path, monkeypatch):
    # The block that reads a trained run back: on a saved (untrained) model of the CLI
    # example's shape, and that example's test file.
    import jax.random as jr

    text = (ROOT / "README.md").read_text()
    block = re.search(r"\*\*A trained run in Python\*\*.*?```python\n(.*?)```", text, re.S).group(1)
    test = generate("oscillator-bath", trajectories=2, steps=30, dt=0.022, seed=1)
    mx.write(tmp_path / "test.npz", test)
    model = mx.GenericModel(energy=mx.MLPPotential(3, key=jr.key(0)), entropy=mx.SumOf((2,)),
                            poisson=mx.CanonicalPoisson(3, pairs=1),
                            friction=mx.CholeskyFriction(3, key=jr.key(1)))
    (tmp_path / "run").mkdir()
    mx.save(tmp_path / "run" / "model.mpx", model, n=3, names=test.names)
    monkeypatch.chdir(tmp_path)
    scope: dict = {}
    exec(compile(block, "README.md", "exec"), scope)
    assert scope["E"].shape == scope["S"].shape == (len(test.x),)
    assert np.allclose(scope["S"], test.x[:, 2], rtol=1e-6)  # S = s, given
    assert scope["pred"].shape == (31, 3) and np.all(np.isfinite(np.asarray(scope["pred"])))
    assert scope["terms"].friction.shape == (31, 3, 3)
    assert scope["scheme"].name == "cn"  # no config.json: the default step
    assert scope["report"]["rollout_failures"] == 0
    assert (tmp_path / "q.png").exists()
