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

from . import (
    charged_particle,
    double_pendulum_friction,
    heat_exchange,
    oscillator_bath,
    oscillator_family,
    relaxing_rigid_body,
    rlc_circuit,
    spinning_satellite,
    stiff_thermal_oscillator,
    thermoelastic_chain,
)
from ._case import ZooCase as ZooCase

#: Every zoo case, by system name, one line per system.
ZOO: dict[str, ZooCase] = {
    module.CASE.name: module.CASE
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
        oscillator_family,
    )
}
