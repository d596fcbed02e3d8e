r"""The zoo: GENERIC systems that metriplex's defaults are chosen and checked on.

None of them is a reference experiment. Each is a ground-truth :class:`~metriplex.systems.System`
(analytic :math:`E, S, L, M`, checked exactly GENERIC in ``tests/test_zoo_a.py`` and
``tests/test_zoo_b.py``) plus a
:class:`ZooCase`: how much data a user would have, and the structure options that describe
what such a user knows (e.g. ``--poisson canonical:2 --entropy sum:4``), nothing else.

Defaults are chosen on the cases with ``held_out=False`` and checked on the others
(``benchmarks/zoo.py``).
"""

from __future__ import annotations

import dataclasses
from typing import Mapping

from .._base import System


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

    @property
    def name(self) -> str:
        return self.system.name

    @property
    def horizon_steps(self) -> int:
        return self.steps if self.test_steps is None else self.test_steps


#: Every zoo case, by system name (filled in below, one line per system).
ZOO: dict[str, ZooCase] = {}


def _register() -> None:
    from . import (
        charged_particle,
        double_pendulum_friction,
        heat_exchange,
        oscillator_bath,
        relaxing_rigid_body,
        rlc_circuit,
        spinning_satellite,
        stiff_thermal_oscillator,
        thermoelastic_chain,
    )

    for module in (
        oscillator_bath,
        double_pendulum_friction,
        charged_particle,
        thermoelastic_chain,
        rlc_circuit,
        heat_exchange,
        relaxing_rigid_body,
        spinning_satellite,
        stiff_thermal_oscillator,
    ):
        ZOO[module.CASE.name] = module.CASE


_register()
