"""Default settings on a stand-in for a published (q, p, s) double-pendulum benchmark.

A peer project published a thermoelastic double-pendulum dataset: 50 trajectories x 200
snapshots at dt = 0.3, split 40 for training and 10 for testing, made with one
energy-conserving discrete-gradient step per snapshot, with stiff heat conduction (relaxation
rate about 120 per time unit, so 36 relaxation times per snapshot) and close passes of mass 1
by the pivot. Its published network reaches a mean relative L2 error of about 0.033 on the 10
test trajectories. The dataset itself is not shipped here; this script builds two stand-ins
with the ``spnn`` parameter set of ``pendulum-energetic`` (the same masses, lengths and
effective constants; initial states are our own choice, see ``PendulumConfig``):

- ``flow``: the exact flow (fine RK4 substeps), sampled at dt = 0.3;
- ``dg``: one discrete-gradient step per snapshot, as the published data were made.

Beside the trained GENERIC model, the table shows the plain rel. L2 of an unconstrained vector
field trained on the same data and split with ``fit``'s defaults and the same scheme's residual
(``BlackBoxModel``, as ``zoo.py --black-box``): what the data allow a model with no structure.

For each, training uses the defaults plus one of two sets of structure flags (``--given``):

- ``physics``: what a user who knows the physics gives, ``--poisson canonical:4 --entropy
  sum:8,9`` (E and M learned);
- ``file``: what the published dataset file holds beside the trajectories, a constant L and M
  (``--poisson file:L.npy --friction file:M.npy``; L canonical, M = [[1, -1], [-1, 1]] on
  (s1, s2): heat conduction between the springs at equal temperatures, the form the peer's
  network is given; its scale is immaterial since S is learned) with E and S learned
  (``--entropy neural``), as the peer's network learns them.

Training is on trajectories 0-39 (validation split from them), and the table reports the 10
test trajectories 40-49: plain and standardised rel. L2, failed rollouts, the true model
rolled out by each scheme at the same dt (what a perfect vector field would reach with that
scheme) and the trivial prediction x(t) = x(0). Over the 60 time units the rel. L2 mostly
rewards a model that stays bounded near the data, an almost untrained one included; the
error up to t = 3 (ten steps) and the step of the model kept say whether it learned the
dynamics.

```bash
python benchmarks/published_pendulum.py                    # both stand-ins, both flag sets
python benchmarks/published_pendulum.py --data dg --given file --set scheme=discrete-gradient
```
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false")

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)  # ground truth in float64; training stays float32

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))

from zoo import _fmt, black_box, parse_overrides, train_and_test  # noqa: E402

from metriplex.config import RunConfig, scheme_from_name  # noqa: E402
from metriplex.app.runs import trained_scheme  # noqa: E402
from metriplex.diagnostics import evaluate  # noqa: E402
from metriplex.integrate import DiscreteGradient  # noqa: E402
from metriplex.systems import SYSTEMS, generate  # noqa: E402

FLAGS = {"poisson": "canonical:4", "entropy": "sum:8,9"}  # --given physics


def file_flags(folder: Path) -> dict:
    """--given file: the constant L and M of the dataset file, written as .npy to ``folder``;
    E and S learned."""
    n, eye = 10, np.eye(4)
    L = np.zeros((n, n))
    L[:4, 4:8], L[4:8, :4] = eye, -eye
    M = np.zeros((n, n))
    M[8:, 8:] = [[1.0, -1.0], [-1.0, 1.0]]
    np.save(folder / "L.npy", L)
    np.save(folder / "M.npy", M)
    return {"poisson": f"file:{folder / 'L.npy'}", "friction": f"file:{folder / 'M.npy'}",
            "entropy": "neural"}


# Over 60 time units the stand-ins' rel. L2 mostly rewards a model that stays bounded near the
# data (x(t) = x(0) reaches ~1.1, an almost untrained model ~0.6); the error up to t = 3 (ten
# steps) tells whether a model follows the dynamics at all.
SHORT = 3.0
PUBLISHED = 0.033  # the peer's network on the real dataset (mean rel. L2, 10 test trajectories)


def stand_in(kind: str):
    """50 trajectories x 200 snapshots at dt = 0.3 of the ``spnn`` pendulum (seed 0)."""
    system = SYSTEMS["pendulum-energetic"].with_params(parameter_set="spnn")
    extra = {"scheme": DiscreteGradient(), "substeps": 1} if kind == "dg" else {}
    return system, generate(system, trajectories=50, steps=199, dt=0.3, seed=0, **extra)


def constant_prediction_error(data) -> float:
    """Mean rel. L2 of predicting x(t) = x(0) on every trajectory."""
    errs = [np.linalg.norm(x - x[0]) / np.linalg.norm(x) for _, x in data]
    return float(np.mean(errs))


def run(kind: str, given: list[str], overrides: dict, workdir: Path) -> list[dict]:
    """One row per flag set of ``given`` on the stand-in ``kind`` (the black box, the truth and
    x(t) = x(0) are the same for both)."""
    system, data = stand_in(kind)
    train, test = data.select(list(range(40))), data.select(list(range(40, 50)))
    rows, box = [], None
    for flags in given:
        base = FLAGS if flags == "physics" else file_flags(workdir)
        config = dataclasses.replace(RunConfig(), **{**base, **overrides})  # --set may override
        row = _train_and_test(system, train, test, config, workdir / f"{kind}-{flags}")
        box = black_box(train, test, dataclasses.replace(config, scheme=row["scheme"]),
                        horizon=SHORT) if box is None else box
        rows.append({"data": kind, "given": flags, **row, "black_box": box})
    return rows


def _train_and_test(system, train, test, config, out: Path) -> dict:
    run = train_and_test(train, test, config, out, horizon=SHORT)
    report, history = run["report"], run["history"]
    truth = {name: evaluate(system.model, test, scheme=scheme_from_name(name))
             for name in ("cn", "midpoint", "discrete-gradient")}
    return {
        "scheme": trained_scheme(run["header"]),  # given, or the one the data chose
        "rel_l2": report["rollout_error_mean"],
        "to_short": report["rollout_error_to_horizon_mean"],
        "rel_l2_completed": report["rollout_error_mean_completed"],
        "standardised": run["standardised"],
        "failed": int(report["rollout_failures"]),
        "truth": {k: v["rollout_error_mean"] for k, v in truth.items()},
        "constant": constant_prediction_error(test),
        "steps": history.step[-1] if history.step else 0,
        "kept_step": history.best_step,
        "stopped": history.stopped,
        "seconds": run["seconds"],
    }


def _opt(v: float | None) -> str:
    return "–" if v is None else _fmt(v)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--data", choices=["flow", "dg", "both"], default="both")
    p.add_argument("--given", choices=["physics", "file", "both"], default="both",
                   help="structure flags: physics (canonical L, S = s1 + s2), file (the "
                   "dataset's constant L and M, E and S learned), or both")
    p.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE",
                   help="override a training setting (RunConfig field), e.g. scheme=midpoint")
    args = p.parse_args(argv)
    overrides = parse_overrides(args.set)
    kinds = ["flow", "dg"] if args.data == "both" else [args.data]
    given = ["physics", "file"] if args.given == "both" else [args.given]
    print(f"published-pendulum stand-ins {kinds}, flags {given} (physics: {FLAGS}), overrides "
          f"{overrides or 'none'}, load {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores",
          flush=True)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for kind in kinds:
            t0 = time.perf_counter()
            rows.extend(run(kind, given, overrides, Path(tmp)))
            print(f"  {kind}: done in {time.perf_counter() - t0:.0f} s", flush=True)
    print(f"\n| data | given | rel. L2 | to t = {SHORT:g} | over completed | standardised | "
          "failed | truth CN | truth midpoint | truth DG | x(t) = x(0) | black box (plain; "
          f"to t = {SHORT:g}) | steps | kept | train s |")
    print("|" + "---|" * 15)
    for r in rows:
        t, b = r["truth"], r["black_box"]
        print(f"| {r['data']} | {r['given']} | {_fmt(r['rel_l2'])} | {_opt(r['to_short'])} | "
              f"{_fmt(r['rel_l2_completed'] or np.inf)} | "
              f"{_fmt(r['standardised'])} | {r['failed']}/10 | {_fmt(t['cn'])} | "
              f"{_fmt(t['midpoint'])} | {_fmt(t['discrete-gradient'])} | "
              f"{_fmt(r['constant'])} | {_fmt(b['rel_l2'])}; {_opt(b['to_horizon'])} "
              f"({b['failed']} failed, {b['scheme']}) | {r['steps']} | {r['kept_step']} | "
              f"{r['seconds']:.0f} |")
    print(f"\nThe peer's published network: {PUBLISHED} on the real dataset.")
    return 0


if __name__ == "__main__":
    sys.exit(main())
