"""What a zoo case is: a ground-truth system, how much data its user would have, and the
structure options that describe what that user knows; the data are the system's own
``defaults`` (:func:`case_settings`)."""

from __future__ import annotations

import dataclasses
from typing import Any, Mapping

from .._base import Settings, System


@dataclasses.dataclass(frozen=True)
class ZooCase:
    """One zoo benchmark: a system, its data, and what the user tells metriplex.

    - ``flags``: structure options as on the command line, without dashes
      (``{"poisson": "canonical:2", "entropy": "sum:4"}``); every other setting is the default.
    - ``trajectories`` training trajectories (validation is split from them) of ``steps`` steps
      of size ``dt`` in the system's own time unit (``time_unit``, for the table).
    - ``test_trajectories`` unseen initial conditions (another seed), rolled out for
      ``test_steps`` steps (default ``steps``).
    - ``held_out``: not used to choose defaults, only to check them.
    """

    system: System
    flags: Mapping[str, str]
    trajectories: int
    steps: int
    dt: float
    time_unit: str = "s"
    test_trajectories: int = 10
    test_steps: int | None = None
    held_out: bool = False
    note: str = ""

    @classmethod
    def of(cls, system: System, flags: Mapping[str, str], **options: Any) -> "ZooCase":
        """The case of ``system``: its ``defaults`` give ``trajectories``, ``steps`` and ``dt``;
        ``options`` are the other fields."""
        d = system.defaults
        return cls(system, flags, d.trajectories, d.steps, d.dt, **options)

    @property
    def name(self) -> str:
        """The system's name, which names the case."""
        return self.system.name

    @property
    def horizon_steps(self) -> int:
        """How many steps the test trajectories are rolled out: ``test_steps``, or ``steps``."""
        return self.steps if self.test_steps is None else self.test_steps


def case_settings(dt: float, steps: int, trajectories: int) -> Settings:
    """A zoo system's ``defaults``: the data of its case, ``steps`` steps of size ``dt`` per
    trajectory (our choice, not a published experiment)."""
    return Settings(dt, steps, trajectories, "zoo case (our choice)")
