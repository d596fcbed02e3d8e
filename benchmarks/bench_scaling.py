"""Cost per sample of a fully learned training step as the state size n grows (issue #16).

    .venv/bin/python benchmarks/bench_scaling.py            # n ~ 5..100, batch 256 (~15-25 min)
    .venv/bin/python benchmarks/bench_scaling.py --quick    # n = 6, 9, few steps (~1 min)
    .venv/bin/python benchmarks/bench_scaling.py --sizes 20 100 --jacobi stochastic

What is measured, and how:

- **system**: the zoo's ``thermoelastic-chain`` (``particles`` N, state n = 3N: positions,
  momenta, reservoir entropies; canonical L, friction plus conduction in M), the only built-in
  exactly-GENERIC family whose size is a parameter. A requested size n maps to
  N = round(n / 3) (at least 2), so n = 5, 10, 20, 50, 100 are measured at n = 6, 9, 21, 51, 99;
  the fit uses the n actually measured. The data (``metriplex.systems.generate``, a few short
  trajectories) only give the shapes and the units.
- **model and loss**: exactly what ``metriplex train DATA --jacobi J`` builds with every other
  option at its default: ``RunConfig`` (E, S, L, M all networks of width 64 x 2, the
  Crank-Nicolson residual, both degeneracy penalties, ``--jacobi`` with 1 probe), made by
  ``_build.units_for`` / ``build_model`` / ``build_loss`` in the data's units, float32, and fit's
  optimiser under the default plateau schedule (``_optimizers.adjustable_optimizer``).
- **step**: ``metriplex._train.make_chunk``, the compiled unit that ``metriplex.fit`` runs
  (random minibatch, ``value_and_grad`` of the loss, Adam; ``length`` steps in one compiled loop), as
  ``benchmarks/run.py`` times it. Two chunk lengths are compiled (``--short`` steps, and
  ``--long`` or as many as take about ``--chunk-seconds`` of CPU time) and run alternately;
  per step = (time of the long chunk - time of the short chunk) / (difference in steps), so
  compilation, dispatch and the per-call overhead cancel. Median over 3 to ``--repeats`` such
  pairs (no fourth one once a size has used ``--budget`` CPU seconds). ``cpu`` is process CPU
  time (one compute thread: the step's cost; other processes on a shared machine disturb it
  far less than ``wall``).
- **cost per sample** = per-step time / batch; the **exponent** is the least-squares slope of
  log(cost per sample) on log(n) over the sizes (CPU time), with the local slopes between
  consecutive sizes beside it.
- **marginal cost of a sample**: the same step at ``--marginal-batch`` (512) as well;
  (step at 512 - step at 256) / 256 is what one more sample costs, without the work done once
  per batch (its own exponent), and the remainder is that per-batch work.
- **where the step's time goes at the largest n**: the stochastic step minus the plain one (the
  Jacobi term), XLA's FLOP count per step, and the folded output heads of L and M (a fixed
  (n², m) assembly matrix times the (m, width) weight, once per step) timed on their own.
- **does it train**: the largest size with the stochastic Jacobi penalty runs ``--train-steps``
  steps of the same chunk from fresh parameters; the mean loss (and each term) of the first and
  of the last chunk are printed.

One compute thread is pinned by default (the XLA flags of ``benchmarks/run.py``, which this
script imports before JAX); ``--threads 0`` leaves XLA's default. The load average
(``os.getloadavg()``) is printed with every table: compare ratios within one run, never
absolute times across runs.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

# benchmarks/run.py sets XLA_FLAGS from this process' --threads before it imports JAX, and
# gives the suite's helpers (machine description, XLA cost analysis).
sys.path.insert(0, str(Path(__file__).resolve().parent))
import run as suite  # noqa: E402

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import math  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402

import equinox as eqx  # noqa: E402
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import jax.random as jr  # noqa: E402
import numpy as np  # noqa: E402

# benchmarks/run.py turns x64 on for its float64 rows; `metriplex train` (float32, the default)
# does not, so neither does this benchmark (index and PRNG arrays stay 32-bit, as in training).
jax.config.update("jax_enable_x64", False)

from metriplex.app._build import build_loss, build_model, units_for  # noqa: E402
from metriplex._model import with_dtype  # noqa: E402
from metriplex._pairs import PairRows, PairStore  # noqa: E402
from metriplex._optimizers import adjustable_optimizer  # noqa: E402
from metriplex._train import make_chunk  # noqa: E402
from metriplex.config import RunConfig  # noqa: E402
from metriplex.structure._mlp import lower_assembly, signed_rows, skew_assembly  # noqa: E402
from metriplex.systems import generate, get_system  # noqa: E402

SYSTEM = "thermoelastic-chain"


def load() -> str:
    try:
        return "load average %.2f %.2f %.2f" % os.getloadavg()
    except OSError:
        return "load average unavailable"


def particles_for(n: int) -> int:
    return max(2, int(round(n / 3)))


_DATA: dict = {}


def chain_data(particles: int, trajectories: int, steps: int):
    """A few short thermoelastic-chain trajectories (float32): shapes and units only."""
    if particles not in _DATA:
        system = get_system(SYSTEM, particles=particles)
        _DATA[particles] = generate(system, trajectories=trajectories, steps=steps,
                                    dt=system.defaults.dt, seed=0)
    return _DATA[particles]


@dataclasses.dataclass
class Step:
    """One configuration's compiled chunks (short and long) and its training state."""

    n: int
    jacobi: str
    batch: int
    lengths: tuple[int, int]
    compiled: dict
    full: PairStore
    params: object
    opt_state: object
    key: jax.Array
    compile_s: float
    cost: dict
    fresh: tuple = ()
    requested_batch: int = 0

    def run(self, length: int) -> tuple[float, float, float, dict]:
        """One call of the chunk of ``length`` steps: wall s, CPU s, mean loss, mean terms."""
        self.key, sub = jr.split(self.key)
        jax.block_until_ready(sub)
        w0, c0 = time.perf_counter(), time.process_time()
        p, o, v, parts = self.compiled[length](self.params, self.opt_state, sub, self.full)
        jax.block_until_ready((p, o, v, parts))
        w, c = time.perf_counter() - w0, time.process_time() - c0
        self.params, self.opt_state = p, o
        v = float(v)
        if not math.isfinite(v):
            raise RuntimeError(f"n={self.n} jacobi={self.jacobi}: non-finite loss {v}")
        return w, c, v, {k: float(x) for k, x in parts.items()}


