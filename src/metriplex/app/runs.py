"""Run folders: what ``metriplex train`` writes and ``rollout``/``evaluate`` read.

A run folder holds ``model.mpx`` (the best model), ``config.json`` (the options, what the data
decided, the variables' names, the split), ``history.json``, ``checkpoint.ckpt`` (to resume),
``metrics.json``, ``figures/`` (PNG, PDF, NPZ) and, while a training writes it,
``.metriplex.lock``: one training at a time owns a run folder (see ``_lock``).
"""

from __future__ import annotations

import dataclasses
import io
import json
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np

from . import plots
from .._fit_loop import INTERRUPTED, ending
from .._errors import MetriplexError, TrainingDiverged
from ._lock import LOCK_NAME, RunLock, check_not_in_use
from ._selection import TrajectoryIds, format_ids
from ._build import (Given, build_loss, build_model, casimir_variables, constant_variables,
                     stopping_for, units_for)
from ._repeats import Training, good_score, repeats_for, train_repeats
from ._report import report_figures
from ._trainings_note import search_cut_short
from ._data_checks import (FOURTH_ORDER, chosen_scheme, coarse_note, coarse_steps,
                           data_notes, spacing_note)
from ._resume import (check_resume, decisions, earlier_seconds, left_checkpoint,
                      remove_stage_checkpoints, resume_differences, spent_seconds)
from .config import RunConfig, scheme_from_name, validate
from ..data import Trajectories, pair_spacing
from .._rounding import needs_float64
from ..diagnostics import evaluate, rollout_data
from ..io import check_output_folder, save, write_json

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

    from .._model import GenericModel
    from .._train import History


def check_run_folder(out: str | Path, *, overwrite: bool = False, resume: bool = False) -> None:
    """Whether a training may write the run folder ``out``; checked before any work, and
    again once the folder is locked. Creates nothing."""
    out = Path(out)
    if resume and overwrite:
        raise MetriplexError(
            "--resume continues the interrupted run in --out and --overwrite replaces it; got "
            "both. Give --resume to continue it, or --overwrite to start over."
        )
    check_output_folder(out)
    check_not_in_use(out)
    if resume:
        if not left_checkpoint(out, 0):
            raise MetriplexError(
                f"cannot resume: {str(out)!r} holds no checkpoint (a run interrupted before "
                "its first checkpoint keeps none). Start it again with --overwrite instead of "
                "--resume."
            )
        return
    if out.is_dir() and any(p.name != LOCK_NAME for p in out.iterdir()) and not overwrite:
        raise MetriplexError(
            f"output folder {str(out)!r} exists and is not empty; refusing to overwrite it. Pass "
            "--overwrite, choose another --out, or --resume an interrupted run."
        )


def _prepare_dir(out: Path, *, overwrite: bool, resume: bool) -> None:
    check_run_folder(out, overwrite=overwrite, resume=resume)
    out.mkdir(parents=True, exist_ok=True)


def train_run(
    data: Trajectories,
    config: RunConfig,
    out: str | Path,
    *,
    overwrite: bool = False,
    resume: bool = False,
    progress: bool = True,
    trajectories: ArrayLike | None = None,
    validation_ids: ArrayLike | None = None,
    source: dict | None = None,
) -> tuple[GenericModel, History, Trajectories, Trajectories | None, float]:
    """Train a model described by ``config`` on ``data`` and fill the run folder ``out``.

    ``trajectories``: the ids of ``data`` to use (default all). ``validation_ids``: the ids of
    those that validate, the rest train (empty: no validation); by default
    ``config.validation`` of them, drawn with ``config.seed``. ``source`` (e.g. the data file
    and ``dt``) is recorded in ``config.json`` beside the data's fingerprint, which ``resume``
    compares with the interrupted run's.
    """
    validate(config, data.n)
    parts = RunData.of(data, config, trajectories=trajectories,
                       validation_ids=validation_ids, source=source)
    return train_parts(parts, config, out, overwrite=overwrite, resume=resume,
                       progress=progress)


class RunData(NamedTuple):
    """What a training keeps of its data: the ``train`` and ``valid`` parts of
    :func:`split_trajectories`, ``info``, the source and fingerprint of the whole data, and
    ``validation_by`` (``"ids"`` where given, else ``"fraction"``), both recorded in
    ``config.json``. Without the whole data, which the caller can then drop: ``metriplex
    train`` holds the file's states once, not twice (#14)."""

    train: Trajectories
    valid: Trajectories | None
    info: dict
    validation_by: str

    @classmethod
    def of(cls, data: Trajectories, config: RunConfig, *,
           trajectories: ArrayLike | None = None, validation_ids: ArrayLike | None = None,
           source: dict | None = None) -> "RunData":
        """The parts of ``data`` that :func:`train_run` trains and validates on (its
        ``trajectories``, ``validation_ids`` and ``source``)."""
        train, valid = split_trajectories(data, config, trajectories=trajectories,
                                          validation_ids=validation_ids)
        starts = [x[0].tolist() for _, x in train]  # evaluate tells trained-on data by them
        return cls(train, valid, {**(source or {}), **data.fingerprint(), "train_starts": starts},
                   "fraction" if validation_ids is None else "ids")


