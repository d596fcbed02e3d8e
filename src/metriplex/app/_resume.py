"""What a resumed run must share with the interrupted one (``metriplex train --resume``): its
options, where those left at None/"auto" are compared by what they decide, its data and its
split; and where each training and stage keeps its checkpoint."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

from .._errors import MetriplexError
from .._fit_loop import ENDED, INTERRUPTED, STEP_BUDGET, ending
from ._build import jacobi_of, residual_metric_of
from ._selection import format_ids
from ._stages import starts_for
from .config import (RunConfig, confine_on, exact_blocks, hold_energy_on, reversible_first_on,
                     temperature_init_on, temperature_weight)

if TYPE_CHECKING:
    from ..data import Trajectories

#: Options a resumed run may change: the wall-time cap (``--max-minutes``), which changes no
#: step of the training.
RESUME_MAY_CHANGE = ("max_minutes",)

#: Options whose default is decided from the others: a resume compares what they decide, so a
#: run saved with the decision spelled out (or made before the option had a default of None)
#: resumes with the option left out.
DECIDED = {"confine": confine_on, "reversible_first": reversible_first_on,
           "hold_energy": hold_energy_on, "w_temperature": temperature_weight,
           "temperature_init": temperature_init_on,
           "starts": starts_for, "residual_metric": residual_metric_of, "jacobi": jacobi_of}


def decisions(config: RunConfig) -> dict[str, Any]:
    """What the options left at None/"auto" decide for ``config``, for config.json's
    ``decided``: :data:`DECIDED` and the exact blocks."""
    exact_L, exact_M = exact_blocks(config)
    return {**{k: decide(config) for k, decide in DECIDED.items()},
            "exact_poisson_degeneracy": exact_L, "exact_friction_degeneracy": exact_M}


def resume_differences(saved: RunConfig, given: RunConfig) -> str:
    """The options of ``given`` that differ from those of the interrupted run, as flags."""
    said = []
    for k in saved.to_json():
        if k in RESUME_MAY_CHANGE:
            continue
        a, b = (DECIDED[k](saved), DECIDED[k](given)) if k in DECIDED else \
            (getattr(saved, k), getattr(given, k))
        if a != b:
            flag = "--" + k.replace("_", "-")
            if isinstance(a, bool) and isinstance(b, bool):
                on, off = flag, "--no-" + flag[2:]
                said.append(f"it ran with {on if a else off}, this command gives "
                            f"{on if b else off}")
            else:
                said.append(f"{flag} was {a!r}, given {b!r}")
    return "; ".join(said)


def describe_data(info: dict) -> str:
    """The data a run trained on, from config.json's ``data`` (``info``), in a few words."""
    where = f"{info['file']!r}" if info.get("file") else "data"
    if info.get("dt") is not None:
        where += f" with --dt {info['dt']!r}"
    ids = info.get("trajectory_ids") or []
    rows, n = (info.get("shape") or [None, None])[:2]
    return (f"{where} ({len(ids)} trajectories, ids {format_ids(ids)}; {rows} rows x {n} "
            f"variables; sha256 {str(info.get('sha256'))[:12]})")


def check_resume(stored: dict, data_info: dict, train: Trajectories,
                 valid: Trajectories | None) -> None:
    """``--resume`` continues only the interrupted run: the same data, the same split."""
    old = stored.get("data")
    if isinstance(old, dict) and old.get("sha256") and old.get("sha256") != data_info["sha256"]:
        raise MetriplexError(
            f"--resume needs the data of the interrupted run, but they differ: it trained on "
            f"{describe_data(old)}; this command gives {describe_data(data_info)}. Resume "
            "with the same data file (and the same --dt), or start a new run (--overwrite)."
        )
    ids = (sorted(int(i) for i in train.ids),
           [] if valid is None else sorted(int(i) for i in valid.ids))
    before = (sorted(stored.get("train_trajectories", ids[0])),
              sorted(stored.get("validation_trajectories", ids[1])))
    if before != ids:
        raise MetriplexError(
            f"--resume needs the trajectories of the interrupted run, but they differ: it "
            f"trained on {format_ids(before[0])} and validated on {format_ids(before[1])}; this "
            f"command trains on {format_ids(ids[0])} and validates on {format_ids(ids[1])}. "
            "Repeat its --trajectories, --validation-ids or --split, or pass --split RUN_DIR to "
            "reuse its split."
        )


