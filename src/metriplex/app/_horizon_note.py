"""The note on how soon a model's rollouts from nearby states part (``evaluate``'s
``predictability_time``, :func:`metriplex.diagnostics.initial_state_sensitivity`): beyond
that time a whole-trajectory error measures the motion's sensitivity as much as the model."""

from __future__ import annotations

from .._sensitivity import TWIN_APART, TWIN_OFFSET


def predictability_note(metrics: dict) -> list[str]:
    """A note where the model's twins part within the evaluated trajectories, naming the time
    and the ``--horizon`` that judges the model before it (none once ``--horizon`` is that
    short already)."""
    when = metrics.get("predictability_time")
    if when is None or metrics.get("horizon", float("inf")) <= when:
        return []
    growth = TWIN_APART / TWIN_OFFSET
    return [f"note: the model's rollouts from states {TWIN_OFFSET:g} standard deviations apart "
            f"are {TWIN_APART:g} apart {when:.3g} after the start (median over the trajectories "
            f"checked; a {growth:.0f}-fold growth, as chaotic motion, or one whose period "
            "depends on its amplitude, makes it). Beyond that its predictions depend on the "
            "initial state more than on the model, as the system's own would if the model is "
            "right, so the whole-trajectory errors above measure that growth as much as the "
            f"model: judge it up to that time (evaluate ... --horizon {when:.3g})."]
