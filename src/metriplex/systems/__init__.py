r"""Ground-truth GENERIC systems with analytic :math:`E, S, L, M`, and data made from them.

Each system is a frozen dataclass around a typed, frozen config; it exposes ``model`` (a
:class:`~metriplex.GenericModel`), ``names``, ``sample_initial(num, *, seed)``,
``description``, ``parameter_summary()``, ``help_text()`` and ``defaults`` (published
``dt``, ``steps``, ``trajectories``).

```python
from metriplex.systems import SYSTEMS, generate, get_system

pend = get_system("pendulum-energetic", parameter_set="spnn")
data = generate(pend, trajectories=50, steps=199, dt=0.3, seed=0)   # metriplex.Trajectories
```
"""

from ._base import Settings as Settings
from ._base import System as System
from ._generate import Substeps as Substeps
from ._generate import generate as generate
from ._registry import SYSTEMS as SYSTEMS
from ._registry import get_system as get_system
from .gas import GasConfig as GasConfig
from .gas import GasContainers as GasContainers
from .pendulum import PendulumConfig as PendulumConfig
from .pendulum import PendulumEnergetic as PendulumEnergetic
from .pendulum_temperature import PendulumTemperature as PendulumTemperature
from .pendulum import entropy_to_temperature as entropy_to_temperature
from .pendulum import temperature_to_entropy as temperature_to_entropy
from .rigid_body import RigidBody as RigidBody
from .rigid_body import RigidBodyConfig as RigidBodyConfig
