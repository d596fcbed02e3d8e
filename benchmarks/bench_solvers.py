"""Implicit-step root finders compared: Newton at every step vs fixed point first (``auto``).

For the ``unit`` thermoelastic pendulum (64 trajectories x 1000 steps, dt = 0.1), each row
rolls out one model with one scheme and dtype under ``root_finder=Newton()`` (``newton``) and
``root_finder=FixedPointThenNewton()`` (``auto``, the default) in the same process, repeats
interleaved, and prints the median process CPU time, the mean iterations per step, and an
accuracy figure: for float32, the relative error at t = 10 against a tight float64 Newton
rollout of the same scheme; for the float64 discrete gradient, the largest relative energy
drift over t in [0, 100].

```
.venv/bin/python benchmarks/bench_solvers.py            # ~2 minutes on 2 cores
.venv/bin/python benchmarks/bench_solvers.py --repeats 1 --steps 50   # smoke test
```

One compute thread is pinned (docs/design.md, 'Performance rules'); compare times within one run
only.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

os.environ.setdefault(
    "XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1"
)

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import jax.random as jr  # noqa: E402
import numpy as np  # noqa: E402

import metriplex as mx  # noqa: E402
from metriplex._model import with_dtype  # noqa: E402
from metriplex.app._build import build_model  # noqa: E402
from metriplex.config import preset  # noqa: E402
from metriplex.systems import generate, get_system  # noqa: E402


def _time(model, x0, ts, scheme, repeats):
    out = mx.solve(model, x0, ts, scheme=scheme)
    jax.block_until_ready(out.xs)
    cpu = []
    for _ in range(repeats):
        c0 = time.process_time()
        out = mx.solve(model, x0, ts, scheme=scheme)
        jax.block_until_ready(out.xs)
        cpu.append(time.process_time() - c0)
    return out, statistics.median(cpu)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--steps", type=int, default=1000)
    ap.add_argument("--trajectories", type=int, default=64)
    args = ap.parse_args(argv)
    system = get_system("pendulum-energetic")
    data = generate(system, trajectories=8, steps=50, dt=0.1, seed=0)
    learned = build_model(preset("pendulum-energetic"), data, key=jr.key(0))
    x0 = np.asarray(system.sample_initial(args.trajectories, seed=1))
    ts = np.arange(args.steps + 1) * 0.1
    k10 = min(100, args.steps)
    truth = system.model
    tight = {
        name: np.asarray(mx.solve(truth, jnp.asarray(x0), jnp.asarray(ts),
                                  scheme=cls(root_finder=mx.Newton(rtol=1e-13, atol=1e-13))).xs)
        for name, cls in (("cn", mx.CrankNicolson), ("discrete-gradient", mx.DiscreteGradient))
    }
    energy = jax.vmap(jax.vmap(truth.energy))
    rows = [
        ("learned-size network (untrained)", learned, jnp.float32, "cn"),
        ("ground truth", truth, jnp.float32, "cn"),
        ("ground truth", truth, jnp.float64, "cn"),
        ("ground truth", truth, jnp.float64, "discrete-gradient"),
    ]
    print(f"{args.trajectories} trajectories x {args.steps} steps, dt = 0.1, unit pendulum; "
          f"median CPU s of {args.repeats}\n")
    print("| model | dtype | scheme | newton s | auto s | speed-up | iterations/step "
          "(newton / auto) | accuracy (newton / auto) |")
    print("|---|---|---|---|---|---|---|---|")
    for label, model, dtype, name in rows:
        model = with_dtype(model, dtype)
        xs0, grid = jnp.asarray(x0, dtype), jnp.asarray(ts, dtype)
        cls = mx.CrankNicolson if name == "cn" else mx.DiscreteGradient
        res = {s: _time(model, xs0, grid, cls(root_finder=finder), args.repeats)
               for s, finder in (("newton", mx.Newton()), ("auto", mx.FixedPointThenNewton()))}
        acc = []
        for solver in ("newton", "auto"):
            xs = np.asarray(res[solver][0].xs, dtype=np.float64)
            if label.startswith("learned"):
                acc.append("–")
            elif dtype == jnp.float32:
                ref = tight[name][:, k10]
                err = np.linalg.norm(xs[:, k10] - ref, axis=-1) / np.linalg.norm(ref, axis=-1)
                acc.append(f"{np.median(err):.1e} (t = {ts[k10]:g})")
            else:
                e = np.asarray(energy(jnp.asarray(xs)))
                acc.append(f"drift {np.max(np.abs(e - e[:, :1]) / np.abs(e[:, :1])):.1e}")
        its = [float(np.asarray(res[s][0].iterations)[:, 1:].mean()) for s in ("newton", "auto")]
        ok = all(res[s][0].ok for s in res)
        tn, ta = res["newton"][1], res["auto"][1]
        print(f"| {label} | {jnp.dtype(dtype).name} | {name} | {tn:.3f} | {ta:.3f} | "
              f"{tn / ta:.1f}x | {its[0]:.1f} / {its[1]:.1f} | {acc[0]} / {acc[1]} |"
              + ("" if ok else " (a rollout failed)"), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
