"""metriplex benchmark suite: training-step cost, compilation, rollouts, memory, utilisation,
time to accuracy. Prints Markdown tables, writes ``results.json`` and the generated part of
``docs/performance.md``.

    .venv/bin/python benchmarks/run.py            # full suite (~15-25 min on 2 busy cores)
    .venv/bin/python benchmarks/run.py --quick    # smoke test for CI (a few seconds of work)

What is measured, and how:

- **training step**: the compiled chunk of :func:`metriplex.fit` itself
  (``metriplex._train.make_chunk``: random minibatch, ``value_and_grad`` of the loss, Adam
  update, ``length`` steps in one compiled loop), on a model and loss made by
  ``_build.build_model`` / ``_build.build_loss`` from data of ``metriplex.systems.generate``.
  Times are medians over repeats after compilation. ``cpu ms`` is process CPU time per step
  (with one compute thread this is the step's cost, and other processes on a shared machine
  disturb it far less than ``wall ms``); targets are judged on it.
- **compile**: seconds to lower and compile that chunk.
- **memory**: XLA's compiled memory analysis (arguments + outputs + temporaries of the step)
  and the process' peak resident set (``getrusage``), device memory stats where the backend
  has them.
- **FLOP**: ``compiled.cost_analysis()['flops']`` per step, against the machine's measured
  float32 matmul rate on the same thread count: the step's utilisation of the machine.
- **rollout**: :func:`metriplex.solve` (Crank–Nicolson, Newton) of 1 and of 64 trajectories
  x 1000 steps, the pendulum ground truth and an untrained learned-size model.
- **time to accuracy**: ``runs/*/metrics.json`` of reference experiments, if present.

One compute thread is pinned by default (docs/design.md, 'Performance rules'): on a shared
machine, compare ratios within one run, never absolute times across runs. ``--threads 0``
leaves XLA's default.
"""

from __future__ import annotations

import os
import sys

# Set before JAX is imported: XLA reads its flags once.
_THREADS = 1
for _i, _a in enumerate(sys.argv):
    if _a == "--threads" and _i + 1 < len(sys.argv):
        _THREADS = int(sys.argv[_i + 1])
    elif _a.startswith("--threads="):
        _THREADS = int(_a.split("=", 1)[1])
if _THREADS == 1:
    os.environ["XLA_FLAGS"] = (
        os.environ.get("XLA_FLAGS", "")
        + " --xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1"
    ).strip()

import argparse  # noqa: E402
import dataclasses  # noqa: E402
import glob  # noqa: E402
import itertools  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import platform  # noqa: E402
import resource  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import equinox as eqx  # noqa: E402
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import jax.random as jr  # noqa: E402
import numpy as np  # noqa: E402

jax.config.update("jax_enable_x64", True)  # float64 rows; float32 rows cast explicitly

import metriplex as mx  # noqa: E402
from metriplex.app._build import build_loss, build_model  # noqa: E402
from metriplex.config import RunConfig, preset, scheme_from_name  # noqa: E402
from metriplex.data import state_scale  # noqa: E402
from metriplex._model import with_dtype  # noqa: E402
from metriplex.systems import generate, get_system  # noqa: E402
from metriplex._pairs import PairRows, PairStore  # noqa: E402
from metriplex._optimizers import default_optimizer  # noqa: E402
from metriplex._train import make_chunk  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
BEGIN = "<!-- benchmarks/run.py: generated results begin -->"
END = "<!-- benchmarks/run.py: generated results end -->"

# Models of the training-step table: (label, system, n, config, Jacobi modes that apply).
MODELS = {
    "rigid-body": ("rigid-body", 3, lambda jac: preset("rigid-body", jacobi=jac),
                   ("none", "exact", "stochastic")),
    "pendulum-energetic": ("pendulum-energetic", 10, lambda jac: preset("pendulum-energetic"),
                           ("none",)),
    "fully-learned": ("pendulum-energetic", 10,
                      lambda jac: RunConfig(features="pendulum", jacobi_probes=1,
                                            **_jacobi_options(jac)),
                      ("none", "exact", "stochastic", "exact@256", "stochastic@256")),
}