def build_step(n_target: int, jacobi: str, batch: int, lengths: tuple[int, int | None],
               data_size: tuple[int, int], target_s: float) -> Step:
    """The model, loss and optimiser of ``metriplex train DATA --jacobi JACOBI`` (all other
    options default: E, S, L, M networks), and fit's chunk compiled at both lengths (a long
    length of ``None``: as many steps as take about ``target_s`` of CPU time, at least
    short + 8)."""
    data = chain_data(particles_for(n_target), *data_size)
    config = RunConfig(jacobi=jacobi, batch_size=batch)
    units = units_for(config, data)
    model = with_dtype(build_model(config, data, key=jr.key(0), units=units), jnp.float32)
    loss = build_loss(config, units).as_loss()
    full = PairStore.of(PairRows.of(data, data.n, "benchmark"), units.rate, jnp.float32)
    optimizer = adjustable_optimizer(config.lr, weight_decay=config.weight_decay)
    params, static = eqx.partition(model, eqx.is_inexact_array)
    opt_state = optimizer.init(params)
    bsz = min(batch, full.count)
    fn = jax.jit(make_chunk(loss, optimizer, static, bsz), static_argnums=3)
    short, long_ = lengths
    step = Step(data.n, jacobi, bsz, lengths, {}, full, params, opt_state, jr.key(2), 0.0, {},
                fresh=(params, opt_state), requested_batch=batch)

    def compile_length(length):
        t0 = time.perf_counter()
        step.compiled[length] = fn.lower(params, opt_state, jr.key(1), length, full).compile()
        step.compile_s += time.perf_counter() - t0
        if not step.cost:  # a scan body counts once: FLOP per step
            step.cost = suite._cost(step.compiled[length])
        step.run(length)  # warm-up: the first execution allocates

    compile_length(short)
    if long_ is None:
        # Long enough that the difference is well above the timer's and the load's noise.
        est = min(step.run(short)[1] for _ in range(3)) / short  # an upper bound (overhead)
        long_ = min(max(short + 8, math.ceil(target_s / max(est, 1e-6))), 1000)
    step.lengths = (short, long_)
    compile_length(long_)
    return step


