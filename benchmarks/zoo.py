"""The zoo benchmark: default settings on GENERIC systems that no default was tuned on.

For every zoo case (``metriplex.systems.zoo``): ground-truth training data (seed 0), training
with the **default** settings plus only the structure options that the case's user knows, then
rollouts from unseen initial conditions (seed 1000) over the case's horizon. Prints one table:

    system, n, flags given, rel. L2 (plain and standardised), failed rollouts, training time

- plain rel. L2: ``|pred - obs| / |obs|`` per trajectory (``metriplex evaluate``'s
  ``rollout_error_mean``), mean over test trajectories; a failed rollout counts as inf;
- standardised: the same after dividing every variable by its standard deviation over the test
  data and removing its mean (offsets such as a temperature of 300 K or a spin of 1e4 cannot
  hide an error), ``|D^-1 (pred - obs)| / |D^-1 (obs - mean)|``.

```bash
python benchmarks/zoo.py                         # every case, defaults
python benchmarks/zoo.py --cases oscillator-bath,heat-exchange --set lr=1e-2
python benchmarks/zoo.py --out zoo.json          # also write the rows as JSON
python benchmarks/zoo.py --black-box             # also an unconstrained field, for comparison
python benchmarks/zoo.py --cases thermoelastic-chain --trajectories 96   # more training data
python benchmarks/zoo.py --verdict               # also evaluate's verdict on the test data
```

``--verdict`` also gives each case's trained model, on its unseen test data, the verdict that
``metriplex evaluate`` gives (:func:`metriplex.verdict.verdict`, with the training's history
and units): every zoo system is GENERIC, so "not consistent" there is a false alarm, and a
"cannot tell" says which evidence was short.

``--black-box`` also trains, on the same training data and split, an unconstrained vector field
(:class:`metriplex.verdict.BlackBoxModel`, an MLP of the same width and depth as the GENERIC
model's networks, ``fit``'s defaults, the same scheme's residual) and adds its standardised
error and failed rollouts as a column: where it beats the GENERIC model, the structure (or how it is learned)
costs accuracy on that case; where both miss, the data are the limit.

Cases marked ``held_out`` were not used to choose the defaults (``--tuning`` runs only the
others, ``--held-out`` only those).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false")

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)  # ground truth in float64; training stays float32

import jax.numpy as jnp  # noqa: E402
import jax.random as jr  # noqa: E402
import numpy as np  # noqa: E402

from metriplex.config import RunConfig, reversible_first_on  # noqa: E402
from metriplex.data import Trajectories, state_scale, time_scale  # noqa: E402
from metriplex.diagnostics import evaluate, rollout_data  # noqa: E402
from metriplex.integrate import DiscreteGradient  # noqa: E402
from metriplex.losses import SchemeResidual  # noqa: E402
from metriplex.config import scheme_from_name  # noqa: E402
from metriplex.app.runs import train_run, trained_scheme  # noqa: E402
from metriplex._rounding import needs_float64  # noqa: E402
from metriplex._standardised import standardised_errors  # noqa: E402
from metriplex.systems import generate  # noqa: E402
from metriplex.systems.zoo import ZOO  # noqa: E402
from metriplex.train import fit  # noqa: E402
from metriplex.verdict import BlackBoxModel  # noqa: E402

BAR = 2e-2


def _coerce(value: str):
    if value.lower() in ("true", "false"):  # "False" as a string would be truthy
        return value.lower() == "true"
    for kind in (int, float):
        try:
            return kind(value)
        except ValueError:
            pass
    return None if value == "none" else value


def parse_overrides(items: list[str]) -> dict:
    """``--set KEY=VALUE ...`` as RunConfig fields (``lr-cuts`` spelled ``lr_cuts`` too) and
    their values (:func:`_coerce`)."""
    return {key.replace("-", "_"): _coerce(value)
            for key, _, value in (item.partition("=") for item in items)}


def standardised_error(model, data, scheme, rollout=None) -> tuple[float, list[float]]:
    """Mean over trajectories of ``|D^-1 (pred - obs)| / |D^-1 (obs - mean)|``; ``rollout``:
    the ``rollout_data`` of ``model`` on ``data`` if already computed."""
    out, xs, lengths = rollout_data(model, data, scheme=scheme) if rollout is None else rollout
    errs = standardised_errors(np.asarray(out.xs, np.float64), xs, lengths, data.x)
    return float(np.mean(errs)), errs


def constant_drift(data, rollout) -> float | None:
    """The largest change, over the test rollouts (``rollout_data``'s result), of a variable
    that is constant along every test trajectory, in standard deviations of that variable over
    the test data (``None`` when no variable is constant), over the states each rollout reached
    (a failed one is NaN from its failed step on)."""
    out, xs, lengths = rollout
    xs = np.asarray(xs, np.float64)
    constant = [i for i in range(xs.shape[2])
                if all(np.ptp(xs[k, :T, i]) == 0.0 for k, T in enumerate(lengths))]
    if not constant:
        return None
    pred = np.asarray(out.xs, np.float64)
    d = data.x.std(axis=0)
    scale = np.where(d[constant] > 0, d[constant], 1.0)
    worst = 0.0
    for k, T in enumerate(lengths):
        p = pred[k, :T][:, constant]
        change = np.abs(p - p[0]) / scale
        reached = change[np.isfinite(change)]
        if reached.size:
            worst = max(worst, float(reached.max()))
    return worst


def black_box(train, test, config: RunConfig, horizon: float | None = None) -> dict:
    """Standardised and plain rel. L2 and failed rollouts on ``test`` of an unconstrained field
    trained on ``train`` by ``fit`` with its defaults and, as ``config``'s GENERIC model, the
    same validation split, the residual of the same scheme (``config.scheme``: the one the
    GENERIC model trained with, ``trained_scheme`` of its run), the same width, depth and
    precision (float64 where ``train_run`` chooses it from the data; activation: softplus;
    input statistics and rate units from all of ``train``).

    A discrete-gradient step needs E, S, L and M, which a bare field has not: with that scheme
    the black box trains and rolls out with Crank–Nicolson (``"scheme"`` of the result).
    ``horizon``: also the plain rel. L2 up to that time (``"to_horizon"``)."""
    d = state_scale(train.x)
    rate = d / time_scale(train, d)
    float64 = config.float64 if config.float64 is not None else (  # as train_run decides
        needs_float64(train.pairs(), train.names) is not None)
    dtype = jnp.float64 if float64 else jnp.float32
    box = BlackBoxModel(train.n, width=config.width, depth=config.depth, data=train.x, rate=rate,
                        key=jr.key(config.seed))
    given = config.scheme or "cn"  # the GENERIC model's: trained_scheme of its run
    name = "cn" if isinstance(scheme_from_name(given), DiscreteGradient) else given
    scheme = scheme_from_name(name)
    t0 = time.perf_counter()
    box, history = fit(box, train, loss=SchemeResidual(scheme), validation=config.validation,
                       seed_split=config.seed, scale=rate, dtype=dtype, progress=False,
                       key=jr.key(config.seed + 1))
    seconds = time.perf_counter() - t0
    rollout = rollout_data(box, test, scheme=scheme)
    error, _ = standardised_error(box, test, scheme, rollout)
    report = evaluate(box, test, scheme=scheme, rollout=rollout, horizon=horizon)
    return {"standardised": error, "rel_l2": report["rollout_error_mean"],
            "to_horizon": report.get("rollout_error_to_horizon_mean"),
            "failed": int(report["rollout_failures"]), "scheme": name,
            "steps": history.step[-1] if history.step else 0, "seconds": seconds}


def flag_line(flags: dict) -> str:
    """A case's structure flags as on the command line (``"(none)"`` for none)."""
    return " ".join(f"--{k.replace('_', '-')} {v}" for k, v in flags.items()) or "(none)"


def train_and_test(train, test, config: RunConfig, out: Path,
                   horizon: float | None = None) -> dict:
    """Train ``config``'s model on ``train`` into the run folder ``out`` and roll it out once on
    ``test``: the ``model``, its ``history``, the training ``seconds``, the run's config.json
    (``header``), the ``rollout`` (``rollout_data``'s), evaluate's ``report`` (with the error
    up to ``horizon`` where given) and the ``standardised`` error."""
    model, history, _, _, seconds = train_run(train, config, out, overwrite=True,
                                              progress=False)
    header = json.loads((out / "config.json").read_text())
    scheme = scheme_from_name(trained_scheme(header))  # config's, or the one the data chose
    rollout = rollout_data(model, test, scheme=scheme)
    return {"model": model, "history": history, "seconds": seconds,
            "header": header, "rollout": rollout,
            "report": evaluate(model, test, scheme=scheme, rollout=rollout, horizon=horizon),
            "standardised": standardised_error(model, test, scheme, rollout)[0]}


def verdict_row(run: dict, test, config: RunConfig) -> dict:
    """``metriplex evaluate``'s verdict on ``test`` for a :func:`train_and_test` result, in
    brief: the outcome, the residual ratio and residuals, and the checks that failed."""
    from metriplex.app._warnings import trained_units
    from metriplex.verdict import verdict

    v = verdict(run["model"], test, report=run["report"], history=run["history"],
                scheme=scheme_from_name(trained_scheme(run["header"])), width=config.width,
                depth=config.depth,
                learning_rate=config.lr, batch_size=config.batch_size,
                trained_on=trained_units(run["header"].get("units") or {}))
    return {"outcome": v["outcome"], "ratio": v["ratio"],
            "generic": v["residual_generic_relative"], "black_box": v["residual_black_box_relative"],
            "failed": [r["name"] for r in v["reasons"] if r["passed"] is False],
            "statement": v["statement"]}


def run_case(case, overrides: dict, workdir: Path, seed: int = 0,
             with_black_box: bool = False, trajectories: int | None = None,
             horizon: float | None = None, with_verdict: bool = False,
             noise: float = 0.0) -> dict:
    """Train and test one zoo case (or a case built like one) with the defaults, ``overrides``
    and its flags; ``horizon``: also the plain rel. L2 up to that time (``"to_horizon"``);
    ``with_verdict``: also evaluate's verdict on the test data (:func:`verdict_row`);
    ``noise``: Gaussian noise of this fraction of each variable's standard deviation on every
    training state (one draw, numpy seed 5; the test data stay clean)."""
    system = case.system
    trajectories = case.trajectories if trajectories is None else trajectories
    t0 = time.perf_counter()
    train = generate(system, trajectories=trajectories, steps=case.steps, dt=case.dt,
                     seed=seed)
    test = generate(system, trajectories=case.test_trajectories, steps=case.horizon_steps,
                    dt=case.dt, seed=1000 + seed)
    if noise:
        spread = np.std(train.x, axis=0)
        noisy = train.x + noise * spread * np.random.default_rng(5).normal(size=train.x.shape)
        train = Trajectories(train.trajectory, train.t, noisy, train.names)
    gen_seconds = time.perf_counter() - t0
    config = dataclasses.replace(RunConfig(), **{**case.flags, **overrides})  # --set may replace a flag
    run = train_and_test(train, test, config, workdir / case.name, horizon=horizon)
    history, header, report = run["history"], run["header"], run["report"]
    drift = constant_drift(test, run["rollout"])
    truth = evaluate(system.model, test, scheme=scheme_from_name("cn"), horizon=horizon)
    return {
        "system": case.name,
        "n": system.n,
        "flags": flag_line(case.flags),
        "held_out": case.held_out,
        "scheme": trained_scheme(header),
        "rel_l2": report["rollout_error_mean"],
        "to_horizon": report.get("rollout_error_to_horizon_mean"),
        "rel_l2_standardised": run["standardised"],
        "failed": int(report["rollout_failures"]),
        "test_trajectories": case.test_trajectories,
        "train_trajectories": trajectories,
        "ground_truth_cn_rel_l2": truth["rollout_error_mean"],
        "ground_truth_cn_to_horizon": truth.get("rollout_error_to_horizon_mean"),
        # The share of the motion that L grad E drives, learned and true: near 0 where the true
        # one is not, friction carries the motion and the learned E is not the energy.
        "reversible_share": report["reversible_share"],
        "true_reversible_share": truth["reversible_share"],
        "constant_drift": drift,
        # Above 1, train and evaluate warn: the rollouts make entropy the data do not show.
        "entropy_rise": report.get("entropy_rise_over_data_spread"),
        # How far the learned E moves along the test data, over its spread there (0 for the
        # true E of GENERIC data).
        "energy_change": report.get("energy_change_along_data_over_spread"),
        "train_seconds": run["seconds"],
        "steps": history.step[-1] if history.step else 0,
        "kept_step": history.best_step,
        "first_stage": reversible_first_on(config),
        "generalisation_gap": history.generalisation_gap(),
        "stopped": history.stopped,
        "converged": history.converged,
        "every": (header.get("decided") or {}).get("every"),  # the pairs' spacing in samples
        # The held-out rollout score of the kept model (its validation trajectories, in units
        # of each variable's spread), and every training's where --repeats trained again.
        "held_out_score": history.best_rollout,
        **{k: header.get(k) for k in ("trainings", "kept_training")},
        "data_seconds": gen_seconds,
        "overrides": overrides,
        "black_box": black_box(train, test, dataclasses.replace(
            config, scheme=trained_scheme(header))) if with_black_box else None,
        "verdict": verdict_row(run, test, config) if with_verdict else None,
    }


def _kept(row: dict) -> str:
    """The main stage's step of the kept model; 0 is its start: the untrained model, or the
    first stage's after one (training never beat it)."""
    step = row.get("kept_step")
    start = "0 (first stage's)" if row.get("first_stage") else "0 (untrained)"
    return "-" if step is None else (start if step == 0 else str(step))


def _share(row: dict) -> str:
    """The learned reversible share beside the true one ("-" where L = 0)."""
    learned, true = row.get("reversible_share"), row.get("true_reversible_share")
    if learned is None and true is None:
        return "-"
    f = lambda v: "-" if v is None else f"{v:.2g}"  # noqa: E731
    return f"{f(learned)} ({f(true)})"


def _trainings(row: dict) -> str:
    """How many trainings ran (``--repeats``) and which was kept, with the held-out score of
    each: "1 (0.012)" for one training."""
    runs = row.get("trainings") or [{"score": row.get("held_out_score")}]
    kept = row.get("kept_training", 0) if len(runs) > 1 else 0
    scores = ", ".join("-" if o.get("score") is None else f"{o['score']:.2g}" for o in runs)
    return f"{len(runs)} ({scores})" + (f", kept {kept + 1}" if len(runs) > 1 else "")


def _fmt(v: float) -> str:
    return "inf" if not np.isfinite(v) else f"{v:.2e}"


def _black_box(row: dict) -> str:
    b = row.get("black_box")
    if b is None:
        return ""
    scheme = "" if b["scheme"] == row["scheme"] else f", {b['scheme']}"
    return f" {_fmt(b['standardised'])} ({b['failed']} failed{scheme}) |"


def print_table(rows: list[dict], file=sys.stdout) -> None:
    boxed = any(r.get("black_box") is not None for r in rows)
    head = ("| system | n | flags given | rel. L2 | standardised | failed | CN truth | "
            "L∇E share (true) | steps | kept | trainings | train s | bar |"
            + (" black box, standardised |" if boxed else ""))
    print(head, file=file)
    print("|" + "---|" * (13 + boxed), file=file)
    for r in rows:
        met = r["failed"] == 0 and max(r["rel_l2"], r["rel_l2_standardised"]) <= BAR
        name = r["system"] + (" (held out)" if r["held_out"] else "")
        print(
            f"| {name} | {r['n']} | `{r['flags']}` | {_fmt(r['rel_l2'])} | "
            f"{_fmt(r['rel_l2_standardised'])} | {r['failed']}/{r['test_trajectories']} | "
            f"{_fmt(r['ground_truth_cn_rel_l2'])} | {_share(r)} | {r['steps']} | {_kept(r)} | "
            f"{_trainings(r)} | {r['train_seconds']:.0f} | "
            f"{'met' if met else 'NOT met'} |{_black_box(r)}",
            file=file, flush=True,
        )
    met = sum(r["failed"] == 0 and max(r["rel_l2"], r["rel_l2_standardised"]) <= BAR
              for r in rows)
    for r in rows:
        if r.get("constant_drift") is not None:
            print(f"\n{r['system']}: a variable constant along every test trajectory moves by up "
                  f"to {r['constant_drift']:.2e} standard deviations in its rollouts.", file=file)
    for r in rows:
        v = r.get("verdict")
        if v is not None:
            ratio = "-" if v["ratio"] is None else f"{v['ratio']:.2g}"
            print(f"{r['system']}: verdict {v['outcome']} (ratio {ratio}; failed: "
                  f"{', '.join(v['failed']) or 'none'})", file=file)
    print(f"\n{met} of {len(rows)} cases meet rel. L2 <= {BAR:g} (plain and standardised) with "
          "0 failed rollouts.", file=file)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--cases", help="comma list of zoo cases (default: all)")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--tuning", action="store_true", help="only the cases used to choose defaults")
    g.add_argument("--held-out", action="store_true", help="only the held-out cases")
    p.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE",
                   help="override a training setting (RunConfig field), e.g. lr=1e-2")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", help="also write the rows to this JSON file")
    p.add_argument("--trajectories", type=int,
                   help="training trajectories per case (default: each case's own; the "
                        "validation split is taken from them)")
    p.add_argument("--black-box", action="store_true",
                   help="also train an unconstrained field on the same data, for comparison")
    p.add_argument("--noise", type=float, default=0.0, metavar="FRACTION",
                   help="Gaussian noise of FRACTION of each variable's standard deviation on "
                        "the training states (default 0; the test data stay clean)")
    p.add_argument("--verdict", action="store_true",
                   help="also give each trained model evaluate's verdict on the test data")
    args = p.parse_args(argv)
    overrides = parse_overrides(args.set)
    names = args.cases.split(",") if args.cases else list(ZOO)
    unknown = [n for n in names if n not in ZOO]
    if unknown:
        p.error(f"unknown zoo case(s) {unknown}; known: {', '.join(ZOO)}")
    cases = [ZOO[n] for n in names]
    if args.tuning:
        cases = [c for c in cases if not c.held_out]
    if args.held_out:
        cases = [c for c in cases if c.held_out]
    print(f"zoo benchmark: {len(cases)} cases, overrides {overrides or 'none'}, "
          + (f"noise {args.noise:g} on the training states, " if args.noise else "")
          + f"load {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores", flush=True)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for case in cases:
            row = run_case(case, overrides, Path(tmp), seed=args.seed,
                           with_black_box=args.black_box, trajectories=args.trajectories,
                           with_verdict=args.verdict, noise=args.noise)
            rows.append(row)
            print(f"  {row['system']}: rel. L2 {_fmt(row['rel_l2'])}, standardised "
                  f"{_fmt(row['rel_l2_standardised'])}, failed {row['failed']}, "
                  f"{row['train_seconds']:.0f} s ({row['stopped']}), pairs {row['every']} "
                  f"samples apart, learned E moving "
                  f"{'-' if row['energy_change'] is None else _fmt(row['energy_change'])} "
                  "of its spread along the test data", flush=True)
    print()
    print_table(rows)
    if args.out:
        Path(args.out).write_text(json.dumps(rows, indent=1, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