def _jacobi_options(jac: str) -> dict:
    """``exact`` -> the penalty on every pair; ``exact@256`` -> on 256 pairs of each batch."""
    estimator, _, samples = jac.partition("@")
    return {"jacobi": estimator, "jacobi_samples": int(samples) if samples else None}
MODEL_NOTES = {
    "rigid-body": "n = 3, rigid-body preset: learned E and L (S = 0, M = 0)",
    "pendulum-energetic": "n = 10, pendulum-energetic preset: canonical L, S = s1 + s2, learned "
                          "E (pendulum features) and M; L is given, so no Jacobi term applies",
    "fully-learned": "n = 10, pendulum data, learned E, S (pendulum features), L and M; "
                     "stochastic Jacobi with 1 probe",
}

# Targets (this 2-core CPU, float32, width 64 x 2). key -> (text, limit, unit, lookup)
TARGETS = [
    ("pendulum n=10, batch 1024, no Jacobi", 10.0, "ms/step",
     ("train", "pendulum-energetic", "none", 1024, "float32")),
    ("fully learned n=10, batch 1024, no Jacobi", 10.0, "ms/step",
     ("train", "fully-learned", "none", 1024, "float32")),
    ("fully learned n=10, batch 1024, exact Jacobi", 30.0, "ms/step",
     ("train", "fully-learned", "exact", 1024, "float32")),
    ("fully learned n=10, batch 1024, stochastic Jacobi", 30.0, "ms/step",
     ("train", "fully-learned", "stochastic", 1024, "float32")),
    ("fully learned n=10, batch 1024, exact Jacobi on 256 pairs (--jacobi-samples 256)", 30.0,
     "ms/step", ("train", "fully-learned", "exact@256", 1024, "float32")),
    ("fully learned n=10, batch 1024, stochastic Jacobi on 256 pairs", 30.0, "ms/step",
     ("train", "fully-learned", "stochastic@256", 1024, "float32")),
    ("64 trajectories x 1000 CN steps, learned-size model", 0.3, "s",
     ("rollout", "learned-size", 64)),
    ("64 trajectories x 1000 CN steps, pendulum ground truth", 0.3, "s",
     ("rollout", "ground-truth", 64)),
]


# ------------------------------------------------------------------------------------------
# Machine


def machine(threads: int) -> dict:
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    dev = jax.devices()[0]
    try:
        load = os.getloadavg()
    except OSError:
        load = None
    return {
        "cpu": cpu,
        "cores": os.cpu_count(),
        "platform": platform.platform(),
        "python": platform.python_version(),
        "jax": jax.__version__,
        "jaxlib": getattr(jax.lib, "__version__", None) or _version("jaxlib"),
        "equinox": _version("equinox"),
        "optax": _version("optax"),
        "backend": jax.default_backend(),
        "device": getattr(dev, "device_kind", str(dev)),
        "devices": jax.device_count(),
        "compute_threads": "1 (pinned)" if threads == 1 else "XLA default",
        "xla_flags": os.environ.get("XLA_FLAGS", ""),
        "load_average_at_start": load,
        "date": time.strftime("%Y-%m-%d %H:%M:%S %Z"),
    }


def _version(pkg: str):
    try:
        from importlib.metadata import version

        return version(pkg)
    except Exception:  # metadata is best-effort
        return None


