"""Learned models of the reference experiments rolled out with every scheme (issue #8).

Reads the run folders written by `metriplex reproduce NAME --out runs/NAME` (model.mpx and
test_data.npz) and prints, per model and scheme: test rollout error, learned-energy drift,
minimum entropy step, Newton iterations per step and time per step.

    .venv/bin/python benchmarks/bench_learned_schemes.py [--runs runs] [--markdown]
"""

from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

os.environ.setdefault("XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1")

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import metriplex as mx  # noqa: E402
from metriplex.diagnostics import evaluate, rollout_data  # noqa: E402
from metriplex.config import scheme_from_name  # noqa: E402

EXPERIMENTS = ("rigid-body", "pendulum-energetic", "pendulum-temperature", "gas-containers")
SCHEMES = ("cn", "midpoint", "discrete-gradient", "rk4")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", default="runs")
    args = parser.parse_args()
    rows = []
    for name in EXPERIMENTS:
        run = Path(args.runs) / name
        if not (run / "model.mpx").exists() or not (run / "test_data.npz").exists():
            print(f"skipping {name}: no {run}/model.mpx or test_data.npz (run `metriplex "
                  f"reproduce {name} --out {run}` first)")
            continue
        model = mx.load(run)
        test = mx.read(run / "test_data.npz")
        for scheme_name in SCHEMES:
            scheme = scheme_from_name(scheme_name)
            out, _, lengths = rollout_data(model, test, scheme=scheme)  # compile
            jax.block_until_ready(out.xs)
            t0 = time.perf_counter()
            out, _, lengths = rollout_data(model, test, scheme=scheme)
            jax.block_until_ready(out.xs)
            seconds = time.perf_counter() - t0
            steps = int(np.sum(lengths - 1))
            its = np.asarray(out.iterations)
            report = evaluate(model, test, scheme=scheme)
            rows.append((name, scheme_name, report["rollout_error_mean"],
                         report["energy_relative_drift"], report["entropy_min_step"],
                         float(its[:, 1:].mean()) if its.shape[1] > 1 else 0.0,
                         1e6 * seconds / steps, report["rollout_failures"]))
    head = ("| model | scheme | test rollout error | learned-energy drift (raw) | min entropy step "
            "| Newton its/step | µs/step (batched) | failed rollouts |")
    print(head)
    print("|" + "---|" * 8)
    for r in rows:
        print(f"| {r[0]} | {r[1]} | {r[2]:.3g} | {r[3]:.2g} | {r[4]:.2g} | {r[5]:.2f} | "
              f"{r[6]:.1f} | {r[7]} |")
    print(f"\nmachine: {jax.devices()[0].device_kind}, jax {jax.__version__}")


if __name__ == "__main__":
    main()
