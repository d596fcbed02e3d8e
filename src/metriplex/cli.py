"""The ``metriplex`` command line: a thin front that parses options and calls the library.

Bad input ends with one clear message on stderr and exit status 2, never a traceback.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import re
import sys
from pathlib import Path

from ._errors import MetriplexError

#: integrate.SOLVERS, spelled out so that building the parser does not import JAX.
_SOLVERS = ("auto", "newton", "fixed-point")

EXIT_BAD_INPUT = 2
EXIT_FAILED = 3

#: A value that starts with a minus sign and a digit is a number, never an option: argparse
#: alone reads "--lr -1e-3" as "--lr" without a value (it knows only -1 and -.5 as numbers).
_NEGATIVE_NUMBER = re.compile(r"^-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$|^-(inf|infinity|nan)$",
                              re.IGNORECASE)


class _Parser(argparse.ArgumentParser):
    """argparse, with negative numbers in any notation as values, and usage errors as one line
    (the rule and the value, and where to look) instead of the whole usage text."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = _NEGATIVE_NUMBER

    def error(self, message: str):
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: error: {message}. See `{self.prog} --help`.\n")


def _add_structure_options(p: argparse.ArgumentParser) -> None:
    from .config import SCHEDULES, RunConfig

    d = RunConfig()
    g = p.add_argument_group("structure (what is learned, what is given)")
    g.add_argument("--energy", help="neural (default)")
    g.add_argument("--entropy", help="neural (default) | sum:I,J,... (S = sum of those "
                   "components, counted from 0) | zero")
    g.add_argument("--poisson", help="neural (default) | canonical:K (first K positions, next "
                   "K momenta) | zero | casimir3 (n = 3, Jacobi exact) | lie-poisson (learned, "
                   "linear in the state) | file:PATH (a constant L from .npy, .npz or .mat)")
    g.add_argument("--friction", help="neural (default) | zero | file:PATH (a constant M from "
                   ".npy, .npz or .mat)")
    g.add_argument("--degeneracy", help="auto (default: L grad S = 0 exact when S is given, "
                   "penalties otherwise) | soft (penalties only) | exact (L and M by "
                   "construction)")
    g.add_argument("--degeneracy-at", help="where soft degeneracy penalties are evaluated: states "
                   "(both states of each pair, default) | midpoints (one per pair; with "
                   "--scheme discrete-gradient about halves the step's cost)")
    g.add_argument("--jacobi", help="none | exact | stochastic (Jacobi-identity penalty)")
    g.add_argument("--jacobi-probes", type=int, help=f"probes per sample (default {d.jacobi_probes})")
    g.add_argument("--jacobi-samples", type=int, help="pairs of each batch that the Jacobi penalty "
                   "is evaluated on (default: all; fewer is cheaper, still unbiased)")
    g.add_argument("--quadratic", action="store_true", default=None,
                   help="add a learned quadratic form to the learned E and S networks (a "
                   "second-order Taylor term that extrapolates the forces linearly; off by "
                   "default)")
    g.add_argument("--features", help="none | pendulum (the paper's invariant features)")
    g.add_argument("--features-for", help="networks that see the features: a comma list of "
                   f"energy, entropy, friction (default {d.features_for})")
    g.add_argument("--scheme", help="training residual scheme: cn (default) | midpoint | "
                   "discrete-gradient | rk4")
    w = p.add_argument_group("loss weights and optimisation")
    w.add_argument("--w-traj", type=float, help=f"residual weight (default {d.w_traj})")
    w.add_argument("--w-degeneracy-L", dest="w_degeneracy_L", type=float,
                   help=f"|L grad S|^2 weight (default {d.w_degeneracy_L})")
    w.add_argument("--w-degeneracy-M", dest="w_degeneracy_M", type=float,
                   help=f"|M grad E|^2 weight (default {d.w_degeneracy_M})")
    w.add_argument("--w-jacobi", type=float, help=f"Jacobi weight (default {d.w_jacobi})")
    w.add_argument("--width", type=int, help=f"network width (default {d.width})")
    w.add_argument("--depth", type=int, help=f"hidden layers (default {d.depth})")
    w.add_argument("--lr", type=float, help=f"peak learning rate (default {d.lr})")
    w.add_argument("--weight-decay", type=float,
                   help=f"AdamW weight decay (default {d.weight_decay})")
    w.add_argument("--steps", type=int, help=f"the most optimiser steps (default {d.steps}); "
                   "training usually stops earlier, when the held-out rollouts stop improving")
    w.add_argument("--max-minutes", type=float, help="stop training after this many minutes "
                   "(default: no time limit)")
    w.add_argument("--batch-size", type=int, help=f"pairs per step (default {d.batch_size})")
    w.add_argument("--validation", type=float,
                   help="fraction of the selected trajectories held out for validation, drawn "
                   f"at random with --seed (default {d.validation}; 0 for none); to choose "
                   "them, see --validation-ids and --split")
    w.add_argument("--eval-every", type=int, help=f"steps between validations (default {d.eval_every})")
    w.add_argument("--patience", type=int, help="validations without improvement before the "
                   "learning rate is cut (x0.3, from the best model; after --lr-cuts cuts "
                   "training stops; default 20)")
    w.add_argument("--lr-cuts", type=int, help="learning-rate cuts before training stops "
                   f"(default {d.lr_cuts})")
    w.add_argument("--schedule", choices=sorted(SCHEDULES), help="learning-rate schedule: "
                   + "; ".join(f"{k}: {v}" for k, v in SCHEDULES.items()).replace("%", "%%"))
    w.add_argument("--lbfgs-steps", type=int, help="iterations of an L-BFGS finish on a fixed "
                   "batch of up to 8192 training pairs after the Adam stage, kept only where "
                   f"the held-out rollouts improve (default {d.lbfgs_steps}; 0 for none)")
    w.add_argument("--input-noise", type=float, metavar="FRACTION", help="Gaussian noise on "
                   "both states of every training pair, as a fraction of each variable's "
                   f"standard deviation (default {d.input_noise}; 0 for none)")
    w.add_argument("--checkpoint-every", type=int,
                   help=f"validations between checkpoints (default {d.checkpoint_every})")
    w.add_argument("--seed", type=int, help=f"PRNG seed (default {d.seed})")
    w.add_argument("--float64", action="store_true", default=None, help="train in float64")
    w.add_argument("--data-parallel", action="store_true", default=None,
                   help="split each batch over all local devices (GPUs, or CPU devices with "
                   "XLA_FLAGS=--xla_force_host_platform_device_count=N)")