def matmul_rate(size: int, repeats: int) -> float:
    """Measured float32 GFLOP/s of a square matmul (the machine's practical peak)."""
    a = jr.normal(jr.key(0), (size, size), jnp.float32)
    b = jr.normal(jr.key(1), (size, size), jnp.float32)
    f = jax.jit(lambda a, b: a @ b).lower(a, b).compile()
    f(a, b).block_until_ready()
    cpu = []
    for _ in range(repeats):
        c0 = time.process_time()
        f(a, b).block_until_ready()
        cpu.append(time.process_time() - c0)
    return 2 * size**3 / min(cpu) / 1e9  # min: the unloaded rate


# ------------------------------------------------------------------------------------------
# Training step


def _cost(compiled) -> dict:
    out = {}
    try:
        cost = compiled.cost_analysis()
        if isinstance(cost, (list, tuple)):
            cost = cost[0]
        out["flops"] = float(cost["flops"])
    except Exception:  # backend dependent
        out["flops"] = None
    try:
        m = compiled.memory_analysis()
        out["memory_bytes"] = int(
            m.argument_size_in_bytes + m.output_size_in_bytes + m.temp_size_in_bytes
            - m.alias_size_in_bytes
        )
        out["temp_bytes"] = int(m.temp_size_in_bytes)
    except Exception:  # backend dependent
        out["memory_bytes"] = out["temp_bytes"] = None
    return out


_DATA: dict = {}


def training_data(system: str, quick: bool):
    if system not in _DATA:
        traj, steps = (4, 40) if quick else (20, 200)
        sysobj = get_system(system)
        dt = sysobj.defaults.dt
        _DATA[system] = generate(sysobj, trajectories=traj, steps=steps, dt=dt, seed=0)
    return _DATA[system]


def compile_train_step(model_name: str, jac: str, batch: int, dtype, length: int, quick: bool):
    system, n, make_config, _ = MODELS[model_name]
    config = make_config(jac)
    config = dataclasses.replace(config, batch_size=batch)
    data = training_data(system, quick)
    model = build_model(config, data, key=jr.key(0))
    model = with_dtype(model, dtype)
    loss = build_loss(config)
    full = PairStore.of(PairRows.of(data, None, "benchmark"), state_scale(data.x), dtype)
    optimizer = default_optimizer(config.lr, 10_000)
    params, static = eqx.partition(model, eqx.is_inexact_array)
    opt_state = optimizer.init(params)
    chunk = make_chunk(loss, optimizer, static, batch)
    fn = jax.jit(chunk, static_argnums=3)
    t0 = time.perf_counter()
    compiled = fn.lower(params, opt_state, jr.key(1), length, full).compile()
    compile_s = time.perf_counter() - t0
    cost = _cost(compiled)  # XLA's cost analysis counts a scan body once: FLOP per step
    state = {"p": params, "o": opt_state, "k": jr.key(2)}

    def run():
        state["k"], sub = jr.split(state["k"])
        jax.block_until_ready(sub)
        w0, c0 = time.perf_counter(), time.process_time()
        p, o, v, _ = compiled(state["p"], state["o"], sub, full)
        jax.block_until_ready((p, o, v))
        w, c = time.perf_counter() - w0, time.process_time() - c0
        state["p"], state["o"] = p, o
        if not bool(jnp.isfinite(v)):
            raise RuntimeError(f"{model_name}/{jac}/{batch}: non-finite loss {v}")
        return w / length, c / length

    run()  # warm-up (first execution allocates)
    return run, compile_s, cost


