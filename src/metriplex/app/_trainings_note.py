"""What train's final line says of the trainings a run repeated (``--repeats``): each one's
held-out score, the one kept, and, where those from different initialisations did alike, that
the start is not what limits them."""

from __future__ import annotations

import dataclasses

from .._fit_loop import TIME_BUDGET, ending
from ._repeats import GOOD_SCORE, Outcome


def trainings_note(header: dict) -> str:
    """The words train's final line adds where more than one training ran, from the run's
    ``config.json`` (``header``; its ``trainings`` and ``kept_training``); else ``""``."""
    trainings = header.get("trainings") or []
    if len(trainings) < 2:
        return ""
    scores = ", ".join("diverged" if o.get("diverged") else (
        "not judged" if o.get("score") is None else f"{o['score']:.3g}")
        + (f" ({o['failures']} failed)" if o.get("failures") else "")
        + (f" [{o['change']}]" if o.get("change") else "") for o in trainings)
    kept = header.get("kept_training", 0)
    change = trainings[kept].get("change") if kept < len(trainings) else None
    good = (header.get("decided") or {}).get("good_score") or GOOD_SCORE
    alike = _alike_note(trainings, good)
    cut = search_cut_short(header)
    if cut:  # said on stderr only, the final line read "converged" (new-user check 29)
        left = ((header.get("decided") or {}).get("repeats") or 0) - len(trainings)
        alike = (f"; {cut}: --resume with a larger --max-minutes goes on with training "
                 f"{len(trainings)}" + (f", then the {left} left of --repeats" if left > 0
                                        else ""))
    elif not alike and not any(_good(o, good) for o in trainings):
        # A new-user check's four scores, 0.0343, 0.0212, 0.035, 0.0207, were read as good.
        alike = (f"; none scored under {good:.3g}, the score at which training stops "
                 "repeating: the one kept is the best of them, not judged good")
    return (f"kept training {kept + 1} of {len(trainings)}"
            + (f", with {change}" if change else "") + " "
            f"(their held-out scores during training: the error over the rollout check's "
            f"windows, in units of the data's spread, not the relative L2 below: {scores})"
            + alike)


def search_cut_short(header: dict) -> str:
    """Why the run's trainings are no finished search, from its ``config.json`` (``header``):
    where none was judged good and the time budget ended the last before it converged while
    an earlier one is kept; else ``""``. The verdict then reads training as not converged: a
    new-user check's gantry crane, exactly GENERIC, was "NOT consistent" at a residual ratio
    of 2.1 with its kept training 2 of 3 at 0.078."""
    trainings = header.get("trainings") or []
    kept = header.get("kept_training", 0)
    good = (header.get("decided") or {}).get("good_score") or GOOD_SCORE
    if (len(trainings) < 2 or kept >= len(trainings) - 1
            or ending(str(trainings[-1].get("stopped", ""))) != TIME_BUDGET
            or any(_good(o, good) for o in trainings)):
        return ""
    score = Outcome.from_json(trainings[kept]).score
    return (f"{TIME_BUDGET}: the search for a good training was cut short (it ended training "
            f"{len(trainings)} before it converged), none judged good at <= {good:.3g}; the one "
            f"kept, training {kept + 1}, scored {score:.3g}")


def _good(outcome: dict, good: float) -> bool:
    """Whether a training's outcome (``config.json``'s) scored good at ``good`` (its rollouts;
    one that broke M grad E = 0 also trains again, but these notes speak of the scores)."""
    return dataclasses.replace(Outcome.from_json(outcome), degenerate=None).good(good)


#: Trainings from other initialisations whose held-out scores lie within this factor of each
#: other did alike: where all are poor, the start is not what limits them. A new-user check's
#: two coupled spins (32 trajectories): 0.255, 0.304, 0.258, and one training met the bar
#: with 128 trajectories; the oscillator network's 0.207, 0.203, 0.175, whose energy lacked a
#: form (``--quadratic`` met it); the pendulum's seeds, which another start did help: factors
#: of 7 and 10 (docs/zoo.md).
ALIKE = 1.5


def _alike_note(trainings: list[dict], good: float = GOOD_SCORE) -> str:
    """Where two or more trainings from different initialisations (no changed settings) all
    converged and were judged, none failing, with scores within :data:`ALIKE` of each other,
    and no training of the run was good (at ``good``): that the limit is the data, the
    model's form, or data not GENERIC in their variables (a new-user check's hidden heat bath,
    drive and noise: each blamed on the first two), not the start."""
    plain = [o for o in trainings if not o.get("change")]
    scores = [o.get("score") for o in plain]
    # A training cut short by the time budget is no like for like (a new-user check: one
    # converged training and one cut at step 12 600 "did alike").
    if (len(plain) < 2 or any(s is None or o.get("failures") or o.get("diverged")
                              or o.get("converged") is False for s, o in zip(scores, plain))
            or max(scores) > ALIKE * min(scores)
            # none good, of another form either (a new-user check's chain: 0.045, 0.056,
            # 0.042, then 0.0067 with --quadratic): the note would blame what was solved
            or any(_good(o, good) for o in trainings)):
        return ""
    return (f"; the {len(plain)} trainings from different initialisations did alike (scores "
            f"within {max(scores) / min(scores):.3g}x of each other), so where training starts "
            "is not what limits them: the data (too few trajectories near the states to "
            "predict: give more), what the model can express (give more of the structure you "
            "know), or the data themselves: not GENERIC in these variables (a variable "
            "missing, a drive, noise; `metriplex evaluate` says which)")