def _config_from_args(args):
    from .config import RunConfig, preset

    base = preset(args.preset) if args.preset else RunConfig()
    updates = {
        f.name: getattr(args, f.name)
        for f in dataclasses.fields(RunConfig)
        if getattr(args, f.name, None) is not None
    }
    return dataclasses.replace(base, **updates)


def _check_trajectory_out(path, overwrite: bool) -> Path:
    from .io import check_output_file, trajectory_suffixes

    return check_output_file(path, overwrite=overwrite, suffixes=trajectory_suffixes())


def _honour_model_dtype(run) -> None:
    """Enable x64 before any array exists when the model file holds float64 weights: every
    command reads a model in the precision it was trained in."""
    from .io import read_header

    if read_header(run).get("dtype") == "float64":
        import jax

        jax.config.update("jax_enable_x64", True)


def _positive_finite(value, option: str) -> None:
    if value is not None and not (math.isfinite(value) and value > 0):
        raise MetriplexError(f"{option} must be a positive finite number; got {value}.")


def cmd_simulate(args) -> None:
    from . import systems
    from .config import check_seed
    from .io import write

    out = _check_trajectory_out(args.out, args.overwrite)
    check_seed(args.seed)
    if args.float64:
        import jax

        jax.config.update("jax_enable_x64", True)
    system = systems.get_system(args.system, **_params(args.param))
    data = systems.generate(
        system, trajectories=args.trajectories, steps=args.steps, dt=args.dt, seed=args.seed
    )
    write(out, data)
    print(f"wrote {len(data)} trajectories x {args.steps + 1} states of {args.system} to {out}")


def _params(items):
    params = {}
    for item in items or []:
        key, sep, value = item.partition("=")
        if not sep:
            raise MetriplexError(f"--param expects NAME=VALUE; got {item!r}.")
        params[key.replace("-", "_")] = value
    return params


