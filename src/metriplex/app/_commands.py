"""What each ``metriplex`` command does: its implementation and the helpers it needs. The
parser (the options, their help, ``main``) is in :mod:`metriplex.app.cli`, which imports this
module; this module never imports the parser."""

from __future__ import annotations

import dataclasses
import gc
import math
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from .._fit_loop import INTERRUPTED, ending
from .._errors import MetriplexError
from ..data import noise_level
from ..verdict import Thresholds
from ._summary import against_constant, evaluated_noise_note, train_summary
from ._outputs import check_figures, not_an_input
from ._warnings import (cells_hint, in_sample_warning, structure_warnings, time_unit_warning,
                        trained_on, trained_units, training_range_warning)

if TYPE_CHECKING:
    import argparse


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
    from ..io import check_output_file, trajectory_suffixes

    return check_output_file(path, overwrite=overwrite, suffixes=trajectory_suffixes())


def _honour_model_dtype(run) -> None:
    """Enable x64 before any array exists when the model file holds float64 weights: every
    command reads a model in the precision it was trained in."""
    from ..io import read_header

    if read_header(run).get("dtype") == "float64":
        import jax

        jax.config.update("jax_enable_x64", True)


def _positive_finite(value, option: str) -> None:
    if value is not None and not (math.isfinite(value) and value > 0):
        raise MetriplexError(f"{option} must be a positive finite number; got {value}.")


def cmd_generate(args: argparse.Namespace) -> None:
    """Write trajectories of a built-in system (``metriplex generate``, formerly ``metriplex
    simulate``, which still works): from ``--trajectories``
    initial states drawn with ``--seed``, ``--steps`` steps of ``--dt`` each, to ``--out``."""
    from .. import systems
    from ._option import system_params
    from .config import check_seed
    from ..io import write

    out = _check_trajectory_out(args.out, args.overwrite)
    check_seed(args.seed)
    if args.float64:
        import jax

        jax.config.update("jax_enable_x64", True)
    params = system_params(args.param, systems.get_system(args.system).config)
    system = systems.get_system(args.system, **params)
    data = systems.generate(
        system, trajectories=args.trajectories, steps=args.steps, dt=args.dt, seed=args.seed
    )
    write(out, data)
    print(f"wrote {len(data)} trajectories x {args.steps + 1} states of {args.system} to {out}")


#: The former name of :func:`cmd_generate` (``metriplex simulate``).
cmd_simulate = cmd_generate


def cmd_train(args: argparse.Namespace) -> int | None:
    """Train a model on ``args.data`` into the run folder ``--out`` (``metriplex train``), evaluate
    it on the validation trajectories and print a summary; the exit status 130 when the training was
    interrupted, else ``None``."""
    from ._data_checks import operators_note, split_in_time
    from ._lock import RunLock
    from ._selection import check_selection, choose_trajectories
    from ._trainings_note import trainings_note
    from .config import hold_energy_on, reversible_first_on, validate
    from ..io import read
    from .runs import (RunData, check_run_folder, evaluate_run, run_config, train_parts,
                       trained_scheme, write_json)

    out = Path(args.out)
    check_run_folder(out, overwrite=args.overwrite, resume=args.resume)
    config = _config_from_args(args)
    _positive_finite(args.dt, "--dt")
    selection = check_selection(trajectories=args.trajectories,
                                validation_ids=args.validation_ids, split=args.split,
                                validation=args.validation)
    data = read(args.data, dt=args.dt)
    try:
        validate(config, data.n)
    except MetriplexError as e:  # a preset's structure is not the user's typing: say whose
        if not args.preset:
            raise
        raise MetriplexError(f"--preset {args.preset} (its reference experiment's settings: "
                             f"--poisson {config.poisson} --entropy {config.entropy} ...) does "
                             f"not fit these data: {e} Leave --preset out for other data.") \
            from None
    trajectories, validation_ids = choose_trajectories(
        data.ids, f"the data file {str(args.data)!r}", selection)
    for line in operators_note(args.data, config.poisson, config.friction):
        print(line, file=sys.stderr)
    # The lock covers the evaluation and metrics.json too, not only the training.
    with RunLock(out) as lock:
        if lock.note:
            print(lock.note, file=sys.stderr)
        parts = RunData.of(data, config, trajectories=trajectories,
                           validation_ids=validation_ids,
                           source={"file": str(args.data), "dt": args.dt})
        del data  # the training holds only its parts of the data (large data: memory)
        model, history, train, valid, seconds = train_parts(
            parts, config, out, overwrite=args.overwrite, resume=args.resume,
            progress=not args.quiet)
        target, in_time = valid if valid is not None else train, split_in_time(train, valid)
        saved = run_config(out)  # what training wrote: its choices and trainings
        # The evaluation holds only what it rolls out (large data: memory). The loss figure
        # leaves a reference cycle through matplotlib's frames that holds the training's
        # locals, the training part among them, until the collector runs: collect now.
        del parts, train
        gc.collect()
        # The step check is left to `evaluate`: after training it would add a compilation
        # (seconds) to every run for what the final line does not print.
        metrics = evaluate_run(model, target, scheme=trained_scheme(saved),
                               figures=out / "figures", progress=not args.quiet, step_check=False)
        metrics["train_seconds"] = seconds
        metrics["evaluated_on"] = (
            "training data" if valid is None else "validation trajectories" if not in_time
            else "the validation part (each trajectory's end, after its training part)")
        metrics.update(stopped=history.stopped, noise_over_spread=noise_level(target),
                       coarse_steps=saved.get("decided", {}).get("coarse_steps"))
        write_json(out / "metrics.json", metrics)
    print(train_summary(history, metrics, seconds, out,
                        first_stage=reversible_first_on(config) and not args.resume,
                        held_stage=hold_energy_on(config),
                        trainings=trainings_note(saved)))
    for line in structure_warnings(metrics) + cells_hint(metrics, config, target.n):
        print(line, file=sys.stderr)
    if ending(history.stopped) == INTERRUPTED:
        print(
            f"metriplex train: interrupted; the best model so far and a checkpoint are in {out}. "
            "Continue with the same command and --resume.",
            file=sys.stderr,
        )
        return 130


