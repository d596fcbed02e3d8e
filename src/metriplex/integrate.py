r"""Time stepping: the schemes, the root finders of the implicit ones, their registries by
name, and rollouts.

The schemes live one per file in ``metriplex._solve`` (:class:`RK4`, :class:`CrankNicolson`,
:class:`ImplicitMidpoint`, :class:`DiscreteGradient`), the root finders an implicit scheme
takes as ``root_finder=`` in ``metriplex._solve.root_finder`` (:class:`FixedPointThenNewton`,
the default, :class:`Newton`, :class:`FixedPoint`). This module is their public home, with
the base class of the implicit schemes (:class:`AbstractImplicitScheme`), and holds the
registries that the command line's ``--scheme`` and ``--solver`` names come from
(:data:`SCHEMES`, :data:`ROOT_FINDERS`). The names are parsed by the application layer
(:func:`metriplex.app.config.scheme_from_name`); the library takes the objects.
"""

from __future__ import annotations

from ._solve import (
    RK4,
    ROOT_FINDERS,
    AbstractImplicitScheme,
    AbstractRootFinder,
    AbstractScheme,
    CrankNicolson,
    DiscreteGradient,
    FixedPoint,
    FixedPointThenNewton,
    Hermite,
    ImplicitMidpoint,
    Newton,
    Rollout,
    discrete_generic_field,
    discrete_gradient,
    model_size,
    project_out,
    simulate,
    solve,
    step_failure,
)

__all__ = ["RK4", "ROOT_FINDERS", "SCHEMES", "AbstractImplicitScheme", "AbstractRootFinder",
           "AbstractScheme",
           "CrankNicolson", "DiscreteGradient", "FixedPoint", "FixedPointThenNewton",
           "Hermite", "ImplicitMidpoint", "Newton", "Rollout", "discrete_generic_field", "discrete_gradient",
           "model_size", "project_out", "simulate", "solve", "step_failure"]


SCHEMES: dict[str, type[AbstractScheme]] = {
    "cn": CrankNicolson,
    "midpoint": ImplicitMidpoint,
    "discrete-gradient": DiscreteGradient,
    "rk4": RK4,
    "hermite": Hermite,
}

