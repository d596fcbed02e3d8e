"""Checks, before any work, of what ``rollout`` and ``evaluate`` would write: never over what
they read (the data file, the run folder's files), and never over existing figures without
``--overwrite``."""

from __future__ import annotations

import argparse
from pathlib import Path

from .._errors import MetriplexError


def check_figures(folder: str | Path, overwrite: bool) -> None:
    """Refuse, before any work, report figures that would replace files in ``folder``
    without ``--overwrite``."""
    from ._report import FIGURE_SUFFIXES, REPORT_FIGURES, TEMPERATURE_FIGURE

    there = [f"{name}{suffix}" for name in (*REPORT_FIGURES, TEMPERATURE_FIGURE)
             for suffix in FIGURE_SUFFIXES
             if (Path(folder) / f"{name}{suffix}").exists()]
    if there and not overwrite:
        raise MetriplexError(
            f"--figures {str(folder)!r} already holds {', '.join(there[:4])}"
            + (f" and {len(there) - 4} more" if len(there) > 4 else "")
            + "; refusing to overwrite them. Pass --overwrite or choose another --figures "
            "folder."
        )


#: The files of a run folder that rollout and evaluate read, and never write.
RUN_FILES = ("model.mpx", "config.json", "history.json", "metrics.json")


def not_an_input(out: str | Path, args: argparse.Namespace, option: str = "--out") -> None:
    """Refuse an output that would replace what the command reads: the data file, or a file
    of the run folder (even with --overwrite, which replaces earlier outputs, not inputs)."""
    out = Path(out).resolve()
    data = Path(args.data).resolve()
    run = Path(args.run).resolve()
    if out == data:
        raise MetriplexError(
            f"{option} {str(args.data)!r} is the data file this command reads; writing there "
            f"would replace your data. Choose another {option}."
        )
    if out.parent == run and (out.name in RUN_FILES or out.name.endswith(".ckpt")):
        raise MetriplexError(
            f"{option} {str(out)!r} is a file of the run folder {str(args.run)!r}, which this "
            f"command reads; writing there would damage the run. Choose another {option}."
        )
