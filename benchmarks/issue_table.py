"""The new-user table of issue #13, made again: systems like the issue's own, with parameters
that no zoo case or reference experiment has, trained with the defaults and the structure
flags alone.

    .venv/bin/python benchmarks/issue_table.py                    # all four, ~25 minutes on 2 cores
    .venv/bin/python benchmarks/issue_table.py --cases rigid-other --out rows.json

The issue's table measured these cases on the code of the time (its figures in the last
column); its data are not ours, so each case here is our reading of its one-line description:

- **bath-linear**: a damped *linear* oscillator heating a bath (the zoo's oscillator-bath with
  no quartic term, stiffness 2, friction 0.3); `--poisson canonical:1 --entropy sum:2`.
- **rigid-other**: a free rigid body with inertia (8, 15, 35) instead of (10, 20, 40), five
  trajectories of 10 000 steps as the reference experiment's; nothing given.
- **independent-simulator**: a damped oscillator heating a bath, simulated by SciPy
  (``solve_ivp``, DOP853, tolerance 1e-11), not by metriplex; 30 trajectories of 200 steps
  of 0.05; `--poisson canonical:1 --entropy sum:2`.
- **pendulum-other**: the double thermoelastic pendulum with masses (1.5, 0.8) and
  conductivity 0.3, the reference experiment's data otherwise (100 trajectories of 400 steps
  of 0.1); `--poisson canonical:4 --entropy sum:8,9`. Also its error up to t = 10, the
  horizon of the reference experiment's bar.

Test trajectories: 10 unseen initial states (seed 1000; SciPy's case seed 1), over the
training trajectories' length (the rigid body's over 1 000 steps). Results: docs/zoo.md, *The
issue's new-user table, made again*.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy as np  # noqa: E402
from scipy.integrate import solve_ivp  # noqa: E402

from zoo import _fmt, flag_line, run_case, train_and_test  # noqa: E402
from metriplex.config import RunConfig  # noqa: E402
from metriplex.data import Trajectories  # noqa: E402
from metriplex.systems import get_system  # noqa: E402
from metriplex.systems.zoo._case import ZooCase  # noqa: E402

CANONICAL_BATH = {"poisson": "canonical:1", "entropy": "sum:2"}


def _cases() -> dict:
    """name -> (description, the issue's figure, a ZooCase or the SciPy case's maker, and the
    time up to which the error is also reported, or None)."""
    return {
        "bath-linear": (
            "damped linear oscillator with a heat bath", "0.114",
            ZooCase(get_system("oscillator-bath").with_params(quartic=0.0, damping=0.3,
                                                              stiffness=2.0),
                    CANONICAL_BATH, 32, 300, 0.022, held_out=True), None),
        "rigid-other": (
            "rigid body with another inertia, all learned", "0.023",
            ZooCase(get_system("rigid-body").with_params(inertia=(8.0, 15.0, 35.0)), {}, 5,
                    10_000, 2 * np.pi / 100, test_trajectories=10, test_steps=1000,
                    held_out=True), None),
        "independent-simulator": (
            "oscillator with a heat bath from an independent simulator (SciPy)", "0.054",
            _scipy_oscillator, None),
        "pendulum-other": (
            "thermoelastic double pendulum, other masses and conductivity", "0.33",
            ZooCase(get_system("pendulum-energetic").with_params(masses=(1.5, 0.8), kappa=0.3),
                    {"poisson": "canonical:4", "entropy": "sum:8,9"}, 100, 400, 0.1,
                    held_out=True), 10.0),
    }


def _oscillator_rates(t, x, m=1.0, k=1.0, friction=0.2, heat_capacity=1.0, theta0=1.0):
    """q' = p/m, p' = -k q - friction p/m, s' = friction v^2 / theta with theta = theta0
    exp(s / heat_capacity): the friction's work heats the bath."""
    q, p, s = x
    v = p / m
    return [v, -k * q - friction * v, friction * v * v / (theta0 * np.exp(s / heat_capacity))]


def _scipy_trajectories(count: int, seed: int, steps: int = 200, dt: float = 0.05):
    rng = np.random.default_rng(seed)
    t = np.arange(steps + 1) * dt
    pieces = []
    for _ in range(count):
        x0 = [rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-0.1, 0.1)]
        sol = solve_ivp(_oscillator_rates, (0.0, t[-1]), x0, t_eval=t, method="DOP853",
                        rtol=1e-11, atol=1e-12)
        pieces.append((t, sol.y.T))
    return Trajectories.from_list(pieces, names=("q", "p", "s"))


def _scipy_oscillator(workdir: Path) -> dict:
    train, test = _scipy_trajectories(30, seed=0), _scipy_trajectories(10, seed=1)
    run = train_and_test(train, test, RunConfig(**CANONICAL_BATH), workdir / "scipy")
    return {"flags": flag_line(CANONICAL_BATH), "rel_l2": run["report"]["rollout_error_mean"],
            "rel_l2_standardised": run["standardised"],
            "failed": int(run["report"]["rollout_failures"]), "ground_truth_cn_rel_l2": None,
            "train_seconds": run["seconds"], "trainings": run["header"].get("trainings")}


def _up_to(row: dict, key: str) -> str:
    """`` (to t = H: error)`` where the case reports its error up to a time H."""
    return "" if row.get(key) is None else f" (to t = {row['horizon']:g}: {_fmt(row[key])})"


def main(argv=None) -> int:
    cases = _cases()
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--cases", help=f"comma list of {', '.join(cases)} (default: all)")
    p.add_argument("--out", help="also write the rows to this JSON file")
    args = p.parse_args(argv)
    names = args.cases.split(",") if args.cases else list(cases)
    unknown = [n for n in names if n not in cases]
    if unknown:
        p.error(f"unknown case(s) {unknown}; known: {', '.join(cases)}")
    print(f"issue table: {len(names)} cases, load {os.getloadavg()[0]:.2f} on "
          f"{os.cpu_count()} cores", flush=True)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name in names:
            what, issue, case, horizon = cases[name]
            t0 = time.perf_counter()
            if isinstance(case, ZooCase):
                row = run_case(case, {}, Path(tmp), horizon=horizon)
            else:
                row = case(Path(tmp))
            row.update(case=name, what=what, issue=issue, horizon=horizon,
                       wall=time.perf_counter() - t0)
            rows.append(row)
            print(f"  {name}: rel. L2 {_fmt(row['rel_l2'])}, failed {row['failed']}", flush=True)
    print("\n| case | flags | rel. L2 | standardised | failed | true field, CN | trainings | "
          "train s | the issue's figure |\n|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        truth = r.get("ground_truth_cn_rel_l2")
        truth = "-" if truth is None else _fmt(truth) + _up_to(r, "ground_truth_cn_to_horizon")
        print(f"| {r['case']}: {r['what']} | `{r['flags']}` | {_fmt(r['rel_l2'])}"
              f"{_up_to(r, 'to_horizon')} | {_fmt(r['rel_l2_standardised'])} | "
              f"{r['failed']}/10 | {truth} | {len(r.get('trainings') or [0])} | "
              f"{r['train_seconds']:.0f} | {r['issue']} |")
    if args.out:
        Path(args.out).write_text(json.dumps(rows, indent=1, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