def cmd_rollout(args: argparse.Namespace) -> None:
    """Roll a trained model out from the first state of every chosen trajectory of ``args.data`` on
    its own grid (``metriplex rollout``), writing the predictions to ``--out`` and each trajectory's
    status beside it."""
    import numpy as np

    from ..data import Trajectories
    from ..diagnostics import rollout_data
    from ..integrate import step_failure
    from ..io import check_output_file, load, write, write_json
    from .config import scheme_from_name
    from ._data_checks import check_names
    from .runs import run_config

    not_an_input(args.out, args)
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
    units = run_config(args.run).get("units") or {}
    for line in time_unit_warning(units, data):
        print(line, file=sys.stderr)
    ids, t_out, x_out, status = [], [], [], []
    for k, T in enumerate(lengths):
        tid = int(data.ids[k])
        stop = T if failed[k] < 0 or failed[k] >= T else int(failed[k])
        entry = {"trajectory": tid, "status": "ok", "states": stop, "samples": int(T)}
        if stop < T:
            what = step_failure(scheme, ts[k, stop - 1], ts[k, stop])
            entry.update(status="failed", failed_at_t=float(ts[k, stop]), reason=what)
            away = _departure(units, xs[k, :stop], data.names)
            if away is not None:
                entry["left_training_data"] = away
                when = ("in its initial state" if away["step"] == 0 else
                        f"at t={float(ts[k, away['step']]):.6g}")
                what += (f". Before that, the rollout had left the training data: "
                         f"{away['variable']} was {away['standard_deviations']:.0f} training "
                         f"standard deviations from its training mean {when}; the model was "
                         "never fitted there (training trajectories that reach that region "
                         "would help)")
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


#: How far (in training standard deviations from the training mean) a rolled-out state may go
#: before a failure is blamed on extrapolation: the training data themselves rarely exceed 4
#: (the verdict's ``training_range``).
FAR_FROM_DATA = Thresholds().training_range


def _departure(units: dict, xs, names) -> dict | None:
    """Where a rollout ``xs`` (its finite states) first went furthest outside the training
    data, in the run's data units (``config.json``'s ``units``: each variable's training mean
    and standard deviation); ``None`` when it stayed within :data:`FAR_FROM_DATA` of them or
    the run has no units (an older run)."""
    trained = trained_units(units)
    if trained is None or len(xs) == 0:
        return None
    far, step, var = trained.farthest(xs)
    if not far > FAR_FROM_DATA:
        return None
    return {"variable": str(names[var]), "standard_deviations": far, "step": step}