def train_parts(parts: RunData, config: RunConfig, out: str | Path, *,
                overwrite: bool = False, resume: bool = False, progress: bool = True,
                ) -> tuple[GenericModel, History, Trajectories, Trajectories | None, float]:
    """:func:`train_run` on data already split (:meth:`RunData.of`)."""
    out = Path(out)
    validate(config, parts.train.n)
    check_output_folder(out)
    with RunLock(out) as lock:
        if lock.note:
            print(lock.note, file=sys.stderr)
        return _train_run(parts, config, out, overwrite=overwrite, resume=resume,
                          progress=progress)


def split_trajectories(data: Trajectories, config: RunConfig, *,
                       trajectories: ArrayLike | None = None,
                       validation_ids: ArrayLike | None = None,
                       ) -> tuple[Trajectories, Trajectories | None]:
    """``(train, validation)`` of :func:`train_run` (see its ``trajectories`` and
    ``validation_ids``); ids that ``data`` lack, or no trajectory left to train, are refused."""
    if trajectories is not None:
        chosen = TrajectoryIds.of(np.asarray(trajectories).reshape(-1).tolist(),
                                  "trajectories")
        if not len(chosen):
            raise MetriplexError("trajectories is empty; give at least one id (None: all).")
        data = data.select(chosen.pick(data.ids, "the data"))
    if validation_ids is None:
        return data.split(config.validation, seed=config.seed)
    held = TrajectoryIds.of(np.asarray(validation_ids).reshape(-1).tolist(), "validation_ids")
    valid = held.pick(data.ids, "the selected trajectories")
    rest = np.setdiff1d(data.ids, valid)
    if len(rest) == 0:
        raise MetriplexError(
            f"validation_ids takes every selected trajectory ({format_ids(valid)}), which "
            "leaves none to train on; leave at least one out of it."
        )
    return data.select(rest), (data.select(valid) if len(valid) else None)


def _precision(config: RunConfig, train: Trajectories, saved: dict) -> tuple[bool, list[str]]:
    """Whether the run trains in float64, and the note that says why where the data decided
    it: ``--float64``/``--no-float64`` as given, else an interrupted run's choice (``saved``),
    else float64 where float32 would round the states into the rates (:func:`needs_float64`)."""
    if config.float64 is not None:
        return config.float64, []
    if saved:  # a run saved before the choice trained in float32
        return bool((saved.get("decided") or {}).get("float64", False)), []
    why = needs_float64(train.pairs(), train.names)
    return why is not None, [] if why is None else [
        f"note: training in float64: {why}. --no-float64 trains in float32 anyway (faster); "
        "subtracting the offset from that variable in the data lets it train in float32."]


