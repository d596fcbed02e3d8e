"""train's final line: how training ended, and how the held-out rollouts went (beside predicting
no motion, which evaluate prints too)."""

from __future__ import annotations

import math
import statistics
from pathlib import Path
from typing import TYPE_CHECKING

from .._fit_loop import INTERRUPTED, TIME_BUDGET, ending

if TYPE_CHECKING:
    from ..train import History


#: The noise on the evaluated states (``noise_over_spread``, the median over the variables of
#: :func:`metriplex.data.state_noise` over their standard deviation) from which train's final
#: line says that its rollout error includes it.
NOTED_NOISE = 0.005


def against_constant(metrics: dict) -> tuple[str, bool]:
    """The completed rollouts' error beside that of predicting ``x(t) = x(0)`` on the same
    trajectories (also in standard deviations), and whether the model fails to beat it
    (``("", False)`` if none completed)."""
    done = metrics.get("rollout_error_mean_completed")
    base = metrics.get("constant_prediction_error_mean_completed")
    if done is None or base is None:
        return "", False
    if done >= base:
        won, total = _beaten(metrics)
        if 2 * won > total:  # a few trajectories decide the mean (a new-user check: 2 of 6)
            return (f"NO better on average than predicting x(t) = x(0) ({base:.3e}), though "
                    f"better on {won} of the {total} completed rollouts: the mean is decided "
                    f"by the other {total - won}; judge the model on more trajectories"), True
        return (f"NO better than predicting x(t) = x(0) ({base:.3e}): the model does not "
                f"predict these trajectories"), True
    still = metrics.get("constant_prediction_error_standardised_mean")  # None: an old report
    std = "" if still is None else f" ({still:.3e} in standard deviations)"
    return f"predicting x(t) = x(0) gives {base:.3e}{std}", False


def _beaten(metrics: dict) -> tuple[int, int]:
    """On how many of the completed rollouts the model errs less than x(t) = x(0), and of how
    many (``(0, 0)`` where the report lacks the per-trajectory errors: an old report)."""
    errors, still = metrics.get("rollout_error"), metrics.get("constant_prediction_error")
    if not errors or not still or len(errors) != len(still):
        return 0, 0
    done = [(e, c) for e, c in zip(errors, still) if e is not None and math.isfinite(e)
            and c is not None and math.isfinite(c)]
    return sum(e < c for e, c in done), len(done)


def train_summary(history: History, metrics: dict, seconds: float, out: Path, *,
                  first_stage: bool = False, held_stage: bool = False,
                  trainings: str = "") -> str:
    """train's final line: how training ended, and how the held-out rollouts went.
    ``first_stage``: a first stage ran before the main one (``--reversible-first``; with
    ``held_stage``, ``--hold-energy``'s too); their steps are on the lines they printed, and
    ``seconds`` counts all. ``trainings``: what ``--repeats`` did, where it trained more than
    once (:func:`~metriplex.app._trainings_note.trainings_note`)."""
    last = history.step[-1] if history.step else 0
    ended = history.stopped or "completed"
    timed = ending(ended) == TIME_BUDGET
    if timed and first_stage:  # the stage's budget is what the earlier ones left of the run's
        ended = ended.replace(" s)", " s: what the stages and trainings before it left of "
                              "--max-minutes)", 1)
        if last == 0:
            ended += ("; the first stage took the whole budget, so the main stage (the "
                      "friction with it) never trained: allow more time (--max-minutes)")
    more_time = "continue it with --resume and a larger --max-minutes (the whole run counts)"
    if not history.converged and history.best_step == last and last > 0:
        ended += ("; the best model is the last one: not converged, " + (
            "continue it with --resume" if ending(ended) == INTERRUPTED else more_time
            if timed else "allow more --steps"))
    elif timed and not history.converged and last > 0:  # capped, its best model earlier
        ended += f"; not converged: {more_time}"
    # Where --repeats trained from other initialisations already, another --seed is no advice.
    reseed = "other initialisations did no better" if trainings else "try another --seed"
    if history.best_step == 0 and last > 0:
        if first_stage:  # the main stage starts from the first stage's E and L: a trained model
            ended += ("; the main stage's start (the first stage's model with an untrained "
                      "friction) rolled out the held-out trajectories best (kept); if its "
                      f"error below is poor, the first stage can have stalled: {reseed}; "
                      "try --no-reversible-first")
        else:
            ended += ("; NO trained model rolled out the held-out trajectories better than "
                      "the untrained one (kept): either the data do not determine the "
                      "dynamics away from the training trajectories (give more trajectories or "
                      f"more of the structure), or training ended in a poor fit ({reseed})")
    if trainings:  # how the kept one ended: another may have been cut (a new-user check)
        ended = f"the kept training: {ended}; {trainings}"
    early = kept_early(history, first_stage, reseed)
    if early:
        ended += early
    k = metrics.get("trajectories", 0)
    failed = metrics.get("rollout_failures", 0)
    err = metrics.get("rollout_error_mean")
    where = metrics.get("evaluated_on", "")
    if failed:
        rollouts = f"{failed} of {k} rollouts on {where} FAILED (blew up or did not converge)"
        done = metrics.get("rollout_error_mean_completed")
        if done is not None:
            rollouts += f"; error of the {k - failed} completed: {done:.3e}"
    else:
        span = metrics.get("duration_median")
        rollouts = (f"rollout error on {where}: {err:.3e} (relative L2 over each whole "
                    "trajectory" + ("" if span is None else f", each {span:.3g} time units "
                                    "long (median)") + f", mean of {k}")
        std = metrics.get("rollout_error_standardised_mean")
        rollouts += ")" if std is None else (f"; {std:.3e} in standard deviations about the "
                                            "data's mean, which no offset shrinks)")
    noise = metrics.get("noise_over_spread")
    if noise is not None and noise >= NOTED_NOISE:  # audit 10: read as the model's error alone
        rollouts += (f"; against the recorded states, whose noise (about {noise:.1%} of a "
                     "variable's standard deviation over the evaluated trajectories, which "
                     "may differ from the training data's) it includes: `metriplex evaluate` on "
                     "clean data, where there are, tells the model's own error")
    coarse = metrics.get("coarse_steps")
    if coarse is not None:  # a new-user check: 3.5e-3 here, 16x that on a finer grid
        rollouts += (f"; at the data's own steps, coarse for their motion (roughness "
                     f"{coarse:.2g}): at finer steps the model can be far less accurate "
                     "(README, Coarse steps)")
    against, _ = against_constant(metrics)
    if against:
        rollouts += f"; {against}"
    # The seconds are of every training (--repeats) with its stages (audit 10: "both in" read
    # as one training's two stages).
    span = "every training with its stages in" if trainings else None
    steps = f"{last} steps" + ("; every training in" if trainings else " in")
    if first_stage and held_stage:
        steps = (f"{last} steps after the first stage's (L grad E alone) and the held one's "
                 f"(the friction to that energy; above), {span or 'all in'}")
    elif first_stage:
        steps = f"{last} steps after the first stage's (L grad E alone, above), {span or 'both in'}"
    return f"trained {steps} {seconds:.1f} s ({ended}); {rollouts}; run folder: {out}"


