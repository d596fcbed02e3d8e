"""Time after the last training step (issue #16, target <= 10% of the training time).

Runs ``metriplex train DATA --out RUN --entropy sum:8,9 --poisson canonical:4 --quiet`` in this
process, as the command line does, on a pendulum dataset of ``--trajectories`` x ``--samples``
(default 400 x 2001, the size in docs/performance.md), and prints:

- ``training``: the wall time from the start of the run's first :func:`metriplex.fit` (the
  starts' trials and the first stage are fits too) to the end of its last one;
- ``after``: from the moment ``fit`` returns to the end of the command (saving the model and
  history, rolling out the validation trajectories, the metrics, the report figures);
- their ratio, with the machine's load average (other jobs make both slower, not equally).

```bash
python benchmarks/bench_after_training.py                    # about 3-10 minutes on 2 cores
python benchmarks/bench_after_training.py --trajectories 40 --samples 201 --steps 2000
```
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

from metriplex.app import _repeats, _stages, cli


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--trajectories", type=int, default=400)
    p.add_argument("--samples", type=int, default=2001, help="states per trajectory")
    p.add_argument("--steps", type=int, default=None,
                   help="training step cap (default: metriplex train's default)")
    args = p.parse_args(argv)
    marks: dict[str, float] = {}
    fit = _repeats.fit

    def timed_fit(*a, **kw):
        # Training is every fit of the run (the starts' trials, the first stage, the main
        # one): from the first one's start to the last one's end.
        marks.setdefault("fit_start", time.perf_counter())
        marks["fits"] = marks.get("fits", 0) + 1
        try:
            return fit(*a, **kw)
        finally:
            marks["fit_end"] = time.perf_counter()

    with tempfile.TemporaryDirectory() as tmp:
        data = Path(tmp) / "data.npz"
        if cli.main(["simulate", "pendulum-energetic", "--trajectories", str(args.trajectories),
                     "--steps", str(args.samples - 1), "--dt", "0.1", "--out", str(data)]):
            return 1
        train = ["train", str(data), "--out", str(Path(tmp) / "run"), "--entropy", "sum:8,9",
                 "--poisson", "canonical:4", "--quiet"]
        if args.steps is not None:
            train += ["--steps", str(args.steps)]
        load = os.getloadavg()[0]
        _repeats.fit = _stages.fit = timed_fit
        try:
            code = cli.main(train)
        finally:
            _repeats.fit = _stages.fit = fit
        end = time.perf_counter()
    if "fit_end" not in marks:
        print(f"metriplex train stopped before training (exit {code}); nothing to time.")
        return code or 1
    training = marks["fit_end"] - marks["fit_start"]
    after = end - marks["fit_end"]
    print(f"{args.trajectories} x {args.samples} pendulum, load {load:.2f} -> "
          f"{os.getloadavg()[0]:.2f} on {os.cpu_count()} cores (exit {code})")
    print(f"training ({marks['fits']} fits) {training:.1f} s; after it {after:.1f} s; "
          f"after / training = {after / training:.1%} (target <= 10%)")
    return code


if __name__ == "__main__":
    sys.exit(main())
