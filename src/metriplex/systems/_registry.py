"""The built-in systems by name (what ``metriplex generate SYSTEM`` accepts)."""

from __future__ import annotations

from typing import Any

from .._errors import MetriplexError
from ._base import System
from .gas import GasContainers
from .pendulum import PendulumEnergetic
from .pendulum_temperature import PendulumTemperature
from .rigid_body import RigidBody
from .zoo import ZOO

#: Every built-in system with its default parameters, by name: the reference experiments'
#: systems, then the zoo (``metriplex.systems.zoo``).
SYSTEMS: dict[str, System] = {
    s.name: s for s in (RigidBody(), PendulumEnergetic(), PendulumTemperature(), GasContainers())
}
SYSTEMS.update({name: case.system for name, case in ZOO.items()})


def get_system(name: str, **params: Any) -> System:
    """The built-in system ``name`` with some parameters changed.

    ``params`` are fields of the system's config, each given as its type (``inertia=(10, 20,
    40)``, not text: ``metriplex generate --param`` parses text); the pendulums also take
    ``parameter_set="unit" | "spnn"``.

    ```python
    rb = get_system("rigid-body", inertia=(1.0, 2.0, 3.0))
    pend = get_system("pendulum-energetic", parameter_set="spnn")
    ```
    """
    if isinstance(name, System):
        return name.with_params(**params) if params else name
    if name not in SYSTEMS:
        raise MetriplexError(
            f"unknown system {name!r}; the built-in systems are {', '.join(SYSTEMS)}. "
            "Run `metriplex generate --help` for their parameters."
        )
    system = SYSTEMS[name]
    return system.with_params(**params) if params else system