def bench_training(args) -> list[dict]:
    rows = []
    dtypes = [("float32", jnp.float32)] + ([] if args.quick else [("float64", jnp.float64)])
    for model_name in args.models:
        _, n, _, jacs = MODELS[model_name]
        for dname, dtype in dtypes:
            for batch in (args.float64_batches if dname == "float64" else args.batches):
                runs = {}
                jacs = [j for j in jacs if j in args.jacobi] or list(jacs[:1])
                for jac in jacs:
                    runs[jac] = compile_train_step(
                        model_name, jac, batch, dtype, args.length, args.quick
                    )
                # Interleave the Jacobi modes repeat by repeat: load hits them alike.
                samples = {jac: [] for jac in jacs}
                t_end = time.perf_counter() + args.budget
                for r in range(args.max_repeats):
                    for jac in jacs:
                        samples[jac].append(runs[jac][0]())
                    if r + 1 >= args.repeats and time.perf_counter() > t_end:
                        break
                for jac in jacs:
                    wall = statistics.median(s[0] for s in samples[jac])
                    cpu = statistics.median(s[1] for s in samples[jac])
                    _, compile_s, cost = runs[jac]
                    row = dict(
                        model=model_name, n=n, jacobi=jac, batch=batch, dtype=dname,
                        cpu_ms=1e3 * cpu, wall_ms=1e3 * wall, steps_per_s=1.0 / cpu,
                        wall_steps_per_s=1.0 / wall, compile_s=compile_s,
                        repeats=len(samples[jac]), length=args.length, **cost,
                    )
                    if row["flops"]:
                        row["gflop_per_step"] = row["flops"] / 1e9
                        row["gflops"] = row["flops"] / cpu / 1e9
                        row["flop_per_sample"] = row["flops"] / batch
                    rows.append(row)
                    print(_train_line(row), flush=True)
                del runs
    return rows


def _train_line(r):
    return (f"  {r['model']:<19} {r['jacobi']:<10} B={r['batch']:<5} {r['dtype']}: "
            f"{r['cpu_ms']:9.2f} cpu ms  {r['wall_ms']:9.2f} wall ms  "
            f"compile {r['compile_s']:5.1f} s")


# ------------------------------------------------------------------------------------------
# Rollouts


def bench_rollout(args) -> list[dict]:
    rows = []
    system = get_system("pendulum-energetic")
    dt = system.defaults.dt
    models = {"ground-truth": system.model}
    if "learned-size" in args.rollout_models:
        data = training_data("pendulum-energetic", args.quick)
        models["learned-size"] = build_model(preset("pendulum-energetic"), data, key=jr.key(0))
    x0_all = np.asarray(system.sample_initial(max(args.rollout_batches), seed=1))
    ts = jnp.arange(args.rollout_steps + 1, dtype=jnp.float32) * dt
    for name, model in models.items():
        if name not in args.rollout_models:
            continue
        model = with_dtype(model, jnp.float32)
        for k, solver in itertools.product(args.rollout_batches, args.rollout_solvers):
            x0 = jnp.asarray(x0_all[0] if k == 1 else x0_all[:k], jnp.float32)
            scheme = scheme_from_name("cn", solver=solver)
            t0 = time.perf_counter()
            out = mx.solve(model, x0, ts, scheme=scheme)
            jax.block_until_ready(out.xs)
            first = time.perf_counter() - t0
            wall, cpu = [], []
            for _ in range(args.rollout_repeats):
                w0, c0 = time.perf_counter(), time.process_time()
                out = mx.solve(model, x0, ts, scheme=scheme)
                jax.block_until_ready(out.xs)
                wall.append(time.perf_counter() - w0)
                cpu.append(time.process_time() - c0)
            its = np.asarray(out.iterations)
            row = dict(
                model=name, trajectories=k, steps=args.rollout_steps, dtype="float32",
                solver=solver, cpu_s=statistics.median(cpu), wall_s=statistics.median(wall),
                first_call_s=first, ok=bool(out.ok),
                iterations_mean=float(its[..., 1:].mean()),
            )
            rows.append(row)
            print(f"  rollout {name:<13} {k:>3} x {args.rollout_steps} steps, {solver:<6}: "
                  f"{row['cpu_s']:.3f} cpu s, {row['wall_s']:.3f} wall s "
                  f"(first call {first:.1f} s, {row['iterations_mean']:.2f} "
                  f"iterations/step, ok={row['ok']})", flush=True)
    return rows


# ------------------------------------------------------------------------------------------
# Time to accuracy (reads reference runs made by `metriplex reproduce`)


