"""Ground-truth trajectories of a built-in system."""

from __future__ import annotations

import math
import numbers

import jax.numpy as jnp
import numpy as np
from jaxtyping import ArrayLike, Float

from .._errors import MetriplexError, RolloutFailure, expect_integer
from ..data import Trajectories
from .._solve.substeps import Substeps
from ..integrate import RK4, AbstractScheme, solve
from ._base import System
from ._registry import get_system
from .pendulum import PendulumEnergetic
from .pendulum_temperature import PendulumTemperature


#: The most substeps one recorded step of :func:`generate` may take (their count is a loop
#: bound in the compiled rollout).
MAX_SUBSTEPS = 1_000_000


def generate(
    system: System | str,
    *,
    trajectories: int | None = None,
    steps: int | None = None,
    dt: float | None = None,
    seed: int = 0,
    substeps: int | None = None,
    scheme: AbstractScheme | None = None,
    x0: Float[ArrayLike, "trajectories n"] | None = None,
) -> Trajectories:
    r"""Ground-truth trajectories: ``trajectories`` initial states from
    ``system.sample_initial(trajectories, seed=seed)``, each recorded at
    :math:`t_k = k\,\Delta t`, :math:`k = 0..` ``steps``.

    Arguments left ``None`` take the system's published settings (``system.defaults``).

    Each recorded step is ``substeps`` steps of ``scheme`` (default: classical RK4,
    ``substeps = ceil(dt / system.max_substep)``), run by :func:`metriplex.solve` (batched,
    jitted) in JAX's default float type (float64 when x64 is enabled). With :math:`S` linear in
    the state, every Runge–Kutta step with positive weights keeps :math:`\Delta S \ge 0`:
    :math:`\Delta S = h\sum_i b_i\,\nabla S\cdot f(X_i)` and :math:`\nabla S\cdot f \ge 0`
    everywhere. The temperature pendulum is integrated in :math:`(q, p, s)` (where this holds)
    and mapped to :math:`(q, p, \theta)`.

    Measured maximum absolute error against SciPy DOP853 (rtol = atol = 1e-12), float64,
    published ``dt``, default substeps, 3 trajectories (seed 0); ``tests/test_systems.py``
    asserts the bound (print with ``pytest tests/test_systems.py -k dop853 -s``):

    =============================  =====================  =========  =======  =========
    system                         steps x dt             substeps   error    bound
    =============================  =====================  =========  =======  =========
    rigid-body                     200 x 2π/100           7          3.3e-12  1e-10
    pendulum-energetic (unit)      400 x 0.1              20         6.5e-8   1e-6
    pendulum-energetic (spnn)      40 x 0.3               328        7.7e-9   1e-7
    pendulum-energetic (spnn)      199 x 0.3 (slow test)  328        4.0e-6   2e-5
    pendulum-temperature (unit)    500 x 0.04             8          4.8e-9   1e-6
    pendulum-temperature (spnn)    40 x 0.3               328        3.6e-6*  2e-5
    gas-containers                 400 x 0.02             10         7.6e-10  1e-7
    =============================  =====================  =========  =======  =========

    (*) :math:`\theta \approx 300`: DOP853's own error in :math:`\theta` (it moves by as much
    between rtol 1e-12 and 1e-13); against DOP853 run in :math:`(q, p, s)` and mapped, 5e-8.
    The spnn pendulum is sensitive (a 1e-8 change of :math:`x_0` grows to 4e-4 by
    :math:`t = 60`), which sets the error over its full horizon. For comparison,
    Crank–Nicolson with the same number of sub-steps errs by 1e-4 on gas-containers and
    ~5e-9 on the rigid body.

    Pass ``scheme=metriplex.CrankNicolson(), substeps=1`` for data made by exactly the scheme
    that a Crank–Nicolson-trained model rolls out with.

    ```python
    data = generate("pendulum-energetic", trajectories=100, steps=400, dt=0.1, seed=0)
    ```
    """
    system = get_system(system) if isinstance(system, str) else system
    d = system.defaults
    explicit_count = None if trajectories is None or x0 is None else trajectories
    trajectories = d.trajectories if trajectories is None else trajectories
    steps = d.steps if steps is None else steps
    dt = d.dt if dt is None else dt
    steps = _positive_int(steps, "steps")
    if not (isinstance(dt, numbers.Real) and math.isfinite(dt) and dt > 0.0):
        raise MetriplexError(f"`dt` must be a positive finite number; got {dt!r}.")
    dt = float(dt)
    if substeps is None:
        substeps = max(1, math.ceil(dt / system.max_substep - 1e-9))
        if substeps > MAX_SUBSTEPS:
            raise MetriplexError(
                f"dt = {dt:g} needs {substeps:.3g} substeps per recorded step: the "
                f"{system.name} system is integrated in substeps of at most "
                f"{system.max_substep:g} (its accuracy limit), and at most {MAX_SUBSTEPS:,} "
                f"substeps per step are allowed. Give a dt of at most "
                f"{MAX_SUBSTEPS * system.max_substep:g} (--dt), in the system's time unit."
            )
    substeps = _positive_int(substeps, "substeps")
    if substeps > MAX_SUBSTEPS:
        raise MetriplexError(
            f"`substeps` must be at most {MAX_SUBSTEPS:,} per recorded step; got {substeps}.")
    if x0 is None:
        x0 = system.sample_initial(_positive_int(trajectories, "trajectories"), seed=seed)
    x0 = np.asarray(x0, dtype=np.float64)
    if x0.ndim != 2 or x0.shape[1] != system.n:
        raise MetriplexError(
            f"x0 must have shape (trajectories, {system.n}) for {system.name!r}; got {x0.shape}."
        )
    if explicit_count is not None and explicit_count != x0.shape[0]:
        raise MetriplexError(
            f"got trajectories={explicit_count} but {x0.shape[0]} initial states in x0; pass "
            "one of them, or make them agree."
        )

    integrated = system
    if isinstance(system, PendulumTemperature):
        integrated = PendulumEnergetic(system.config)
        x0 = np.asarray(system.to_entropy(jnp.asarray(x0)), dtype=np.float64)
    dtype = jnp.zeros(()).dtype  # float64 when x64 is enabled, else float32
    ts = jnp.arange(steps + 1, dtype=dtype) * jnp.asarray(dt, dtype)
    inner = RK4() if scheme is None else scheme
    stepper = inner if substeps == 1 else Substeps(inner, int(substeps))
    out = solve(integrated.model, jnp.asarray(x0, dtype), ts, scheme=stepper)
    failed = np.asarray(out.failed_step)
    if np.any(failed >= 0):
        b = int(np.argmax(failed >= 0))
        k = int(failed[b])
        raise RolloutFailure(
            f"ground-truth step {k} (t={float(ts[k]):.6g}) of trajectory {b} of {system.name!r} "
            f"did not converge or left the finite range; try more substeps (got {substeps}) or "
            "a smaller dt.",
            partial=np.asarray(
                out.xs[b, :k] if integrated is system else system.from_entropy(out.xs[b, :k])
            ),
            trajectory=b,
            time=float(ts[k]),
        )
    xs = out.xs
    if integrated is not system:
        xs = system.from_entropy(xs)
    return Trajectories.from_arrays(
        np.asarray(ts, np.float64), np.asarray(xs, np.float64), system.names
    )


def _positive_int(value, name: str) -> int:
    return expect_integer(value, what=f"`{name}`", least=1)