def _train_summary(history, metrics: dict, seconds: float, out: Path) -> str:
    """train's final line: how training ended, and how the held-out rollouts went."""
    last = history.step[-1] if history.step else 0
    ended = history.stopped or "completed"
    if not history.converged and history.best_step == last and last > 0:
        ended += "; the best model is the last one: not converged, allow more --steps"
    if history.best_step == 0 and last > 0:
        ended += ("; NO trained model rolled out the held-out trajectories better than the "
                  "untrained one (kept): the data do not determine the dynamics away from the "
                  "training trajectories; give more trajectories or more of the structure")
    k = metrics.get("trajectories", 0)
    failed = metrics.get("rollout_failures", 0)
    err = metrics.get("rollout_error_mean")
    where = metrics.get("evaluated_on", "")
    if failed:
        rollouts = f"{failed} of {k} rollouts on {where} FAILED (blew up or did not converge)"
        done = metrics.get("rollout_error_mean_completed")
        if done is not None:
            rollouts += f"; error of the {k - failed} completed: {done:.3e}"
    else:
        rollouts = f"rollout error on {where}: {err:.3e} (relative L2, {k} trajectories)"
    return f"trained {last} steps in {seconds:.1f} s ({ended}); {rollouts}; run folder: {out}"


def cmd_train(args) -> None:
    from ._lock import RunLock
    from ._selection import check_selection, choose_trajectories
    from .config import validate
    from .io import read
    from .runs import check_run_folder, evaluate_run, train_run, write_json

    out = Path(args.out)
    check_run_folder(out, overwrite=args.overwrite, resume=args.resume)
    config = _config_from_args(args)
    _positive_finite(args.dt, "--dt")
    selection = check_selection(trajectories=args.trajectories,
                                validation_ids=args.validation_ids, split=args.split,
                                validation=args.validation)
    data = read(args.data, dt=args.dt)
    validate(config, data.n)
    trajectories, validation_ids = choose_trajectories(
        data.ids, f"the data file {str(args.data)!r}", selection)
    # The lock covers the evaluation and metrics.json too, not only the training.
    with RunLock(out) as lock:
        if lock.note:
            print(lock.note, file=sys.stderr)
        model, history, train, valid, seconds = train_run(
            data, config, out, overwrite=args.overwrite, resume=args.resume,
            progress=not args.quiet, trajectories=trajectories,
            validation_ids=validation_ids, source={"file": str(args.data), "dt": args.dt},
        )
        target = valid if valid is not None else train
        del data, train  # the evaluation holds only what it rolls out (large data: memory)
        metrics = evaluate_run(model, target, scheme=config.scheme, figures=out / "figures",
                               progress=not args.quiet)
        metrics["train_seconds"] = seconds
        metrics["evaluated_on"] = ("validation trajectories" if valid is not None
                                   else "training data")
        metrics["stopped"] = history.stopped
        write_json(out / "metrics.json", metrics)
    print(_train_summary(history, metrics, seconds, out))
    if history.stopped.startswith("interrupted"):
        print(
            f"metriplex train: interrupted; the best model so far and a checkpoint are in {out}. "
            "Continue with the same command and --resume.",
            file=sys.stderr,
        )
        return 130


def cmd_rollout(args) -> None:
    import numpy as np

    from .data import Trajectories
    from .diagnostics import rollout_data
    from .integrate import scheme_from_name, step_failure
    from .io import check_output_file, load, write, write_json
    from .runs import check_names

    out = _check_trajectory_out(args.out, args.overwrite)
    status_path = check_output_file(f"{out}.status.json", overwrite=args.overwrite,
                                    suffixes=(".json",))
    scheme = scheme_from_name(_scheme(args), solver=args.solver)
    chosen = _chosen_trajectories(args)
    _honour_model_dtype(args.run)
    model = load(args.run)
    data = _read_data(args, chosen)
    check_names(args.run, data)
    result, _, lengths = rollout_data(model, data, scheme=scheme, progress=not args.quiet)
    ts, _, _ = data.padded()  # the data's own float64 grid, not the model-precision copy
    xs = np.asarray(result.xs, dtype=np.float64)
    failed = np.asarray(result.failed_step)
    ids, t_out, x_out, status = [], [], [], []
    for k, T in enumerate(lengths):
        tid = int(data.ids[k])
        stop = T if failed[k] < 0 or failed[k] >= T else int(failed[k])
        entry = {"trajectory": tid, "status": "ok", "states": stop, "samples": int(T)}
        if stop < T:
            what = step_failure(scheme, ts[k, stop - 1], ts[k, stop])
            entry.update(status="failed", failed_at_t=float(ts[k, stop]), reason=what)
            kept = (f"writing the {stop} states computed before it" if stop >= 2 else
                    "nothing written for it (a trajectory needs two states)")
            print(f"warning: trajectory {tid}: {what}; {kept}.", file=sys.stderr)
        if stop >= 2:  # the data's own trajectory id, so predictions match the truth by id
            ids.append(np.full(stop, tid))
            t_out.append(ts[k, :stop])
            x_out.append(xs[k, :stop])
        else:
            entry["states"] = 0
        status.append(entry)
    if not ids:
        raise MetriplexError(
            f"no trajectory could be rolled out past its first step with the {scheme.name} "
            f"scheme (each failure is named above); nothing to write to {str(out)!r}."
        )
    write(out, Trajectories(np.concatenate(ids), np.concatenate(t_out),
                            np.concatenate(x_out), data.names))
    write_json(status_path, {"scheme": scheme.name, "trajectories": status})
    n_failed = sum(e["status"] == "failed" for e in status)
    print(f"wrote {len(ids)} predicted trajectories to {out} (data's trajectory ids; "
          f"{n_failed} of {len(status)} failed, see {status_path})")


