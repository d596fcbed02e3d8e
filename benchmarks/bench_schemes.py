"""Ground truth rolled out with every time-stepping scheme, against SciPy's DOP853.

For the ``unit`` and ``spnn`` thermoelastic pendulums and the rigid body, at the published
time steps, each scheme (cn, midpoint, discrete-gradient, rk4) rolls out the analytic model in
float64 from the same initial states. Reported per scheme: the maximum error against DOP853
(rtol = atol = 1e-12) over all trajectories and times, the relative energy drift
max |E(t) - E(0)| / |E(0)|, the smallest entropy change of one step, the mean Newton
iterations per step, and the wall time per trajectory-step (batched rollout, compiled, best of
``--repeats``). A second table times the batched float32 Crank–Nicolson and discrete-gradient
rollouts of 64 unit pendulums x 1000 steps (targets in docs/performance.md).

```
.venv/bin/python benchmarks/bench_schemes.py                       # print the tables
.venv/bin/python benchmarks/bench_schemes.py --write docs/schemes.md  # and update the docs
```

One compute thread is pinned, as docs/design.md, 'Performance rules', asks; compare times within
one run only.
"""

from __future__ import annotations

import argparse
import datetime
import os
import pathlib
import platform
import re
import sys
import time

os.environ.setdefault(
    "XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1"
)

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from scipy.integrate import solve_ivp  # noqa: E402

from metriplex.integrate import RK4, CrankNicolson, DiscreteGradient, ImplicitMidpoint, solve  # noqa: E402
from metriplex.systems import get_system  # noqa: E402

SCHEMES = (CrankNicolson(), ImplicitMidpoint(), DiscreteGradient(), RK4())
BEGIN, END = "<!-- bench_schemes:begin -->", "<!-- bench_schemes:end -->"


def cases(quick: bool):
    """(label, system, dt, steps): the published settings, plus the unit pendulum at dt=0.01
    (the finer step of docs/physics.md, 'Numerics of the pendulum') and the pendulum in
    (q, p, theta) at dt=0.1, where docs/physics.md, 'Thermoelastic pendulum in temperature
    variables', notes negative entropy steps of Crank–Nicolson."""
    unit = get_system("pendulum-energetic", parameter_set="unit")
    spnn = get_system("pendulum-energetic", parameter_set="spnn")
    rigid = get_system("rigid-body")
    temperature = get_system("pendulum-temperature")
    out = [
        ("pendulum `unit`", unit, unit.defaults.dt, unit.defaults.steps),
        ("pendulum `unit`", unit, 0.01, 4000),
        ("pendulum `spnn`", spnn, spnn.defaults.dt, spnn.defaults.steps),
        ("rigid body", rigid, rigid.defaults.dt, rigid.defaults.steps),
        ("pendulum (q, p, θ) `unit`", temperature, 0.1, 400),
    ]
    if quick:
        out = [(label, s, dt, min(steps, 200)) for label, s, dt, steps in out]
    return out


def reference(model, x0, ts):
    """DOP853 (rtol = atol = 1e-12) on the grid ``ts``, one trajectory at a time."""
    f = jax.jit(model.vector_field)

    def rhs(t, x):
        return np.asarray(f(jnp.asarray(x)))

    rows = []
    for x in x0:
        sol = solve_ivp(rhs, (ts[0], ts[-1]), x, method="DOP853", t_eval=ts, rtol=1e-12,
                        atol=1e-12)
        if not sol.success:
            raise RuntimeError(f"DOP853 failed: {sol.message}")
        rows.append(sol.y.T)
    return np.stack(rows)


def measure(model, scheme, x0, ts, exact, repeats):
    x0j, tsj = jnp.asarray(x0), jnp.asarray(ts)
    out = solve(model, x0j, tsj, scheme=scheme)  # compile
    jax.block_until_ready(out.xs)
    best = np.inf
    for _ in range(repeats):
        start = time.perf_counter()
        out = solve(model, x0j, tsj, scheme=scheme)
        jax.block_until_ready(out.xs)
        best = min(best, time.perf_counter() - start)
    xs = np.asarray(out.xs)
    failed = np.asarray(out.failed_step)
    steps = len(ts) - 1
    row = {"time_us": 1e6 * best / (steps * len(x0))}
    row["failed"] = int(failed.min()) if np.any(failed >= 0) else -1
    if np.any(failed >= 0):
        row["failed"] = int(failed[failed >= 0].min())
    energy = np.asarray(jax.vmap(jax.vmap(model.energy))(out.xs))
    entropy = np.asarray(jax.vmap(jax.vmap(model.entropy))(out.xs))
    with np.errstate(invalid="ignore"):
        row["error"] = float(np.nanmax(np.abs(xs - exact))) if np.isfinite(xs).any() else np.nan
        row["drift"] = float(np.nanmax(np.abs(energy - energy[:, :1]) / np.abs(energy[:, :1])))
        row["min_ds"] = float(np.nanmin(np.diff(entropy, axis=1)))
    its = np.asarray(out.iterations)[:, 1:]
    row["newton"] = float(its.mean()) if scheme.name != "rk4" else np.nan
    return row


