"""What the time grid of the data a model is rolled out on means for its predictions: how
soon its rollouts from nearby states part (``evaluate``'s ``predictability_time``,
:func:`metriplex.diagnostics.initial_state_sensitivity`: beyond that time a whole-trajectory
error measures the motion's sensitivity as much as the model), and steps far larger than the
training data's (:func:`step_warning`)."""

from __future__ import annotations

from typing import TYPE_CHECKING

from .._sensitivity import TWIN_APART, TWIN_OFFSET

if TYPE_CHECKING:
    from ..data import Trajectories

#: Beyond this factor between the largest step of the data rolled out on and that of the
#: training data, rollout and evaluate warn.
STEP_FACTOR = 4.0


def step_warning(units: dict, data: Trajectories) -> list[str]:
    """A warning where ``data``'s largest step exceeds the training data's (``units``:
    config.json's; ``step``) :data:`STEP_FACTOR`-fold: the model takes each interval of the
    data in one step of its scheme (and retries in substeps only where a step fails), so a
    grid coarser than it was trained on is a coarser prediction, not a shorter one (a
    new-user check's initial states with one more sample at t = 10, 200 training steps away,
    were predicted in one step each, with errors up to 7.6 and an entropy that fell, all
    "ok")."""
    from .._units import largest_step

    trained, top = units.get("step"), largest_step(data)
    if not trained or top is None or top <= STEP_FACTOR * float(trained):
        return []
    return [f"warning: these data's steps reach {top:.3g}, {top / trained:.3g} "
            f"times the training data's largest ({float(trained):.3g}): the model takes each "
            "interval in one step of its scheme, so its predictions there are as coarse as "
            "those steps. For a prediction at other times, give a grid as fine as the "
            "training data's (rollout reads only each trajectory's first state and its times: "
            "repeat the initial state at every time wanted)."]


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


def every_note(metrics: dict) -> list[str]:
    """A note where ``evaluate --every K`` read every K-th sample (``metrics["every"]``): its
    rollouts then step K samples at a time, so their errors hold the scheme's error at that
    step too (a new-user check's model erred 0.187 at K = 16 and 0.034 at the data's step, on
    the same clean data, and was told to train on more trajectories)."""
    every = metrics.get("every", 1)
    if every <= 1:
        return []
    return [f"note: --every {every}: the rollouts step {every} samples at a time, so their "
            "errors above hold the scheme's error at that step as well as the model's; "
            "--every thins the pairs the verdict compares (noise on the states), and the "
            "model's own error at the data's step is that of evaluate without --every."]