def _chosen_trajectories(args):
    """``--trajectories`` and ``--dt`` of rollout and evaluate, checked before any work."""
    from ._selection import parse_ids

    _positive_finite(args.dt, "--dt")
    return None if args.trajectories is None else parse_ids(args.trajectories, "--trajectories")


def _read_data(args, chosen):
    """DATA as read (with ``--dt``), only the ``--trajectories`` chosen."""
    from .io import read

    data = read(args.data, dt=args.dt)
    if chosen is not None:
        data = data.select(chosen.pick(data.ids, f"the data file {str(args.data)!r}"))
    return data


def _scheme(args) -> str:
    """The --scheme given, else the one the run in args.run was trained with."""
    if args.scheme:
        return args.scheme
    from .runs import run_config

    return run_config(args.run).get("config", {}).get("scheme", "cn")


def cmd_evaluate(args) -> None:
    import json

    from .io import check_output_file, check_output_folder, load, write_json
    from .runs import check_names, evaluate_run

    if args.out:
        check_output_file(args.out, overwrite=args.overwrite)
    if args.figures:
        check_output_folder(args.figures, "--figures")
    _positive_finite(args.horizon, "--horizon")
    if args.verdict_steps < 1:
        raise MetriplexError(
            f"--verdict-steps must be >= 1 (training steps of the black-box reference); got "
            f"{args.verdict_steps}. Pass --no-verdict to skip the verdict."
        )
    if args.strict and args.no_verdict:
        raise MetriplexError(
            "--strict exits with the verdict's outcome, and --no-verdict skips the verdict; "
            "got both. Drop one of them."
        )
    _scheme(args)  # a damaged config.json is reported before any work
    chosen = _chosen_trajectories(args)
    _honour_model_dtype(args.run)
    model = load(args.run)
    data = _read_data(args, chosen)
    check_names(args.run, data)
    figures = Path(args.figures) if args.figures else None
    metrics = evaluate_run(model, data, scheme=_scheme(args), figures=figures, horizon=args.horizon,
                           solver=args.solver, progress=not args.quiet)
    if not args.no_verdict:
        from .runs import run_config, training_outcome
        from .verdict import verdict

        cfg = run_config(args.run).get("config", {})
        ended = training_outcome(args.run)
        metrics["verdict"] = verdict(
            model, data, report=metrics, converged=ended["converged"], stopped=ended["stopped"],
            width=cfg.get("width", 64), depth=cfg.get("depth", 2),
            steps=args.verdict_steps, learning_rate=cfg.get("lr", 3e-3),
            batch_size=cfg.get("batch_size", 256), progress=not args.quiet,
        )
        print(f"verdict: {metrics['verdict']['statement']}", file=sys.stderr)
    if args.out:
        write_json(Path(args.out), metrics)
    summary = {k: v for k, v in metrics.items() if not isinstance(v, (list, dict))}
    if "verdict" in metrics:
        summary["verdict"] = metrics["verdict"]["outcome"]
    from .io import _strict

    print(json.dumps(_strict(summary), indent=2, default=str))
    if args.strict:
        from .verdict import EXIT_STATUS

        return EXIT_STATUS[metrics["verdict"]["outcome"]]


