"""What the run configuration's options may say, with the help text of each choice.

The structure options (``--energy``, ``--entropy``, ``--poisson``, ``--friction``,
``--jacobi``) and ``--schedule``: the command line's help (:mod:`metriplex.app.cli`) and the
checks of :func:`metriplex.app.config.validate` both read these tables, which
:mod:`metriplex.app.config` re-exports, as it does :data:`DEGENERACY_POINTS`
(``--degeneracy-at``).
"""

from __future__ import annotations

#: What each structure option may say (the part before any ``:``), with its help text: the
#: command line's help and ``config.validate`` both read these tables, so a new spelling is
#: one line here plus its case where the block is built (``config._known_*``, ``_build``).
ENERGY_CHOICES = {"neural": "neural (default)"}
ENTROPY_CHOICES = {
    "neural": "neural (default)",
    "sum": "sum:I,J,... (S = sum of those components, counted from 0)",
    "zero": "zero",
}
POISSON_CHOICES = {
    "neural": "neural (default)",
    "canonical": "canonical:K (first K positions, next K momenta)",
    "zero": "zero",
    "casimir3": "casimir3 (n = 3, Jacobi exact)",
    "lie-poisson": "lie-poisson (learned, linear in the state)",
    "file": "file:PATH (a constant L from .npy, .npz or .mat)",
}
FRICTION_CHOICES = {
    "neural": "neural (default)",
    "zero": "zero",
    "file": "file:PATH (a constant M from .npy, .npz or .mat)",
}
JACOBI_CHOICES = {
    "none": "none (default)",
    "exact": "exact",
    "stochastic": "stochastic (random probes; see --jacobi-probes, --jacobi-samples)",
}

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