def time_to_accuracy(runs_dir: Path) -> list[dict]:
    rows = []
    for path in sorted(glob.glob(str(runs_dir / "*" / "metrics.json"))):
        try:
            m = json.loads(Path(path).read_text())
        except (OSError, ValueError):
            continue
        if "experiment" not in m or "bars" not in m:
            continue
        rows.append(dict(
            run=str(Path(path).parent.relative_to(ROOT)) if ROOT in Path(path).parents
            else str(Path(path).parent),
            experiment=m["experiment"], quick=m.get("quick"),
            train_seconds=m.get("train_seconds"), best_step=m.get("best_step"),
            stopped=m.get("stopped"),
            bars={k: dict(value=b.get("value"), target=b.get("target"), met=b.get("met"))
                  for k, b in m["bars"].items()},
        ))
    return rows


# ------------------------------------------------------------------------------------------
# Report


def _fmt(v, spec=".2f"):
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "–"
    return format(v, spec)


def _lookup(results, key):
    if key[0] == "train":
        _, model, jac, batch, dtype = key
        for r in results["training"]:
            if (r["model"], r["jacobi"], r["batch"], r["dtype"]) == (model, jac, batch, dtype):
                return r["cpu_ms"], r["wall_ms"]
    else:
        _, model, k = key
        for r in results["rollout"]:
            if ((r["model"], r["trajectories"], r.get("solver", "newton")) == (model, k, "auto")
                    and r["steps"] == 1000):
                return r["cpu_s"], r["wall_s"]
    return None


REASONS = {
    # Written from the measurements of the committed results (docs/performance.md, "Where the
    # time goes"); the figures in them are those of that run.
    "pendulum n=10, batch 1024, no Jacobi": (
        "0.40 MFLOP/sample = 0.40 GFLOP/step at ~27 GFLOP/s (~1/3 of the measured matmul "
        "rate); ~30 % of the step is the friction block's batched 10x10 products M = B B^T and "
        "their transposes. 10 ms needs fewer FLOP per sample or ~40 GFLOP/s"),
    "fully learned n=10, batch 1024, no Jacobi": (
        "0.51 MFLOP/sample at ~31 GFLOP/s: four networks, each differentiated twice"),
    "fully learned n=10, batch 1024, exact Jacobi": (
        "1.29 MFLOP/sample (n = 10 forward-mode tangents of L, differentiated again) at ~28 "
        "GFLOP/s; needs ~1.6x fewer FLOP (see the suggestions: reuse L, i<j<l only)"),
    "fully learned n=10, batch 1024, stochastic Jacobi": (
        "0.83 MFLOP/sample at only ~22 GFLOP/s: per-sample 10x10 products of the probes and "
        "~1.5 ms/step of threefry normals"),
    "fully learned n=10, batch 1024, exact Jacobi on 256 pairs (--jacobi-samples 256)": (
        "the rest of the step (four networks, each differentiated twice) is itself ~17 ms"),
    "fully learned n=10, batch 1024, stochastic Jacobi on 256 pairs": (
        "the rest of the step (four networks, each differentiated twice) is itself ~17 ms"),
    "64 trajectories x 1000 CN steps, learned-size model": (
        "with solver=auto ~1 fixed-point iteration per step, i.e. one evaluation of the "
        "learned field (a gradient through the energy network plus the friction network) for "
        "64 states, ~4.5 us per trajectory-step, 1000 steps in sequence; Newton (4x slower) "
        "builds a dense Jacobian of that field each step"),
    "64 trajectories x 1000 CN steps, pendulum ground truth": (
        "1000 sequential implicit solves"),
}