def time_steps(steps: list[Step], repeats: int, budget_s: float) -> list[dict]:
    """Per-step wall and CPU time of each configuration: median over repeats of
    (long chunk - short chunk) / (difference in steps), configurations interleaved; at least
    3 repeats (fewer only if ``repeats`` says so), more up to ``repeats`` while the CPU time
    spent stays under ``budget_s``."""
    diffs = {id(s): [] for s in steps}
    c0 = time.process_time()
    for r in range(repeats):
        if r >= min(3, repeats) and time.process_time() - c0 > budget_s:
            break
        for s in steps:
            short, long_ = s.lengths
            ws, cs, _, _ = s.run(short)
            wl, cl, _, _ = s.run(long_)
            diffs[id(s)].append(((wl - ws) / (long_ - short), (cl - cs) / (long_ - short)))
    rows = []
    for s in steps:
        d = diffs[id(s)]
        wall = statistics.median(x[0] for x in d)
        cpu = statistics.median(x[1] for x in d)
        flops = s.cost.get("flops")
        rows.append(dict(
            n=s.n, jacobi=s.jacobi, batch=s.batch, wall_ms=1e3 * wall, cpu_ms=1e3 * cpu,
            us_per_sample=1e6 * cpu / s.batch, wall_us_per_sample=1e6 * wall / s.batch,
            compile_s=s.compile_s, repeats=len(d), lengths=s.lengths,
            requested_batch=s.requested_batch,
            memory_mb=None if not s.cost.get("memory_bytes") else s.cost["memory_bytes"] / 2**20,
            mflop_per_sample=None if not flops else flops / s.batch / 1e6,
            gflops=None if not flops or cpu <= 0 else flops / cpu / 1e9,
        ))
    return rows


def fit_exponent(ns, costs) -> tuple[float, list[float]]:
    """Least-squares slope of log(cost) on log(n), and the slopes between consecutive sizes."""
    ln, lc = np.log(np.asarray(ns, float)), np.log(np.asarray(costs, float))
    slope = float(np.polyfit(ln, lc, 1)[0]) if len(ns) > 1 else float("nan")
    local = [float((lc[i + 1] - lc[i]) / (ln[i + 1] - ln[i])) for i in range(len(ns) - 1)]
    return slope, local


def head_fold_ms(n: int, width: int, repeats: int) -> dict:
    """CPU ms of the folded heads' ``P W`` (L: m = n(n-1)/2, M: m = n(n+1)/2), computed as
    ``FoldedHead`` does (a signed gather of W's rows), forward and with its gradient, as the
    training step computes it once per batch and per call site; ``mflop_dense`` is what the
    dense product ``P @ W`` it replaced cost."""
    out = {}
    for name, P, tri in (("L", skew_assembly(n), "skew"), ("M", lower_assembly(n), "lower")):
        rows, sign = signed_rows(n, tri)
        sign = jnp.asarray(sign, jnp.float32)
        W = jr.normal(jr.key(0), (P.shape[1], width), jnp.float32)
        h = jr.normal(jr.key(1), (width,), jnp.float32)
        fwd = jax.jit(lambda W: sign[:, None] * W[rows]).lower(W).compile()
        vjp = jax.jit(jax.grad(lambda W: jnp.sum(jnp.tanh((sign[:, None] * W[rows]) @ h)))
                      ).lower(W).compile()
        res = {}
        for label, f in (("fwd", fwd), ("grad", vjp)):
            jax.block_until_ready(f(W))
            cpu = []
            for _ in range(repeats):
                c0 = time.process_time()
                jax.block_until_ready(f(W))
                cpu.append(time.process_time() - c0)
            res[label] = 1e3 * statistics.median(cpu)
        res["mflop_dense"] = 2 * P.shape[0] * P.shape[1] * width / 1e6
        out[name] = res
    return out