def spent_seconds(out: Path) -> float:
    """The seconds that the interrupted run in ``out`` spent (its ``model.mpx``'s
    ``train_seconds``, written when it stopped: every stage and training, and those of the
    runs it resumed), so that ``--max-minutes`` caps the whole run; 0 where unknown (a run
    killed before it could write it)."""
    from ..io import read_header

    try:
        seconds = float(read_header(out / "model.mpx").get("extra", {}).get("train_seconds", 0))
    except (OSError, ValueError, TypeError, MetriplexError):
        return 0.0
    return seconds if seconds > 0 else 0.0


def earlier_seconds(out: Path) -> list[float]:
    """Each training's seconds as the interrupted run in ``out`` recorded them
    (``config.json``'s ``trainings``), to which a resumed training adds its own; ``[]`` where
    unknown (a run killed before it wrote them: the trainings' checkpoints then tell their
    main stages' time, :func:`checkpoint_seconds`)."""
    import json
    import math

    try:
        trainings = json.loads((out / "config.json").read_text()).get("trainings") or []
        seconds = [float(t.get("seconds") or 0.0) for t in trainings]
    except (OSError, ValueError, TypeError, AttributeError):
        return []
    return [v if math.isfinite(v) and v > 0 else 0.0 for v in seconds]


def _checkpoint_meta(path: Path) -> dict:
    """A checkpoint's header (its step ``done`` and ``history``), ``{}`` where it cannot be
    read."""
    from .._checkpoint import read_meta

    try:
        return read_meta(path)
    except (OSError, ValueError):
        return {}


def checkpoint_seconds(path: Path) -> float:
    """The training time that a checkpoint's history holds (the last of its ``time``), 0 where
    there is none or it cannot be read: what a resumed :func:`~metriplex.fit` counts against its
    ``max_seconds`` before it trains on."""
    try:
        times = _checkpoint_meta(path)["history"]["time"]
        return float(times[-1]) if times else 0.0
    except (KeyError, TypeError, ValueError, IndexError):
        return 0.0


def resuming_line(path: Path, what: str) -> str:
    """What ``metriplex train --resume`` says as it goes on with ``what`` (e.g. "training 1")
    from the checkpoint at ``path``: that it had ended (its stopping rule or its steps ended
    it, and :func:`~metriplex.fit` keeps it), else the step it goes on from and what had
    stopped it (a time budget: a larger ``--max-minutes`` trains on; it said "kept as it was"
    and went on, in a new-user check)."""
    meta = _checkpoint_meta(path)
    done, stopped = meta.get("done"), str((meta.get("history") or {}).get("stopped", ""))
    at = f" at step {done:,}".replace(",", " ") if isinstance(done, int) else ""
    if ending(stopped) in (*ENDED, STEP_BUDGET):
        return f"resuming: {what} had ended{at} ({stopped}); kept as it was"
    if stopped and ending(stopped) != INTERRUPTED:
        return (f"resuming {what} from its checkpoint{at}, where it had stopped ({stopped}); "
                "it trains on where --max-minutes allows more")
    return f"resuming {what} from its checkpoint{at}"


#: The stages before the main training that keep checkpoints of their own (``--reversible-first``
#: and ``--hold-energy``), by the names of their files.
STAGES = ("first-stage", "held-stage")


def checkpoint_path(out: Path, repeat: int, stage: str = "") -> Path:
    """Training ``repeat``'s checkpoint (0 based): the first one's is ``checkpoint.ckpt``, as
    without repeats; the second's ``checkpoint-2.ckpt``, and so on. A ``stage`` of
    :data:`STAGES` names its own: ``first-stage.ckpt``, ``first-stage-2.ckpt``, ..."""
    stem = stage or "checkpoint"
    return out / (f"{stem}.ckpt" if repeat == 0 else f"{stem}-{repeat + 1}.ckpt")


def left_checkpoint(out: Path, repeat: int) -> bool:
    """Whether training ``repeat`` left a checkpoint to resume from, of its main training or
    of a stage before it."""
    return any(checkpoint_path(out, repeat, stage).is_file() for stage in ("", *STAGES))


def remove_stage_checkpoints(out: Path) -> None:
    """Remove the stages' checkpoints of a finished run (its trainings' own stay, for
    ``--resume`` with more steps)."""
    for path in out.glob("*.ckpt"):
        if path.name.startswith(STAGES):
            path.unlink(missing_ok=True)
