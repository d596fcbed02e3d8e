"""Cost of one training step with and without the Jacobi penalty, as the state size grows.

One step = one jitted ``value_and_grad`` of the loss + one Adam update, on a fixed batch.
Model: MLP energy and entropy, ``SkewMLPPoisson``, ``CholeskyFriction`` (all width 64 x 2).
Loss: Crank–Nicolson residual + degeneracy penalty, plus

- ``none``: nothing else;
- ``exact``: ``JacobiPenalty(ExactJacobi())`` (full n^3 tensor, n forward-mode tangents of L);
- ``stochastic``: ``JacobiPenalty(StochasticJacobi(probes=1))`` (three directional
  derivatives);
- ``projected``: no Jacobi term, but the exactly degenerate blocks
  ``ProjectedSkewMLPPoisson`` / ``ProjectedCholeskyFriction`` (the price of exact degeneracy).

Times are per step, medians over repeats after compilation (each repeat averages enough steps
to last ~0.1 s), in float32 on one pinned compute thread. ``cpu ms`` is process CPU time per
step, which other processes on a shared machine disturb far less than ``wall ms``; ``x none``
is the ratio of CPU times to the ``none`` step of the same ``n``. Modes are interleaved repeat
by repeat. Compare ratios within one run, never absolute times across runs (docs/design.md,
'Performance rules').

    python benchmarks/bench_jacobi.py            # n = 3, 10, 30, 100, batch 256
    python benchmarks/bench_jacobi.py --quick    # n = 3, 10, batch 64 (CI smoke test)
"""

from __future__ import annotations

import os

# One compute thread, set before JAX is imported (it reads XLA_FLAGS once).
os.environ["XLA_FLAGS"] = (
    os.environ.get("XLA_FLAGS", "")
    + " --xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1"
).strip()

import argparse  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402

import equinox as eqx  # noqa: E402
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import jax.random as jr  # noqa: E402
import optax  # noqa: E402

import metriplex as mx  # noqa: E402
from metriplex.losses import Batch  # noqa: E402
from metriplex.structure import ProjectedCholeskyFriction, ProjectedSkewMLPPoisson  # noqa: E402

MODES = ("none", "exact", "stochastic", "projected")


def build(n: int, mode: str, width: int, depth: int, key):
    k = jr.split(key, 4)
    projected = mode == "projected"
    poisson = (ProjectedSkewMLPPoisson if projected else mx.SkewMLPPoisson)(
        n, width=width, depth=depth, key=k[2]
    )
    friction = (ProjectedCholeskyFriction if projected else mx.CholeskyFriction)(
        n, width=width, depth=depth, key=k[3]
    )
    model = mx.GenericModel(
        energy=mx.MLPPotential(n, width=width, depth=depth, key=k[0]),
        entropy=mx.MLPPotential(n, width=width, depth=depth, key=k[1]),
        poisson=poisson,
        friction=friction,
    )
    loss = mx.CrankNicolsonResidual() + 10.0 * mx.DegeneracyPenalty()
    if mode == "exact":
        loss = loss + mx.JacobiPenalty(mx.ExactJacobi())
    elif mode == "stochastic":
        loss = loss + mx.JacobiPenalty(mx.StochasticJacobi(probes=1))
    return model, loss


def flops_of(compiled) -> float | None:
    try:
        cost = compiled.cost_analysis()
        if isinstance(cost, (list, tuple)):
            cost = cost[0]
        return float(cost["flops"])
    except Exception:  # cost analysis is best-effort and backend dependent
        return None


