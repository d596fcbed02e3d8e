"""Progress bars (tqdm) that do not flood logs: where stderr is not a terminal (a log file, a
pipe), a bar is redrawn at most every :data:`PIPED_INTERVAL` seconds instead of ten times a
second, unless ``TQDM_MININTERVAL`` in the environment says otherwise."""

from __future__ import annotations

import contextlib
import os
import sys
from collections.abc import Iterator
from contextvars import ContextVar
from typing import Any

from tqdm.auto import tqdm

#: Seconds between redraws of a bar written to a file or a pipe.
PIPED_INTERVAL = 30.0

#: tqdm's bar without its estimate of the time left: for work under a time budget, whose end
#: is not the bar's total (a fit's step cap), the caller shows the time left itself.
TIMED_BAR = "{l_bar}{bar}| {n_fmt}/{total_fmt} [{elapsed}, {rate_fmt}{postfix}]"

#: tqdm's bar with its estimate of the time left said to run to the step cap: for work that a
#: stopping rule usually ends well before its total.
CAPPED_BAR = ("{l_bar}{bar}| {n_fmt}/{total_fmt} [{elapsed}, cap in {remaining}, "
              "{rate_fmt}{postfix}]")

#: Where in a longer job the bars opened now are (:func:`progress_label`).
_LABELS: ContextVar[tuple[str, ...]] = ContextVar("metriplex_progress_labels", default=())


@contextlib.contextmanager
def progress_label(label: str) -> Iterator[None]:
    """Bars opened inside this block begin their description with ``label`` (nested labels
    in order, joined by ", "): a run of several trainings and stages shows which one a bar is,
    e.g. ``training 2 of at most 4, first stage, fit``."""
    token = _LABELS.set(_LABELS.get() + (label,))
    try:
        yield
    finally:
        _LABELS.reset(token)


def progress_bar(**kwargs: Any) -> tqdm:
    """``tqdm(**kwargs)``, redrawn at most every :data:`PIPED_INTERVAL` s where its stream
    (``file``, default stderr) is not a terminal, outside Jupyter (whose bars are widgets), and
    neither ``mininterval`` nor ``TQDM_MININTERVAL`` is given. (A bar whose postfix changes is
    redrawn then too.) Its description begins with the labels of the enclosing
    :func:`progress_label` blocks."""
    if "mininterval" not in kwargs and "TQDM_MININTERVAL" not in os.environ \
            and "ipykernel" not in sys.modules and not _terminal(kwargs.get("file")):
        kwargs["mininterval"] = PIPED_INTERVAL
    labels = _LABELS.get()
    if labels:
        kwargs["desc"] = ", ".join(labels + ((kwargs["desc"],) if kwargs.get("desc") else ()))
    return tqdm(**kwargs)


def _terminal(stream: Any = None) -> bool:
    try:
        return (sys.stderr if stream is None else stream).isatty()
    except (AttributeError, ValueError):  # an object without it, or a closed stream
        return False