def _train_run(parts: RunData, config, out, *, overwrite, resume, progress):
    _prepare_dir(out, overwrite=overwrite, resume=resume)
    saved = run_config(out) if resume else {}  # the interrupted run's config.json
    if resume:
        stored = saved.get("config")
        if stored is None:
            raise MetriplexError(
                f"cannot resume: {str(out / 'config.json')!r} is missing, so the interrupted "
                "run's settings are unknown. Start a new run (--overwrite) instead of --resume."
            )
        was = RunConfig.from_json(stored)
        if "temperature_init" not in stored:  # a run made before the option resumes without
            was = dataclasses.replace(was, temperature_init=False)
            config = dataclasses.replace(config, temperature_init=config.temperature_init
                                         or False)
        was = dataclasses.replace(was, scheme=trained_scheme(saved),
                                  float64=_precision(was, parts.train, saved)[0])
        config = dataclasses.replace(config, scheme=config.scheme or was.scheme,
                                     float64=_precision(config, parts.train, saved)[0])
        if said := resume_differences(was, config):
            raise MetriplexError(
                f"--resume needs the options of the interrupted run, but they differ: {said}. "
                "Repeat the original options (config.json in the run folder lists them), or "
                "start a new run (--overwrite)."
            )
    given_train, valid, data_info, validation_by = parts
    if resume:
        check_resume(saved, data_info, given_train, valid)
    float64, precision_note = _precision(config, given_train, saved)
    if float64:
        jax.config.update("jax_enable_x64", True)
    dtype = jnp.float64 if float64 else jnp.float32
    # A resumed run keeps the spacing it trained with (1 in a run from before the choice).
    spacing = config.every or ((saved.get("decided") or {}).get("every", 1) if resume
                               else pair_spacing(given_train))
    train = given_train.interleaved(spacing)
    model_key, fit_key = jr.split(jr.key(config.seed))
    given = Given.of(config, train.n)  # a file: L or M read once
    # The trajectories recorded, not the interleaved copies that pair noisy samples further
    # apart: one trajectory stays one (the verdict's training_trajectories check).
    units = dataclasses.replace(units_for(config, train, given),
                                trajectories=len(given_train.ids))
    free, said = casimir_variables(config, given.poisson), io.StringIO()
    constant = constant_variables(config, train, note=said)
    # Built before anything is written: a structure the data cannot take is refused first.
    first = build_model(config, train, key=model_key, units=units, constant=constant, given=given)
    coarse = coarse_steps(given_train, spacing)
    scheme = config.scheme or chosen_scheme(coarse)  # given, else the data's
    for line in ([] if resume else data_notes(given_train, valid, config.entropy, free)
                 + coarse_note(coarse, scheme, config.scheme is None) + spacing_note(
                     given_train, spacing, config.every) + precision_note
                 ) + said.getvalue().splitlines():
        print(line, file=sys.stderr)
    budget = None if config.max_minutes is None else 60.0 * config.max_minutes
    # --max-minutes caps the whole run: a resumed one counts what the interrupted one spent.
    began = time.perf_counter() - (spent_seconds(out) if resume else 0.0)
    earlier = earlier_seconds(out) if resume else []  # before config.json is written again
    header_config, config = config.to_json(), dataclasses.replace(config, scheme=scheme)
    loss = build_loss(config, units, train)
    stopping = stopping_for(config)
    repeats, good = repeats_for(config, valid), good_score(valid)
    header = {
        "config": header_config,
        # What options left at None/"auto" decided: the run's stages, walls and exact blocks
        # (those of the kept training, where another friction was kept: its "friction").
        "decided": {**decisions(config),
                    "entropy_of": None if free is None else list(free),
                    "patience": None if stopping is None else stopping.patience,
                    "repeats": repeats, "good_score": good, "every": spacing, "scheme": scheme,
                    "float64": float64,
                    # said after training too, where the scheme learns the step's map
                    "coarse_steps": None if scheme in FOURTH_ORDER else coarse},
        "names": list(train.names),
        "n": train.n,
        "train_trajectories": [int(i) for i in given_train.ids],
        "validation_trajectories": [] if valid is None else [int(i) for i in valid.ids],
        # "ids": given (--validation-ids, --split); "fraction": config.validation of them at
        # random (config.seed), or the last samples of a single trajectory.
        "validation_by": validation_by,
        # The whole data file as read (--dt applied), whichever trajectories were selected.
        "data": data_info,
        "loss_terms": list(loss.names),
        "units": units.to_json(),
        "constant_variables": list(constant),
    }
    write_json(out / "config.json", header)

    def keep(model: GenericModel | None, history: History | None, **extra: Any) -> None:
        """Write the run's model and history (each where given)."""
        if model is not None:
            save(out / "model.mpx", model, n=train.n, names=train.names, extra=extra or None)
        if history is not None:
            write_json(out / "history.json", history.to_json())

    one = Training(config, train, valid, units=units, constant=constant, given=given,
                   dtype=dtype, loss=loss, keys=(model_key, fit_key), out=out,
                   progress=progress, budget=budget, began=began, first=first, repeats=repeats)
    try:
        model, history, outcomes, chosen = train_repeats(
            one, repeats=repeats, out=out, resume=resume, budget=budget, began=began,
            keep=keep, change=one.change_of, good=good, earlier=earlier,
            degenerate=one.degenerate)
    except TrainingDiverged as e:
        keep(e.model, e.history)
        raise
    kept = one.config_of(chosen)  # its friction or E's form can be another (config_for)
    if kept is not config:
        header["decided"] = {**header["decided"], "friction": kept.friction,
                             "quadratic": kept.quadratic, **decisions(kept)}
        header["loss_terms"] = list(build_loss(kept, units, train).names)
    # How each training ended, one or several (a new-user check looked for it after one).
    write_json(out / "config.json", {**header, "trainings": [o.to_json() for o in outcomes],
                                     "kept_training": chosen})
    seconds = time.perf_counter() - began  # every stage and training
    keep(model, history, train_seconds=seconds)
    if ending(history.stopped) != INTERRUPTED:
        remove_stage_checkpoints(out)
    plots.save_figure(
        plots.loss_curves(history), out / "figures" / "loss",
        step=np.asarray(history.step),
        **{f"train_{k}": np.asarray(v) for k, v in history.train.items()},
        **{f"valid_{k}": np.asarray(v) for k, v in history.valid.items()},
    )
    return model, history, given_train, valid, seconds


