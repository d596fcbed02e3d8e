"""Progress bars (tqdm) that do not flood logs: where stderr is not a terminal (a log file, a
pipe), a bar is redrawn at most every :data:`PIPED_INTERVAL` seconds instead of ten times a
second, unless ``TQDM_MININTERVAL`` in the environment says otherwise."""

from __future__ import annotations

import os
import sys
from typing import Any

from tqdm.auto import tqdm

#: Seconds between redraws of a bar written to a file or a pipe.
PIPED_INTERVAL = 30.0


def progress_bar(**kwargs: Any) -> tqdm:
    """``tqdm(**kwargs)``, redrawn at most every :data:`PIPED_INTERVAL` s where stderr is not a
    terminal (and neither ``mininterval`` nor ``TQDM_MININTERVAL`` is given)."""
    if "mininterval" not in kwargs and "TQDM_MININTERVAL" not in os.environ \
            and not _terminal():
        kwargs["mininterval"] = PIPED_INTERVAL
    return tqdm(**kwargs)


def _terminal() -> bool:
    try:
        return sys.stderr.isatty()
    except (AttributeError, ValueError):  # replaced by an object without it, or closed
        return False