def targets_table(results) -> tuple[str, list[dict]]:
    lines = ["| target | limit | measured (cpu) | wall | met | reason if not |",
             "|---|---|---|---|---|---|"]
    out = []
    for text, limit, unit, key in TARGETS:
        got = _lookup(results, key)
        if got is None:
            continue
        cpu, wall = got
        met = cpu <= limit
        out.append(dict(target=text, limit=limit, unit=unit, measured=cpu, wall=wall, met=met))
        lines.append(f"| {text} | ≤ {limit:g} {unit} | {cpu:.3g} {unit} | {wall:.3g} {unit} | "
                     f"{'met' if met else 'not met'} | {'' if met else REASONS.get(text, '')} |")
    return "\n".join(lines), out


def _row_key(section: str, r: dict) -> tuple:
    if section == "training":
        return (r["model"], r["jacobi"], r["batch"], r["dtype"])
    return (r["model"], r["trajectories"], r["steps"], r.get("solver", "newton"))


def merge(results: dict, earlier: dict) -> None:
    """Keep the rows of ``earlier`` that this run did not re-measure (in their old order)."""
    for section in ("training", "rollout"):
        new = {_row_key(section, r): r for r in results[section]}
        kept = []
        for r in earlier.get(section, []):
            key = _row_key(section, r)
            if key in new:
                kept.append(new.pop(key))
            else:
                kept.append({**r, "run": r.get("run", earlier["machine"]["date"])})
        results[section] = kept + list(new.values())
    results["merged_from"] = [earlier["machine"]["date"], *earlier.get("merged_from", [])]
    results["command"] += f" (other rows from the run of {earlier['machine']['date']})"


