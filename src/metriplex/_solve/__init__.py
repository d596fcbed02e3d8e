r"""Time stepping: implicit Crank–Nicolson, midpoint and discrete-gradient steps (fixed-point
iteration with a Newton fallback), explicit RK4, batched rollouts.

Each scheme is a small object with two verbs:

- ``step(model, x, dt, guess)`` advances one step and says whether it converged;
- ``residual(model, x0, x1, dt, terms0, terms1)`` is the defect of a data pair under the scheme,
  in units of ``dx/dt`` — zero when ``x1`` is exactly the scheme's step from ``x0``. Training
  minimises it, so the model is learned for the scheme that will roll it out.

Implicit equations are solved with Optimistix by the scheme's ``root_finder`` (default
:class:`FixedPointThenNewton`: fixed-point iteration, and Newton's method where that does not
converge; see ``root_finder.py``); a step that does not converge is reported
(``Rollout.failed_step``), never passed on as a silent NaN.

Which scheme keeps what (for any model, to solver tolerance):

============================  ==================  ===================  =========
scheme                        :math:`E` conserved  :math:`\Delta S\ge0`  order
============================  ==================  ===================  =========
:class:`DiscreteGradient`     yes (any :math:`E`)  yes (any :math:`S`)   2
:class:`ImplicitMidpoint`     quadratic :math:`E`  linear :math:`S`      2
:class:`CrankNicolson`        no                   linear :math:`S`      2
:class:`RK4`                  no                   no                    4
============================  ==================  ===================  =========
"""


from .crank_nicolson import CrankNicolson
from .discrete_gradient import (
    DiscreteGradient,
    discrete_generic_field,
    discrete_gradient,
    project_out,
)
from .hermite import Hermite
from .midpoint import ImplicitMidpoint
from .rk4 import RK4
from .rollout import Rollout, model_size, simulate, solve, step_failure
from .root_finder import (
    ROOT_FINDERS,
    AbstractRootFinder,
    FixedPoint,
    FixedPointThenNewton,
    Newton,
)
from ._implicit import AbstractImplicitScheme
from ._scheme import AbstractScheme

__all__ = ["RK4", "ROOT_FINDERS", "AbstractImplicitScheme", "AbstractRootFinder",
           "AbstractScheme", "CrankNicolson", "DiscreteGradient", "FixedPoint",
           "FixedPointThenNewton", "Hermite", "ImplicitMidpoint", "Newton", "Rollout",
           "discrete_generic_field", "discrete_gradient", "model_size", "project_out", "simulate",
           "solve", "step_failure"]
