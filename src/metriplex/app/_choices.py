"""What the run configuration's options may say, with the help text of each choice.

The structure options (``--energy``, ``--entropy``, ``--poisson``, ``--friction``,
``--jacobi``) and ``--schedule``: the command line's help (:mod:`metriplex.app.cli`) and the
checks of :func:`metriplex.app.config.validate` both read these tables, which
:mod:`metriplex.app.config` re-exports, as it does :data:`DEGENERACY_POINTS`
(``--degeneracy-at``).
"""

from __future__ import annotations

from ._spellings import ENERGY, ENTROPY, FRICTION, POISSON

#: What each structure option may say (the part before any ``:``), with its help text, read
#: from the tables of :mod:`metriplex.app._spellings`, which also make the blocks: the command
#: line's help and ``config.validate`` both read these, so a new spelling is one line there.
ENERGY_CHOICES = {k: v.help for k, v in ENERGY.items()}
ENTROPY_CHOICES = {k: v.help for k, v in ENTROPY.items()}
POISSON_CHOICES = {k: v.help for k, v in POISSON.items()}
FRICTION_CHOICES = {k: v.help for k, v in FRICTION.items()}
JACOBI_CHOICES = {
    "auto": "auto (default: exact with lie-poisson, none otherwise)",
    "none": "none",
    "exact": "exact",
    "stochastic": "stochastic (random probes; see --jacobi-probes, --jacobi-samples)",
}

#: How the pair residual is measured (``--residual-metric``): ``correlated`` is
#: :meth:`metriplex.Units.residual_metric` of the training data, ``diagonal`` the plain norm,
#: ``auto`` the former where the model has a friction (see ``_build.residual_metric_of``).
RESIDUAL_METRICS = ("auto", "correlated", "diagonal")

#: Where soft degeneracy penalties are evaluated (``--degeneracy-at``): ``midpoints`` is the
#: losses' ``at_midpoints=True``.
DEGENERACY_POINTS = ("states", "midpoints")


def choices_help(table: dict[str, str]) -> str:
    """One option's choices as its help text lists them: ``a (default) | b:K (...) | ...``."""
    return " | ".join(table.values())


SCHEDULES = {
    "plateau": "cut the rate when the validation loss stops improving, stop after --lr-cuts "
               "cuts; --steps is a cap (default)",
    "cosine": "exactly --steps steps, the rate decayed by a cosine to 1%",
}