def report(results) -> str:
    m = results["machine"]
    parts = []
    parts.append("### Machine\n")
    parts.append(
        f"- CPU: {m['cpu']}, {m['cores']} cores; {m['platform']}\n"
        f"- jax {m['jax']} (jaxlib {m['jaxlib']}), equinox {m['equinox']}, optax {m['optax']}; "
        f"backend **{m['backend']}** ({m['device']}, {m['devices']} device(s))\n"
        f"- compute threads: {m['compute_threads']}; load average at start: "
        f"{m['load_average_at_start']}\n"
        f"- measured float32 matmul rate ({results['matmul_size']}²): "
        f"**{results['matmul_gflops']:.1f} GFLOP/s**\n"
        f"- run: {m['date']}, `{results['command']}`\n"
    )
    if results.get("merged_from"):
        fresh = [r for sec in ("training", "rollout") for r in results[sec]
                 if r.get("run") == m["date"]]
        parts.append(
            f"- merged: {len(fresh)} rows re-measured in this run; the others are kept from "
            f"the run(s) of {', '.join(results['merged_from'])} on this machine (compare "
            "absolute times across runs with care)\n"
        )
    tt, _ = targets_table(results)
    if results.get("targets"):
        parts.append("### Targets (float32, width 64 × 2; judged on CPU time per step)\n")
        parts.append(tt + "\n")
    parts.append("### Training step\n")
    parts.append("Median over repeats after compilation; `cpu ms` = process CPU time per step "
                 "(one compute thread), `wall ms` = elapsed time on the shared machine. "
                 "`util.` = achieved FLOP rate / measured matmul rate.\n")
    for name in dict.fromkeys(r["model"] for r in results["training"]):
        parts.append(f"**{name}** — {MODEL_NOTES[name]}\n")
        parts.append("| dtype | batch | Jacobi | cpu ms/step | wall ms/step | steps/s | "
                     "compile s | MFLOP/sample | GFLOP/s | util. | step memory MB |")
        parts.append("|---|---|---|---|---|---|---|---|---|---|---|")
        for r in results["training"]:
            if r["model"] != name:
                continue
            util = (r.get("gflops") or 0) / results["matmul_gflops"] if r.get("gflops") else None
            mem = r["memory_bytes"] / 2**20 if r.get("memory_bytes") else None
            mfs = r["flop_per_sample"] / 1e6 if r.get("flop_per_sample") else None
            parts.append(
                f"| {r['dtype']} | {r['batch']} | {r['jacobi']} | {r['cpu_ms']:.2f} | "
                f"{r['wall_ms']:.2f} | {r['steps_per_s']:.1f} | {r['compile_s']:.1f} | "
                f"{_fmt(mfs, '.3f')} | {_fmt(r.get('gflops'), '.1f')} | "
                f"{_fmt(util, '.0%')} | {_fmt(mem, '.1f')} |"
            )
        parts.append("")
    parts.append("### Rollouts (metriplex.solve, Crank–Nicolson, float32)\n")
    parts.append("`auto` (the default): fixed-point iteration, Newton only where it does not "
                 "converge; `newton`: Newton at every step.\n")
    parts.append("| model | trajectories × steps | solver | cpu s | wall s | "
                 "first call s (compile) | iterations/step | ok |")
    parts.append("|---|---|---|---|---|---|---|---|")
    for r in results["rollout"]:
        its = r.get("iterations_mean", r.get("newton_iterations_mean"))
        parts.append(f"| {r['model']} | {r['trajectories']} × {r['steps']} | "
                     f"{r.get('solver', 'newton')} | {r['cpu_s']:.3f} | "
                     f"{r['wall_s']:.3f} | {r['first_call_s']:.1f} | {its:.2f} | {r['ok']} |")
    parts.append("")
    parts.append("### Memory\n")
    mem = results["memory"]
    parts.append(f"- process peak resident set: **{mem['peak_rss_mb']:.0f} MB** "
                 "(whole run, all compiled programs)")
    parts.append(f"- device memory stats: {mem['device_memory'] or 'not reported by this backend'}")
    parts.append("- per-step footprint (arguments + outputs + temporaries, from XLA's memory "
                 "analysis): the last column of the training tables\n")
    parts.append("### Time to accuracy (reference runs in runs/)\n")
    tta = results["time_to_accuracy"]
    if not tta:
        parts.append("No `runs/*/metrics.json` from `metriplex reproduce` found at the time of "
                     "this run.\n")
    else:
        parts.append("| run | experiment | training s | best step | bars |")
        parts.append("|---|---|---|---|---|")
        for r in tta:
            bars = "; ".join(
                f"{k} {_fmt(b['value'], '.2e')} {'≥' if k == 'entropy_min_step' else '≤'} "
                f"{_fmt(b['target'], '.0e')}: "
                f"{'met' if b['met'] else 'not met'}" for k, b in r["bars"].items()
            )
            quick = " (quick)" if r["quick"] else ""
            parts.append(f"| {r['run']} | {r['experiment']}{quick} | "
                         f"{_fmt(r['train_seconds'], '.0f')} | {r['best_step']} | {bars} |")
        parts.append("")
    return "\n".join(parts)


