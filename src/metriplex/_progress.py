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

#: tqdm's bar without its estimate of the time left: for work under a time budget, whose end
#: is not the bar's total (a fit's step cap), the caller shows the time left itself.
TIMED_BAR = "{l_bar}{bar}| {n_fmt}/{total_fmt} [{elapsed}, {rate_fmt}{postfix}]"


def progress_bar(**kwargs: Any) -> tqdm:
    """``tqdm(**kwargs)``, redrawn at most every :data:`PIPED_INTERVAL` s where its stream
    (``file``, default stderr) is not a terminal, outside Jupyter (whose bars are widgets), and
    neither ``mininterval`` nor ``TQDM_MININTERVAL`` is given. (A bar whose postfix changes is
    redrawn then too.)"""
    if "mininterval" not in kwargs and "TQDM_MININTERVAL" not in os.environ \
            and "ipykernel" not in sys.modules and not _terminal(kwargs.get("file")):
        kwargs["mininterval"] = PIPED_INTERVAL
    return tqdm(**kwargs)


def _terminal(stream: Any = None) -> bool:
    try:
        return (sys.stderr if stream is None else stream).isatty()
    except (AttributeError, ValueError):  # an object without it, or a closed stream
        return False
