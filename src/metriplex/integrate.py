r"""Time stepping: the schemes, their registry by name, and rollouts.

The schemes live one per file in ``metriplex._solve`` (:class:`RK4`, :class:`CrankNicolson`,
:class:`ImplicitMidpoint`, :class:`DiscreteGradient`); this module is their public home and
the registry that the command line's ``--scheme`` names come from (:data:`SCHEMES`).
"""

from __future__ import annotations

from ._errors import MetriplexError
from ._solve import (
    RK4,
    SOLVERS,
    AbstractScheme,
    CrankNicolson,
    DiscreteGradient,
    ImplicitMidpoint,
    Rollout,
    discrete_generic_field,
    discrete_gradient,
    model_size,
    project_out,
    simulate,
    solve,
    step_failure,
)
from ._solve._implicit import _Implicit

__all__ = ["RK4", "SCHEMES", "SOLVERS", "AbstractScheme", "CrankNicolson", "DiscreteGradient",
           "ImplicitMidpoint", "Rollout", "discrete_generic_field", "discrete_gradient",
           "model_size", "project_out", "scheme_from_name", "simulate", "solve", "step_failure"]


SCHEMES: dict[str, type[AbstractScheme]] = {
    "cn": CrankNicolson,
    "midpoint": ImplicitMidpoint,
    "discrete-gradient": DiscreteGradient,
    "rk4": RK4,
}


def scheme_from_name(name: str, *, solver: str | None = None) -> AbstractScheme:
    """The scheme called ``name``; ``solver`` (``auto``, ``newton``, ``fixed-point``) for an
    implicit one (default ``auto``)."""
    if name not in SCHEMES:
        raise MetriplexError(
            f"unknown time-stepping scheme {name!r}; choose one of {sorted(SCHEMES)}."
        )
    cls = SCHEMES[name]
    if solver is None:
        return cls()
    if not issubclass(cls, _Implicit):
        raise MetriplexError(
            f"--solver applies to the implicit schemes (cn, midpoint, discrete-gradient); "
            f"{name!r} is explicit. Leave --solver out."
        )
    return cls(solver=solver)