def write_docs(path: Path, body: str) -> None:
    block = f"{BEGIN}\n{body}\n{END}"
    if path.exists():
        text = path.read_text()
        if BEGIN in text and END in text:
            text = text[: text.index(BEGIN)] + block + text[text.index(END) + len(END):]
        else:
            text = text.rstrip() + "\n\n## Measured results\n\n" + block + "\n"
    else:
        text = ("# Performance\n\nGenerated by `benchmarks/run.py`.\n\n## Measured results\n\n"
                + block + "\n")
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true",
                    help="tiny sizes, few repeats, float32 only; writes no docs by default")
    ap.add_argument("--threads", type=int, default=1,
                    help="1 (default): pin one compute thread; 0: XLA's default")
    ap.add_argument("--models", nargs="*", default=None, choices=list(MODELS))
    ap.add_argument("--batches", type=int, nargs="*", default=None)
    ap.add_argument("--float64-batches", type=int, nargs="*", default=None,
                    help="batches timed in float64 (default: the same as --batches)")
    ap.add_argument("--jacobi", nargs="*", default=None, choices=["none", "exact", "stochastic", "exact@256", "stochastic@256"],
                    help="Jacobi modes to time (where the model has a learned L)")
    ap.add_argument("--out", type=Path, default=None,
                    help="folder for results.json (default benchmarks/)")
    ap.add_argument("--docs", type=Path, default=None,
                    help="Markdown file to update (default docs/performance.md; none with "
                         "--quick unless given)")
    ap.add_argument("--runs", type=Path, default=ROOT / "runs",
                    help="folder of reference runs for time to accuracy")
    ap.add_argument("--skip", nargs="*", default=[], choices=["training", "rollout"])
    ap.add_argument("--merge", type=Path, default=None, metavar="RESULTS_JSON",
                    help="re-measure only what the other options select and keep every other "
                         "row of this earlier results.json (each row says which run made it)")
    ap.add_argument("--report-only", type=Path, default=None, metavar="RESULTS_JSON",
                    help="measure nothing: re-render the tables (and --docs) from a results.json")
    args = ap.parse_args(argv)
    q = args.quick
    args.models = args.models or (["rigid-body"] if q else list(MODELS))
    if args.float64_batches is None:
        args.float64_batches = args.batches
    args.jacobi = args.jacobi or (
        ["exact"] if q else ["none", "exact", "stochastic", "exact@256", "stochastic@256"]
    )
    args.batches = args.batches or ([32] if q else [256, 1024, 8192])
    args.length = 2 if q else 4
    args.repeats = 2 if q else 5
    args.max_repeats = 2 if q else 30
    args.budget = 0.0 if q else 3.0
    args.rollout_batches = [4] if q else [1, 64]
    args.rollout_models = ["ground-truth"] if q else ["ground-truth", "learned-size"]
    args.rollout_steps = 20 if q else 1000
    args.rollout_repeats = 2 if q else 5
    args.rollout_solvers = ["auto"] if q else ["newton", "auto"]
    out = args.out or ROOT / "benchmarks"
    docs = args.docs or (None if q else ROOT / "docs" / "performance.md")
    if args.report_only is not None:
        results = json.loads(args.report_only.read_text())
        _, results["targets"] = targets_table(results)
        text = report(results)
        print(text)
        if docs is not None:
            write_docs(docs, text)
        return 0

    results = {"command": " ".join(["benchmarks/run.py", *(argv or sys.argv[1:])]),
               "machine": machine(args.threads), "quick": q}
    print(f"# metriplex benchmarks ({'quick' if q else 'full'})\n")
    m = results["machine"]
    print(f"{m['cpu']}, {m['cores']} cores; jax {m['jax']}, backend {m['backend']}; "
          f"compute threads: {m['compute_threads']}\n", flush=True)
    results["matmul_size"] = 256 if q else 1024
    results["matmul_gflops"] = matmul_rate(results["matmul_size"], 3 if q else 10)
    results["training"] = [] if "training" in args.skip else bench_training(args)
    results["rollout"] = [] if "rollout" in args.skip else bench_rollout(args)
    for r in results["training"] + results["rollout"]:
        r["run"] = results["machine"]["date"]
    if args.merge is not None:
        merge(results, json.loads(args.merge.read_text()))
    results["time_to_accuracy"] = time_to_accuracy(args.runs)
    dev = jax.devices()[0]
    try:
        stats = dev.memory_stats()
    except Exception:  # not every backend has them
        stats = None
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    peak_mb = peak / 2**20 if sys.platform == "darwin" else peak / 1024
    results["memory"] = {"peak_rss_mb": peak_mb, "device_memory": stats}
    _, results["targets"] = targets_table(results)
    text = report(results)
    print("\n" + text)
    out.mkdir(parents=True, exist_ok=True)
    (out / "results.json").write_text(json.dumps(results, indent=1, default=str) + "\n")
    print(f"wrote {out / 'results.json'}")
    if docs is not None:
        write_docs(docs, text)
        print(f"wrote {docs}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