def cmd_reproduce(args) -> None:
    from ._lock import RunLock
    from .experiments import default_out, run_experiment
    from .runs import check_run_folder

    out = Path(args.out) if args.out else default_out(args.experiment, quick=args.quick,
                                                      defaults=args.defaults)
    check_run_folder(out, overwrite=args.overwrite)
    with RunLock(out) as lock:
        if lock.note:
            print(lock.note, file=sys.stderr)
        run_experiment(args.experiment, quick=args.quick, out=out, overwrite=args.overwrite,
                       degeneracy=args.degeneracy, progress=not args.quiet,
                       defaults=args.defaults)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="metriplex",
        description="Learn thermodynamically consistent (GENERIC) dynamics "
        "dx/dt = L(x) grad E(x) + M(x) grad S(x) from trajectories.",
    )
    parser.add_argument("--version", action="version", version=_version())
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    p = sub.add_parser("simulate", help="generate trajectories of a built-in system",
                       description=_systems_help(), formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("system", metavar="SYSTEM", help="a built-in system (listed above)")
    p.add_argument("--trajectories", type=int, required=True,
                   help="number of trajectories, each from its own random initial state")
    p.add_argument("--steps", type=int, required=True,
                   help="steps per trajectory (each trajectory has STEPS + 1 samples)")
    p.add_argument("--dt", type=float, required=True,
                   help="time between samples, in the system's time unit")
    p.add_argument("--seed", type=int, default=0,
                   help="seed of the initial states (default 0)")
    p.add_argument("--param", action="append", metavar="NAME=VALUE",
                   help="system parameter, e.g. --param parameter_set=spnn or --param inertia=10,20,40")
    p.add_argument("--float64", action="store_true", help="integrate in float64")
    p.add_argument("--out", required=True, help="data file to write: .npz, .csv, .h5 or .mat")
    p.add_argument("--overwrite", action="store_true", help=_OVERWRITE)
    p.set_defaults(func=cmd_simulate)

    p = sub.add_parser("train", help="learn a GENERIC model from trajectory data",
                       epilog=DATA_FORMAT, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("data", metavar="DATA", help="trajectory data (format below)")
    p.add_argument("--out", required=True, metavar="RUN_DIR",
                   help="run folder: model.mpx, config.json, history.json, metrics.json, "
                   "checkpoint.ckpt, figures/")
    p.add_argument("--preset", help="rigid-body | pendulum-energetic | pendulum-temperature | "
                   "gas-containers")
    p.add_argument("--resume", action="store_true", help="continue an interrupted run in --out "
                   "(with the same DATA, --dt, trajectories and options; others are refused)")
    p.add_argument("--overwrite", action="store_true", help=_OVERWRITE)
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    s = p.add_argument_group("which trajectories train and validate (the ids used are "
                             "recorded in RUN_DIR/config.json)")
    s.add_argument("--trajectories", metavar="IDS", help="use only these trajectory ids of "
                   f"DATA, {_IDS} (default: all)")
    s.add_argument("--validation-ids", metavar="IDS", help="these of the selected trajectories "
                   "validate, the rest train (instead of the random --validation fraction)")
    s.add_argument("--split", metavar="FILE", help="the split to use: a JSON file "
                   '{"train": [ids], "validation": [ids]} (optionally "test": [ids], which '
                   "must not overlap them), or a run folder (or its config.json) whose split "
                   "is reused exactly")
    p.add_argument("--dt", type=float, metavar="STEP", help=_DT)
    _add_structure_options(p)
    p.set_defaults(func=cmd_train)

    p = sub.add_parser("rollout", help="predict every trajectory of DATA from its first state",
                       epilog=DATA_FORMAT, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("run", metavar="RUN_DIR", help="run folder written by `metriplex train`")
    p.add_argument("data", metavar="DATA", help="trajectories to predict (format below)")
    p.add_argument("--out", required=True,
                   help="predictions, in the data format: .npz, .csv, .h5 or .mat")
    p.add_argument("--scheme", help="cn | midpoint | discrete-gradient | rk4 (default: the "
                   "scheme the run was trained with)")
    p.add_argument("--solver", choices=_SOLVERS, help="implicit steps: auto (default: fixed-point "
                   "iteration, Newton where it does not converge) | newton (stiff models) | "
                   "fixed-point")
    p.add_argument("--trajectories", metavar="IDS",
                   help=f"predict only these trajectory ids of DATA, {_IDS} (default: all)")
    p.add_argument("--dt", type=float, metavar="STEP", help=_DT)
    p.add_argument("--overwrite", action="store_true", help=_OVERWRITE)
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_rollout)

    p = sub.add_parser("evaluate", help="metrics (and figures) of a trained model on DATA",
                       epilog=DATA_FORMAT, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("run", metavar="RUN_DIR", help="run folder written by `metriplex train`")
    p.add_argument("data", metavar="DATA", help="test trajectories (format below)")
    p.add_argument("--out", metavar="METRICS.json",
                   help="write the metrics as strict JSON here (default: print a summary only)")
    p.add_argument("--figures", metavar="DIR", help="also write the report figures here")
    p.add_argument("--scheme", help="cn | midpoint | discrete-gradient | rk4 (default: the "
                   "scheme the run was trained with)")
    p.add_argument("--solver", choices=_SOLVERS, help="implicit steps: auto (default: fixed-point "
                   "iteration, Newton where it does not converge) | newton (stiff models) | "
                   "fixed-point")
    p.add_argument("--horizon", type=float, help="also report the error up to t0 + HORIZON")
    p.add_argument("--trajectories", metavar="IDS",
                   help=f"evaluate only these trajectory ids of DATA, {_IDS} (default: all; "
                   "the ids evaluated are `trajectory_ids` in the JSON)")
    p.add_argument("--dt", type=float, metavar="STEP", help=_DT)
    p.add_argument("--no-verdict", action="store_true",
                   help="skip the 'is it GENERIC?' verdict (consistent | not consistent | "
                   "cannot tell, each reason with its figure, under `verdict` in the JSON; it "
                   "trains a black-box reference)")
    p.add_argument("--verdict-steps", type=int, default=3000,
                   help="training steps of the black-box reference (default 3000)")
    p.add_argument("--strict", action="store_true",
                   help="exit with the verdict's outcome, for scripts: 0 consistent, 1 not "
                   "consistent, 3 cannot tell (2 stays bad input); the outcome is also "
                   "`verdict.outcome` in the --out JSON")
    p.add_argument("--overwrite", action="store_true", help=_OVERWRITE)
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=cmd_evaluate)

    p = sub.add_parser("reproduce", help="run a reference experiment end to end, with figures")
    p.add_argument("experiment", metavar="EXPERIMENT",
                   help="rigid-body | pendulum-energetic | pendulum-temperature | gas-containers")
    p.add_argument("--quick", action="store_true", help="reduced size (about two minutes)")
    p.add_argument("--out", default=None, help="output folder (default runs/EXPERIMENT)")
    p.add_argument("--degeneracy", default="soft", help="soft | exact")
    p.add_argument("--defaults", action="store_true",
                   help="train with the experiment's structure only (what is learned, what is "
                   "given) and default settings, as without a preset")
    p.add_argument("--overwrite", action="store_true", help=_OVERWRITE)
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=cmd_reproduce)
    return parser


_OVERWRITE = "replace existing outputs (without it, existing files are never touched)"
_IDS = "a comma list with ranges such as 0,3,5-9"
_DT = ("give every trajectory the uniform time grid t = k*STEP (k = 0, 1, ...), replacing "
       "the file's times or supplying them (e.g. a .mat time vector that does not fit the "
       "snapshots)")

DATA_FORMAT = """\
data format: one row per observed state, in one of
  .csv  columns trajectory,t,<name_1>,...,<name_n> (integer trajectory id, time, the state)
  .npz  arrays trajectory (N,), t (N,), x (N, n), optional names (n,)
  .h5   one group per trajectory, each with datasets t (T,) and x (T, n)
  .mat  snapshots (trajectories x variables x snapshots) with a time vector or step
Trajectories may be ragged and unevenly sampled; samples within a trajectory are in time order.
With --dt STEP the file's times are not read: each trajectory gets t = 0, STEP, 2*STEP, ...
"""


def _version() -> str:
    from . import __version__

    return f"metriplex {__version__}"


def _systems_help() -> str:
    try:
        from . import systems

        return "Built-in systems:\n\n" + "\n\n".join(
            s.help_text() for s in systems.SYSTEMS.values()
        )
    except Exception:  # the listing must never break --help
        return "Generate trajectories of a built-in ground-truth system."


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        code = args.func(args)
    except MetriplexError as e:
        print(f"metriplex {args.command}: error: {e}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print(f"metriplex {args.command}: interrupted", file=sys.stderr)
        return 130
    except OSError as e:
        where = f" {str(e.filename)!r}" if e.filename else ""
        print(f"metriplex {args.command}: error: cannot access{where}: {e.strerror or e}. Check "
              "the path and its permissions.", file=sys.stderr)
        return EXIT_BAD_INPUT
    return code or 0


if __name__ == "__main__":
    sys.exit(main())
