"""Ctrl-C during long work that runs compiled JAX code: turned into a request that the work
stops where it next looks, instead of an exception raised wherever Python happens to be."""

from __future__ import annotations

import signal
import threading


class CtrlC:
    """Ctrl-C while training: the first press asks the loop to stop where it next looks (after
    a chunk of steps or an evaluation: well under a second to a few seconds), the second
    interrupts at once.

    Without it the ``KeyboardInterrupt`` is raised wherever Python happens to be, which may be
    inside a JAX callback of compiled code, where it turns into a runtime error that a
    rollout check counts as a failed rollout: the press was lost and training went on. The
    handler is installed only over Python's default one in the main thread (a caller's own
    handler, or an ignored SIGINT, is left alone).
    """

    def __init__(self) -> None:
        self.requested = False
        self._previous = None

    def __enter__(self) -> "CtrlC":
        if (threading.current_thread() is threading.main_thread()
                and signal.getsignal(signal.SIGINT) is signal.default_int_handler):
            self._previous = signal.signal(signal.SIGINT, self._press)
        return self

    def _press(self, signum, frame):
        if self.requested:
            raise KeyboardInterrupt
        self.requested = True

    def check(self) -> None:
        """Raise ``KeyboardInterrupt`` here, in plain Python, if Ctrl-C was pressed."""
        if self.requested:
            raise KeyboardInterrupt

    def __exit__(self, *exc) -> None:
        if self._previous is not None:
            signal.signal(signal.SIGINT, self._previous)