def kept_early(history: History, first_stage: bool, reseed: str) -> str:
    """A clause for train's line where the model kept is an early one that the later models
    lost to: kept within the first tenth of the steps, and the later evaluations' held-out
    rollout scores at a median of more than twice its own. Its error can then look fair (a
    model that barely moves stays near the data) while it has hardly learned the dynamics.
    After a first stage, the main stage's early model is the first stage's, trained, plus a
    little friction: the clause says that instead. The scores are read as far as both lists
    go (after a divergence the steps have one more entry than the scores). ``reseed``: the
    advice on the initialisation (a run that trained from others already says so)."""
    best, last = history.best_step, history.step[-1] if history.step else 0
    if not (0 < best <= last / 10) or not history.rollout:
        return ""
    later = [r if math.isfinite(r) else math.inf
             for s, r in zip(history.step, history.rollout) if s > best]
    if not later or not math.isfinite(history.best_rollout) or history.best_rollout <= 0:
        return ""
    median = statistics.median(later)
    if median <= 2.0 * history.best_rollout:
        return ""
    worse = (f"the later ones rolled out the held-out trajectories worse (median score "
             f"{median:.3g} against {history.best_rollout:.3g})")
    if first_stage:
        return (f"; the main stage's model of step {best} of {last} was kept: {worse}, so the "
                "friction added to the first stage's model may be barely trained")
    return (f"; the model of step {best} of {last} was kept: {worse}, so it may be barely "
            "trained and its error below says little about the dynamics: the data may not "
            "determine them away from the training trajectories (give more trajectories or "
            f"more of the structure), or later training degraded it ({reseed})")


def evaluated_noise_note(metrics: dict) -> list[str]:
    """evaluate's note where the states it judges carry noise (``noise_over_spread`` at least
    :data:`NOTED_NOISE`), as train's final line says of its held-out error: the rollout
    errors are against noisy states (a new-user check: 0.063 printed at 5 % noise, 0.034
    against the clean truth from the same initial states)."""
    noise = metrics.get("noise_over_spread")
    if noise is None or noise < NOTED_NOISE:
        return []
    return [f"note: the evaluated states carry noise of about {noise:.1%} of a variable's "
            "standard deviation over them (noise_over_spread, the median over the "
            "variables): the "
            "rollout errors above are against them, noise included; evaluated on clean data "
            "from the same initial states, where there are, they tell the model's own error."]