def fmt(v, kind):
    if v is None or (isinstance(v, float) and not np.isfinite(v)):
        return "—"
    if kind == "e":
        return f"{v:.1e}"
    if kind == "f":
        return f"{v:.2f}"
    return f"{v:.0f}"


def accuracy_table(trajectories: int, repeats: int, quick: bool) -> str:
    lines = [
        "| system | dt | steps | scheme | max error vs DOP853 | energy drift | min ΔS per step "
        "| Newton its / step | µs / trajectory-step |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for label, system, dt, steps in cases(quick):
        model = system.model
        x0 = system.sample_initial(trajectories, seed=0)
        ts = np.arange(steps + 1) * dt
        exact = reference(model, x0, ts)
        for scheme in SCHEMES:
            r = measure(model, scheme, x0, ts, exact, repeats)
            if r["failed"] >= 0:
                err = f"fails at step {r['failed']}"
                drift = min_ds = "—"
            else:
                err, drift = fmt(r["error"], "e"), fmt(r["drift"], "e")
                min_ds = fmt(r["min_ds"], "e") if system.name != "rigid-body" else "(S = 0)"
            lines.append(
                f"| {label} | {dt:.4g} | {steps} | {scheme.name} | {err} | {drift} | {min_ds} "
                f"| {fmt(r['newton'], 'f')} | {fmt(r['time_us'], 'f')} |"
            )
            print(lines[-1], flush=True)
    return "\n".join(lines)


def throughput_table(repeats: int) -> str:
    """64 unit pendulums x 1000 steps in float32 (the target in docs/performance.md: <= 0.3 s for
    CN)."""
    system = get_system("pendulum-energetic", parameter_set="unit")
    x0 = jnp.asarray(system.sample_initial(64, seed=0), jnp.float32)
    lines = [
        "| scheme | dt | wall time, 64 × 1000 steps (best of {}) | Newton its / step "
        "(batch max) |".format(repeats),
        "|---|---|---|---|",
    ]
    for scheme in (CrankNicolson(), DiscreteGradient()):
        for dt in (0.01, 0.1):
            ts = jnp.arange(1001, dtype=jnp.float32) * jnp.float32(dt)
            out = solve(system.model, x0, ts, scheme=scheme)
            jax.block_until_ready(out.xs)
            best = np.inf
            for _ in range(repeats):
                start = time.perf_counter()
                out = solve(system.model, x0, ts, scheme=scheme)
                jax.block_until_ready(out.xs)
                best = min(best, time.perf_counter() - start)
            assert out.ok and out.xs.dtype == jnp.float32
            its = np.asarray(out.iterations)[:, 1:].max(axis=0).mean()
            lines.append(f"| {scheme.name} | {dt} | {best:.3f} s | {its:.2f} |")
            print(lines[-1], flush=True)
    return "\n".join(lines)


def machine() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        for line in pathlib.Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{cpu}, {os.cpu_count()} cores, JAX {jax.__version__}, one compute thread"


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--trajectories", type=int, default=5)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--quick", action="store_true", help="at most 200 steps per case")
    parser.add_argument("--write", type=pathlib.Path, help="update the results block of this file")
    args = parser.parse_args(argv)

    command = "python benchmarks/bench_schemes.py" + "".join(
        f" {a}" for a in (argv if argv is not None else sys.argv[1:])
    )
    accuracy = accuracy_table(args.trajectories, args.repeats, args.quick)
    speed = throughput_table(max(args.repeats, 5))
    block = "\n".join(
        [
            BEGIN,
            f"Measured {datetime.date.today().isoformat()} on {machine()} with `{command}`; "
            f"{args.trajectories} trajectories from `sample_initial(..., seed=0)`, float64.",
            "",
            accuracy,
            "",
            "Batched float32 rollouts of the `unit` pendulum (64 trajectories × 1000 steps):",
            "",
            speed,
            END,
        ]
    )
    print()
    print(block)
    if args.write is not None:
        text = args.write.read_text()
        if BEGIN not in text or END not in text:
            raise SystemExit(
                f"{args.write} has no results block; add the lines {BEGIN} and {END} where the "
                "tables should go."
            )
        pattern = re.compile(re.escape(BEGIN) + ".*?" + re.escape(END), re.S)
        args.write.write_text(pattern.sub(lambda _: block, text))
        print(f"\nwrote the results into {args.write}")


if __name__ == "__main__":
    main()
