"""The former README pendulum case: few trajectories of a 10-variable system, defaults.

Training data: ``pendulum-energetic``, 20 trajectories of 400 steps at dt = 0.1 (seed 0);
structure options ``--poisson canonical:4 --entropy sum:8,9``, every other setting the default
(or ``--set KEY=VALUE``). Test: 10 unseen initial conditions (seed 1000) rolled out 400 steps
with the training scheme. Prints one JSON line: failed test rollouts, the mean relative L2 error
of those that completed, and the training summary.

```bash
python benchmarks/few_trajectories.py
python benchmarks/few_trajectories.py --set w_degeneracy_M=1
```
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import tempfile
from pathlib import Path

os.environ.setdefault("XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false")

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)  # ground truth in float64; training stays float32

import numpy as np  # noqa: E402

from metriplex.config import RunConfig, scheme_from_name  # noqa: E402
from metriplex.diagnostics import evaluate  # noqa: E402
from metriplex.app.runs import run_config, train_run, trained_scheme  # noqa: E402
from metriplex.systems import generate  # noqa: E402
from zoo import _coerce  # noqa: E402


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE",
                   help="override a training setting (RunConfig field)")
    p.add_argument("--seed", type=int, default=0, help="seed of the training data")
    args = p.parse_args(argv)
    overrides = {k: _coerce(v) for k, v in (kv.split("=", 1) for kv in args.set)}
    train = generate("pendulum-energetic", trajectories=20, steps=400, dt=0.1, seed=args.seed)
    test = generate("pendulum-energetic", trajectories=10, steps=400, dt=0.1,
                    seed=1000 + args.seed)
    config = dataclasses.replace(RunConfig(), poisson="canonical:4", entropy="sum:8,9",
                                 **overrides)
    with tempfile.TemporaryDirectory() as tmp:
        model, history, _, _, seconds = train_run(train, config, Path(tmp) / "run",
                                                  overwrite=True, progress=False)
        scheme = trained_scheme(run_config(Path(tmp) / "run"))  # given, or the data's
    report = evaluate(model, test, scheme=scheme_from_name(scheme))
    errors = np.asarray(report["rollout_error"], dtype=float)
    done = errors[np.isfinite(errors)]
    print(json.dumps({
        "overrides": overrides,
        "failed": int(report["rollout_failures"]),
        "test_trajectories": len(errors),
        "rel_l2_of_completed": float(done.mean()) if len(done) else None,
        "steps": history.step[-1] if history.step else 0,
        "kept_step": history.best_step,
        "stopped": history.stopped,
        "train_seconds": round(seconds, 1),
    }))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