def run_verdict(run_dir: str | Path, model: Any, data: Trajectories, report: dict, *,
                steps: int = 3000, progress: bool = False) -> dict:
    """``metriplex evaluate``'s verdict on ``data`` of the model of the run in ``run_dir``
    (``report``: its :func:`~metriplex.evaluate` on them): how its training ended, its
    training data's units, and a black-box reference of ``steps`` steps trained with the
    run's width, depth, learning rate and batch size, so that both give the same figures."""
    from ..verdict import verdict
    from ._warnings import trained_units

    run = run_config(run_dir)
    cfg, ended = run.get("config", {}), training_outcome(run_dir)
    return verdict(model, data, report=report, converged=ended["converged"],
                   stopped=ended["stopped"], width=cfg.get("width", 64),
                   depth=cfg.get("depth", 2), steps=steps, learning_rate=cfg.get("lr", 1e-2),
                   batch_size=cfg.get("batch_size", 256), progress=progress,
                   trained_on=trained_units(run.get("units") or {}))


def trained_scheme(saved: dict) -> str:
    """The scheme a run trained with (``saved``: its config.json): given, else its data's."""
    given, decided = saved.get("config") or {}, saved.get("decided") or {}
    return given.get("scheme") or decided.get("scheme") or "cn"


def run_config(run_dir: str | Path) -> dict:
    """The contents of the run folder's ``config.json`` (an empty dict without one); a damaged file
    is refused with a message that says how to repair the folder."""
    path = Path(run_dir) / "config.json"
    if not path.is_file():
        return {}
    try:
        obj = json.loads(path.read_text())
    except (ValueError, UnicodeDecodeError) as e:
        raise MetriplexError(
            f"{str(path)!r} is not valid JSON ({e}); the run folder is damaged. Delete that "
            "file (the scheme then defaults to cn; pass --scheme), or re-train."
        ) from None
    if not isinstance(obj, dict) or not isinstance(obj.get("config", {}), dict):
        raise MetriplexError(
            f"{str(path)!r} does not hold a run configuration (an object with a `config` "
            "object); the run folder is damaged. Delete that file, or re-train."
        )
    return obj


def training_outcome(run_dir: str | Path) -> dict:
    """How the run's training ended, from its ``history.json``: ``converged`` (bool) and
    ``stopped`` (the reason), both ``None`` when unknown (a bare model file, no history, or
    one that cannot be read); not converged where the time budget cut the repeats short
    before one training was judged good (:func:`search_cut_short`). The verdict weighs
    them."""
    path = Path(run_dir) / "history.json"
    try:
        obj = json.loads(path.read_text()) if path.is_file() else {}
    except (OSError, ValueError, UnicodeDecodeError):
        obj = {}
    if not isinstance(obj, dict):
        obj = {}
    converged = obj.get("converged")
    stopped = obj.get("stopped")
    try:  # a damaged config.json leaves the history's word (evaluate says so elsewhere)
        cut = search_cut_short(run_config(run_dir)) if converged is True else ""
    except MetriplexError:
        cut = ""
    if cut:  # the kept training converged, but the search for a good one was cut short
        return {"converged": False, "stopped": cut}
    return {"converged": converged if isinstance(converged, bool) else None,
            "stopped": stopped if isinstance(stopped, str) and stopped else None}


def evaluate_run(model: GenericModel, data: Trajectories, *, scheme: str = "cn",
                 figures: Path | None = None,
                 horizon: float | None = None, solver: str | None = None,
                 progress: bool = False, step_check: bool = True) -> dict:
    """Metrics on ``data`` and, if ``figures`` is given, the standard figure set; the
    trajectories are rolled out once for both (with a progress bar when ``progress`` and the
    data are large enough to be rolled out in batches). ``step_check``: also measure the
    step sensitivity (:func:`~metriplex.diagnostics.step_sensitivity`)."""
    sch = scheme_from_name(scheme, solver=solver)
    rollout = rollout_data(model, data, scheme=sch, progress=progress)
    report = evaluate(model, data, scheme=sch, horizon=horizon, rollout=rollout,
                      step_check=step_check, progress=progress)
    if figures is not None:
        report_figures(model, data, figures, scheme=scheme, solver=solver, rollout=rollout,
                       progress=progress)
    return report