def _chosen_trajectories(args):
    """``--trajectories`` and ``--dt`` of rollout and evaluate, checked before any work."""
    from ._selection import parse_ids

    _positive_finite(args.dt, "--dt")
    return None if args.trajectories is None else parse_ids(args.trajectories, "--trajectories")


def _read_data(args, chosen):
    """DATA as read (with ``--dt``), only the ``--trajectories`` chosen."""
    from ..io import read

    data = read(args.data, dt=args.dt)
    if chosen is not None:
        data = data.select(chosen.pick(data.ids, f"the data file {str(args.data)!r}"))
    return data


def _scheme(args) -> str:
    """The --scheme given, else the one the run in args.run was trained with."""
    if args.scheme:
        return args.scheme
    from .runs import run_config, trained_scheme

    return trained_scheme(run_config(args.run))


def cmd_evaluate(args: argparse.Namespace) -> int | None:
    """Print the metrics and the verdict of a trained model on ``args.data`` (``metriplex
    evaluate``), optionally writing them (``--out``) and the figures (``--figures``); with
    ``--strict`` the verdict's exit status, else ``None``."""
    import json

    from ..io import check_output_file, check_output_folder, load, write_json
    from ._data_checks import check_names, sample_warnings
    from .runs import evaluate_run, run_config

    if args.out:
        not_an_input(args.out, args)
        check_output_file(args.out, overwrite=args.overwrite, suffixes=(".json",))
    if args.figures:
        check_output_folder(args.figures, "--figures")
        check_figures(args.figures, args.overwrite)
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
    if args.every < 1:
        raise MetriplexError(f"--every must be a whole number >= 1 (1: every sample); got "
                             f"{args.every}.")
    data = _read_data(args, chosen).every(args.every)
    check_names(args.run, data)
    figures = Path(args.figures) if args.figures else None
    metrics = evaluate_run(model, data, scheme=_scheme(args), figures=figures, horizon=args.horizon,
                           solver=args.solver, progress=not args.quiet) | {
        "every": args.every, "noise_over_spread": noise_level(data)}
    run = run_config(args.run)
    units = run.get("units") or {}
    for line in (time_unit_warning(units, data) + training_range_warning(units, data)
                 + sample_warnings(data, "evaluated data")):
        print(line, file=sys.stderr)
    failed, k = metrics.get("rollout_failures", 0), metrics.get("trajectories", 0)
    trained = trained_on(run, data)
    if trained:
        metrics["trajectories_trained_on"] = len(trained)
        print(in_sample_warning(trained, k), file=sys.stderr)
    if metrics.get("trajectories_ending_before_horizon"):
        print(f"warning: {metrics['trajectories_ending_before_horizon']} of {k} trajectories "
              f"end before --horizon {args.horizon:g}: their rollout_error_to_horizon is over "
              "their whole length, not up to the horizon.", file=sys.stderr)
    if failed:
        print(f"warning: {failed} of {k} rollouts FAILED (blew up or did not converge), so "
              "rollout_error_mean is null; the other rollout figures are over the completed "
              "ones or the states before the failures (metriplex rollout says where and why "
              "each failed).", file=sys.stderr)
    against, worse = against_constant(metrics)
    if worse:
        print(f"warning: the model's rollouts (relative L2 "
              f"{metrics['rollout_error_mean_completed']:.3e}) are {against}.", file=sys.stderr)
    for line in structure_warnings(metrics) + evaluated_noise_note(metrics):
        print(line, file=sys.stderr)
    if not args.no_verdict:
        from .runs import run_verdict

        metrics["verdict"] = run_verdict(args.run, model, data, metrics,
                                         steps=args.verdict_steps, progress=not args.quiet)
        print(f"verdict: {metrics['verdict']['statement']}", file=sys.stderr)
    if args.out:
        write_json(Path(args.out), metrics)
    summary = {k: v for k, v in metrics.items() if not isinstance(v, (list, dict))}
    if "verdict" in metrics:
        summary["verdict"] = metrics["verdict"]["outcome"]
    from ..io._files import json_safe

    print(json.dumps(json_safe(summary), indent=2, default=str))
    if args.strict:
        from ..verdict import EXIT_STATUS

        return EXIT_STATUS[metrics["verdict"]["outcome"]]


def cmd_reproduce(args: argparse.Namespace) -> None:
    """Run a reference experiment end to end into its run folder (``metriplex reproduce``)."""
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
                       defaults=args.defaults, verdict=False if args.no_verdict else None)