def train_check(step: Step, steps: int) -> dict:
    """``steps`` steps of the step's long chunk from the untrained parameters: mean loss and
    terms of the first and of the last chunk."""
    step.params, step.opt_state = step.fresh
    step.key = jr.key(3)
    length = step.lengths[1]
    chunks = max(2, -(-steps // length))
    t0 = time.perf_counter()
    history = [step.run(length)[2:] for _ in range(chunks)]
    return dict(n=step.n, jacobi=step.jacobi, steps=chunks * length, seconds=time.perf_counter()
                - t0, first=history[0], last=history[-1],
                curve=[h[0] for h in history])


def fmt(v, spec):
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "–"
    return format(v, spec)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true",
                    help="n ~ 5 and 10, short chunks, 2 repeats, 20 training steps (seconds)")
    ap.add_argument("--sizes", type=int, nargs="+", default=None,
                    help="state sizes n to aim at (measured at n = 3 round(n/3)); "
                         "default 5 10 20 50 100")
    ap.add_argument("--batch", type=int, default=256)
    ap.add_argument("--jacobi", nargs="+", default=["none", "stochastic"],
                    choices=["none", "stochastic", "exact"])
    ap.add_argument("--short", type=int, default=None, help="steps of the short chunk (2)")
    ap.add_argument("--long", type=int, default=None,
                    help="steps of the long chunk (default: as many as take --chunk-seconds "
                         "of CPU time, at least short + 8)")
    ap.add_argument("--chunk-seconds", type=float, default=None,
                    help="CPU time the long chunk aims at (default 0.3; 0.02 with --quick)")
    ap.add_argument("--repeats", type=int, default=None,
                    help="(short, long) pairs per configuration (default 5; 2 with --quick)")
    ap.add_argument("--budget", type=float, default=60.0,
                    help="CPU seconds per size after which no repeat beyond the third starts "
                         "(default 60)")
    ap.add_argument("--train-steps", type=int, default=None,
                    help="steps of the training check at the largest n, stochastic Jacobi "
                         "(default 200; 20 with --quick; 0: skip)")
    ap.add_argument("--marginal-batch", type=int, default=None,
                    help="also time this batch, for the marginal cost of a sample (default "
                         "512; 0 with --quick: none)")
    ap.add_argument("--threads", type=int, default=1,
                    help="1 (default): one compute thread (read by benchmarks/run.py before "
                         "JAX is imported); 0: XLA's default")
    args = ap.parse_args(argv)
    q = args.quick
    sizes = args.sizes or ([5, 10] if q else [5, 10, 20, 50, 100])
    short = args.short or 2
    long_ = args.long
    if long_ is not None and long_ <= short:
        ap.error(f"--long ({long_}) must exceed --short ({short})")
    target_s = args.chunk_seconds or (0.02 if q else 0.3)
    repeats = args.repeats or (2 if q else 5)
    marginal = (0 if q else 512) if args.marginal_batch is None else args.marginal_batch
    if marginal and marginal <= args.batch:
        ap.error(f"--marginal-batch ({marginal}) must exceed --batch ({args.batch})")
    train_steps = (20 if q else 200) if args.train_steps is None else args.train_steps
    budget_s = args.budget
    # At least one batch of pairs (fit draws min(batch, pairs)); 4 trajectories.
    data_size = (4, max(20, -(-max(args.batch, marginal) // 4) + 1))
    if q:
        # Compiling is nearly all of a smoke run: XLA's cheap pipeline (as the tests use);
        # quick timings mean nothing anyway.
        jax.config.update("jax_disable_most_optimizations", True)

    m = suite.machine(args.threads)
    print(f"# metriplex scaling in n ({'quick' if q else 'full'})\n")
    print(f"{m['cpu']}, {m['cores']} cores; jax {m['jax']}, backend {m['backend']}; compute "
          f"threads: {m['compute_threads']}; {load()}")
    print(f"system {SYSTEM} (n = 3 x particles), {data_size[0]} trajectories x {data_size[1]} "
          f"steps; fully learned E, S, L, M (width 64 x 2), float32, batch {args.batch}; "
          f"per step = (long chunk - chunk of {short}) / difference, median of "
          f"{repeats if repeats <= 3 else f'3 to {repeats}'}\n",
          flush=True)

    rows, last = [], []
    batches = [args.batch] + ([marginal] if marginal else [])
    for n_target in sizes:
        steps = []
        for jac in args.jacobi:
            for batch in batches:
                s = build_step(n_target, jac, batch, (short, long_), data_size, target_s)
                print(f"  n={s.n:<3} jacobi={jac:<10} B={batch:<5} chunks of {s.lengths[0]} "
                      f"and {s.lengths[1]} steps compiled in {s.compile_s:6.1f} s ({load()})",
                      flush=True)
                steps.append(s)
        new = time_steps(steps, repeats, budget_s)
        for r in new:
            print(f"  n={r['n']:<3} jacobi={r['jacobi']:<10} B={r['batch']:<5} "
                  f"{r['cpu_ms']:9.2f} cpu ms/step {r['wall_ms']:9.2f} wall ms/step "
                  f"{r['us_per_sample']:8.2f} us/sample, median of {r['repeats']} "
                  f"({load()})", flush=True)
        rows += new
        # The largest size's compiled steps stay for the training check.
        last = [s for s in steps if s.requested_batch == args.batch]
        del steps

    main_rows = [r for r in rows if r["requested_batch"] == args.batch]
    print(f"\n## Cost per sample (CPU time; batch {args.batch}; {load()})\n")
    print("| n | Jacobi | batch | ms/step wall | ms/step cpu | µs/sample (cpu) | "
          "MFLOP/sample | GFLOP/s | step MB | chunks (steps) | compile s |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for r in main_rows:
        print(f"| {r['n']} | {r['jacobi']} | {r['batch']} | {r['wall_ms']:.2f} | "
              f"{r['cpu_ms']:.2f} | {r['us_per_sample']:.2f} | "
              f"{fmt(r['mflop_per_sample'], '.3f')} | {fmt(r['gflops'], '.1f')} | "
              f"{fmt(r['memory_mb'], '.0f')} | {r['lengths'][0]}, {r['lengths'][1]} | "
              f"{r['compile_s']:.1f} |")
    print()
    targets = {"stochastic": 2.0, "none": 1.5}
    for jac in args.jacobi:
        sel = [r for r in main_rows if r["jacobi"] == jac]
        ns = [r["n"] for r in sel]
        slope, local = fit_exponent(ns, [r["us_per_sample"] for r in sel])
        wslope, wlocal = fit_exponent(ns, [r["wall_us_per_sample"] for r in sel])
        pairs = ", ".join(f"{a}→{b}: {x:.2f}" for a, b, x in zip(ns, ns[1:], local))
        wpairs = ", ".join(f"{x:.2f}" for x in wlocal)
        limit = targets.get(jac)
        verdict = "" if limit is None or not math.isfinite(slope) else (
            f"; target ≤ {limit:g}: {'met' if slope <= limit else 'NOT met'}")
        print(f"- Jacobi {jac}: fitted exponent **{slope:.2f}** (cpu; wall {wslope:.2f})"
              f"{verdict}; local slopes {pairs} (wall: {wpairs})")
    print(f"- {load()}\n", flush=True)

    if marginal:
        print(f"## Marginal cost of a sample: (step at batch {marginal} - step at batch "
              f"{args.batch}) / {marginal - args.batch} ({load()})\n")
        print("What a sample costs without the per-batch work (the heads' P @ W, the "
              "optimiser update, the minibatch gather's setup).\n")
        print("| n | Jacobi | ms/step cpu at B=" + str(args.batch) + " | at B=" + str(marginal)
              + " | marginal µs/sample (cpu) | per-batch part ms/step (cpu) |")
        print("|---|---|---|---|---|---|")
        marg = {}
        for r in main_rows:
            r2 = next((x for x in rows if (x["n"], x["jacobi"], x["requested_batch"])
                       == (r["n"], r["jacobi"], marginal)), None)
            if r2 is None:
                continue
            per = (r2["cpu_ms"] - r["cpu_ms"]) / (marginal - args.batch)
            fixed = r["cpu_ms"] - per * args.batch
            marg.setdefault(r["jacobi"], []).append((r["n"], 1e3 * per))
            print(f"| {r['n']} | {r['jacobi']} | {r['cpu_ms']:.2f} | {r2['cpu_ms']:.2f} | "
                  f"{1e3 * per:.2f} | {fixed:.2f} |")
        print()
        for jac, pts in marg.items():
            if all(c > 0 for _, c in pts):
                slope, local = fit_exponent([a for a, _ in pts], [c for _, c in pts])
                print(f"- Jacobi {jac}: exponent of the marginal cost per sample "
                      f"**{slope:.2f}**; local slopes "
                      + ", ".join(f"{x:.2f}" for x in local))
            else:
                print(f"- Jacobi {jac}: a marginal cost came out ≤ 0 (noise); no exponent")
        print(f"- {load()}\n", flush=True)

    nmax = max(r["n"] for r in main_rows)
    at = {r["jacobi"]: r for r in main_rows if r["n"] == nmax}
    print(f"## Where the time goes at n = {nmax} ({load()})\n")
    if "none" in at and "stochastic" in at:
        d = at["stochastic"]["cpu_ms"] - at["none"]["cpu_ms"]
        print(f"- stochastic Jacobi term: {d:.2f} cpu ms/step of {at['stochastic']['cpu_ms']:.2f}"
              f" ({d / at['stochastic']['cpu_ms']:.0%}); the rest (four networks, residual, "
              f"degeneracy) {at['none']['cpu_ms']:.2f} ms/step")
    heads = head_fold_ms(nmax, 64, 3 if q else 5)
    for name, h in heads.items():
        print(f"- {name} head fold (signed gather of W's rows, n^2 x 64): {h['fwd']:.2f} cpu ms "
              f"forward, {h['grad']:.2f} cpu ms with its weight gradient (per call site and step, "
              f"independent of the batch); the dense P @ W it replaced: "
              f"{h['mflop_dense']:.4g} MFLOP forward")
    for jac, r in at.items():
        if r["mflop_per_sample"]:
            total = r["mflop_per_sample"] * r["batch"]
            print(f"- Jacobi {jac}: XLA counts {total / 1e3:.1f} GFLOP/step")
    print()

    if train_steps > 0:
        stoch = [s for s in last if s.jacobi == "stochastic"]
        if stoch:
            t = train_check(stoch[0], train_steps)
            (v0, p0), (v1, p1) = t["first"], t["last"]
            terms = "; ".join(f"{k} {p0[k]:.3e} → {p1[k]:.3e}" for k in p0)
            print(f"## Training check: n = {t['n']}, fully learned, stochastic Jacobi, batch "
                  f"{stoch[0].batch} ({load()})\n")
            print(f"- {t['steps']} steps in {t['seconds']:.1f} s wall: mean loss of the first "
                  f"chunk {v0:.4e}, of the last {v1:.4e} (×{v1 / v0:.3g}): "
                  f"{'decreases' if v1 < v0 else 'DOES NOT DECREASE'}")
            print(f"- terms (first → last chunk): {terms}")
            print(f"- chunk means: {', '.join(f'{v:.3g}' for v in t['curve'])}\n")
    print(load())
    return 0


if __name__ == "__main__":
    sys.exit(main())
