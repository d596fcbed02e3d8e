"""The one exception type that the command line turns into a clean message."""

from __future__ import annotations

import functools
import numbers
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import numpy as np


class MetriplexError(ValueError):
    """Bad input or an unrecoverable condition, explained: the rule, the value, the fix."""


class RolloutFailure(MetriplexError):
    """A rollout step failed: an implicit step did not converge, or an explicit step gave a
    non-finite state. ``partial`` holds the states computed before it."""

    def __init__(self, message: str, *, partial: np.ndarray | None = None, trajectory: int = 0,
                 time: float = 0.0) -> None:
        super().__init__(message)
        self.partial = partial
        self.trajectory = trajectory
        self.time = time


class TrainingDiverged(MetriplexError):
    """A loss term became non-finite. ``model`` is the best model before it; ``history`` too."""

    def __init__(self, message: str, *, model: Any = None, history: Any = None) -> None:
        super().__init__(message)
        self.model = model
        self.history = history


def expect_integer(value: Any, *, what: str, least: int, below: int | None = None,
                   fix: str = "") -> int:
    """``value`` as an ``int``, or a :class:`MetriplexError` unless it is an integer (Python's
    or NumPy's; not a bool, not a float such as 2.0) of at least ``least`` and, when given,
    less than ``below``.

    The one check of the integers that options take (steps, probes, pairs, seeds); the message
    says the rule, the value received and, when given, the ``fix``.
    """
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < least \
            or (below is not None and value >= below):
        rule = f">= {least}" if below is None else f"from {least} to {below - 1}"
        raise MetriplexError(
            f"{what} must be an integer {rule}; got {value!r}." + (f" {fix}" if fix else "")
        )
    return int(value)


def count_of(what: str, *, least: int) -> Callable[[Any], int]:
    """:func:`expect_integer` as a field converter (``eqx.field(converter=...)``): a static
    field then holds a Python ``int`` whatever integer it was given."""
    return functools.partial(expect_integer, what=what, least=least)


def expect_instance(value: Any, kind: type, *, what: str, expected: str, fix: str = "") -> None:
    """Raise a :class:`MetriplexError` unless ``value`` is a ``kind``.

    For an option that must be an object of its kind (a root finder, a Jacobi estimator) or a
    flag, checked where it is set (a module's ``__check_init__``). The message says the rule
    (``what`` must be ``expected``), the value received and, when given, the ``fix``: often
    how to write a former string option.
    """
    if not isinstance(value, kind):
        raise MetriplexError(
            f"{what} must be {expected}; got {value!r}." + (f" {fix}" if fix else "")
        )