def compile_step(n: int, mode: str, *, batch: int, width: int, depth: int, seed: int):
    """Build, compile and warm up one training step; return a zero-argument timer."""
    mkey, dkey, lkey = jr.split(jr.key(seed), 3)
    model, loss = build(n, mode, width, depth, mkey)
    params, static = eqx.partition(model, eqx.is_inexact_array)
    opt = optax.adam(1e-3)
    opt_state = opt.init(params)
    x0 = jr.normal(dkey, (batch, n))
    data = Batch(x0, x0 + 0.01 * jnp.cos(x0), jnp.full((batch,), 0.05), jnp.ones((n,)))

    def step(params, opt_state, data, key):
        def f(p):
            return loss(eqx.combine(p, static), data, key=key)[0]

        value, grads = jax.value_and_grad(f)(params)
        updates, opt_state = opt.update(grads, opt_state, params)
        return eqx.apply_updates(params, updates), opt_state, value

    t0 = time.perf_counter()
    compiled = jax.jit(step).lower(params, opt_state, data, lkey).compile()
    compile_s = time.perf_counter() - t0
    state = {"params": params, "opt_state": opt_state, "key": lkey}

    def run(inner: int = 1) -> tuple[float, float]:
        """Wall and process-CPU seconds per step, averaged over ``inner`` steps."""
        keys = jr.split(state["key"], inner + 1)
        state["key"] = keys[0]
        jax.block_until_ready(keys)
        p, o = state["params"], state["opt_state"]
        w0, c0 = time.perf_counter(), time.process_time()
        for k in keys[1:]:
            p, o, value = compiled(p, o, data, k)
        jax.block_until_ready((p, o, value))
        w, c = time.perf_counter() - w0, time.process_time() - c0
        state["params"], state["opt_state"] = p, o
        return w / inner, c / inner

    first, _ = run()  # warm-up
    inner = max(1, min(50, int(0.1 / max(first, 1e-6))))  # ~0.1 s per timing sample
    return (lambda: run(inner)), compile_s, flops_of(compiled)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="n = 3, 10, batch 64, 5 repeats")
    ap.add_argument("--sizes", type=int, nargs="*", default=None)
    ap.add_argument("--batch", type=int, default=None)
    ap.add_argument("--width", type=int, default=64)
    ap.add_argument("--depth", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=None)
    ap.add_argument("--modes", nargs="*", default=list(MODES), choices=MODES)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    sizes = args.sizes or ([3, 10] if args.quick else [3, 10, 30, 100])
    batch = args.batch or (64 if args.quick else 256)
    repeats = args.repeats or (5 if args.quick else 9)
    print(
        f"jax {jax.__version__}, {jax.devices()[0].platform}, float32, one compute thread; "
        f"batch {batch}, width {args.width} x {args.depth}; median of {repeats} repeats"
    )
    header = (
        f"{'n':>4} {'mode':>11} {'cpu ms':>9} {'wall ms':>9} {'x none':>7} {'GFLOP/step':>11} "
        f"{'GFLOP/s':>8} {'compile s':>10}"
    )
    print(header)
    print("-" * len(header))
    for n in sizes:
        runs = {}
        for mode in args.modes:
            runs[mode] = compile_step(
                n, mode, batch=batch, width=args.width, depth=args.depth, seed=args.seed
            )
        # Interleave the modes so that load from other processes hits them alike.
        wall = {mode: [] for mode in args.modes}
        cpu = {mode: [] for mode in args.modes}
        for _ in range(repeats):
            for mode in args.modes:
                w, c = runs[mode][0]()
                wall[mode].append(w)
                cpu[mode].append(c)
        base = statistics.median(cpu["none"]) if "none" in cpu else None
        for mode in args.modes:
            t = statistics.median(cpu[mode])
            tw = statistics.median(wall[mode])
            _, c, fl = runs[mode]
            ratio = f"{t / base:7.2f}" if base else f"{'-':>7}"
            gf = f"{fl / 1e9:11.3f}" if fl else f"{'-':>11}"
            rate = f"{fl / 1e9 / t:8.1f}" if fl else f"{'-':>8}"
            print(
                f"{n:>4} {mode:>11} {1e3 * t:9.2f} {1e3 * tw:9.2f} {ratio} {gf} {rate} {c:10.1f}",
                flush=True,
            )
        del runs


if __name__ == "__main__":
    main()
