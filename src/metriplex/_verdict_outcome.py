"""The verdict's outcome from its failed checks (:mod:`metriplex.verdict`, *Outcome*), and
what a "not consistent" adds: the laws the observed data break and the variables to blame."""

from __future__ import annotations

from typing import Any

import numpy as np

from ._reference import _finite
from ._verdict_checks import (CANNOT_TELL, CONSISTENT, NOT_CONSISTENT, _EVIDENCE,
                              _SYMPTOMS, _reason)


def _outcome(failed: list[dict[str, Any]], ratio: float | None, converged: bool | None,
             far: bool) -> str:
    """The verdict's outcome from its ``failed`` checks (:mod:`metriplex.verdict`, *Outcome*); ``far``:
    the structured model's residual is far beyond the reference's (``_far_beyond``)."""
    # reference_residual_correlation only weakens a "consistent" (below, with the structure
    # checks): a structured model that leaves much more than the reference is not consistent.
    # Failed rollouts and a step-dependent prediction make a "consistent" unsound, but beside
    # a converged training's residual far beyond the reference's (_far_beyond) they are
    # symptoms of the same misfit, not a lack of evidence (a damped oscillator fitted as
    # conservative: ratio 37, "cannot tell" before).
    # (a misfit that the observed data's laws do not back counts only as no evidence:
    # weigh_misfit)
    misfit = any(r["name"] == "residual_ratio" and r.get("effect") != CANNOT_TELL
                 for r in failed)
    if any(r["name"] == "given_entropy" for r in failed):  # the data break it, not the fit
        outcome = NOT_CONSISTENT
    elif any(r["name"] in _EVIDENCE for r in failed) or (ratio is None):
        outcome = CANNOT_TELL
    elif misfit and ((converged is True and far)
                     or not any(r["name"] in _SYMPTOMS for r in failed)):
        outcome = NOT_CONSISTENT
    elif failed:
        outcome = CANNOT_TELL
    else:
        outcome = CONSISTENT
    return outcome


def _worst_variables(excess: dict[str, float | None] | None) -> list[str]:
    """The variables whose excess residual (the structured model's over the reference's) is
    at least a tenth of the largest, the largest first, at most three: those that the
    structure cannot fit (all three of three named before, the one to blame among them)."""
    if not excess:
        return []
    ranked = sorted(((v, n) for n, v in excess.items() if v is not None and v > 0),
                    reverse=True)
    return [n for v, n in ranked[:3] if v >= 0.1 * ranked[0][0]]


#: Above these the observed data break a law under the learned E and S (:func:`_violations`):
#: the median |dE/dt| along the observed pairs over its largest possible rate, and the share
#: of the pairs along which S falls beyond noise.
ENERGY_RATE, ENTROPY_FALLS = 0.05, 0.1
#: weigh_misfit reads those figures as "no law broken" only where the noise floor subtracted
#: from the energy's changes is below this share of ENERGY_RATE.
NOISE_FLOOR = 0.1


def _violations(observed: dict[str, Any], excess: dict[str, float | None] | None,
                given: bool = False) -> list[str]:
    """What a "not consistent" adds: the laws the observed data break under the learned E and
    S (``observed``: :func:`~metriplex._reference._observed_laws`) and the variables the
    structure cannot fit (``excess``: each one's excess residual)."""
    laws = []
    rate = observed["energy_rate_relative_median"]
    if rate is not None and rate > ENERGY_RATE:
        laws.append(f"first law: the observed flow changes the learned energy (median "
                    f"|dE/dt| = {rate:.2g} of its largest possible rate)")
    falls = observed["entropy_decreasing_fraction"]
    if falls is not None and falls > ENTROPY_FALLS:
        laws.append(f"second law: on {100 * falls:.0f}% of the observed pairs the "
                    f"{'given' if given else 'learned'} entropy decreases")
    worst = _worst_variables(excess)
    if worst:
        laws.append(f"the structure cannot fit the variable{'s' if len(worst) > 1 else ''} "
                    f"{', '.join(worst)}")
    return laws


def _accuracy(report: dict[str, Any]) -> str:
    """What a "consistent" adds of the model's accuracy, which it does not judge (a new-user
    check read "consistent, all 14 checks pass" of rollouts 14 % off), with the median and
    the worst trajectory's error where there are three or more: a mean can be one or two
    trajectories' (a new-user check's rigid body: mean 0.076, median 0.011, the worst 0.50,
    two of eight crossing a separatrix)."""
    err = _finite(report.get("rollout_error_standardised_mean"))
    if err is None:
        return ""
    each = np.asarray(report.get("rollout_error_standardised") or [], dtype=np.float64)
    ids = report.get("trajectory_ids") or list(range(len(each)))
    spread = ""
    if len(each) >= 3 and np.all(np.isfinite(each)) and len(ids) == len(each):
        worst = int(np.argmax(each))
        spread = (f"; over the {len(each)} trajectories, median {np.median(each):.3g}, the "
                  f"worst (trajectory {ids[worst]}) {each[worst]:.3g}")
    return (f" That is the structure, not the accuracy: the rollouts err by {err:.3g} in "
            f"standard deviations (rollout_error_standardised_mean{spread}).")


def _given_entropy_check(observed: dict[str, Any], limit: float, *,
                         given: bool) -> dict[str, Any]:
    """The ``given_entropy`` check: where S is given, the share of the observed pairs that
    decrease it beyond noise (``observed``: :func:`~metriplex._reference._observed_laws`).
    A new-user check's heated oscillator whose bath leaks heat was "consistent" (residual
    ratio 1.9, under its limit by the tolerance) while its given S fell on 62 % of the
    pairs."""
    falls = _finite(observed["entropy_decreasing_fraction"]) if given else None
    return _reason("given_entropy", falls, limit, None if falls is None else falls <= limit,
                   NOT_CONSISTENT,
                   "fraction of the held-out pairs along which the data decrease the given "
                   "entropy by more than noise on the states would: GENERIC data never do"
                   if given else "S is learned: it is whatever entropy fits the data")


def weigh_misfit(reasons: list[dict[str, Any]], observed: dict[str, Any]) -> list[dict[str, Any]]:
    """``reasons`` with a failed ``residual_ratio`` made no evidence against the structure
    (effect "cannot tell", the note says why) where the observed data break neither law under
    the learned E and S (``observed``: :func:`~metriplex._reference._observed_laws`) and the
    noise on the states could not hide a broken one: their flow keeps the learned energy and
    never lowers the entropy, as GENERIC data do, and the misfit can be the training's. A new-user check's gantry crane, exactly GENERIC, with L
    and S given and four converged trainings that fit poorly: "NOT consistent" at 6.6x the
    reference's residual, while its learned E changed along the data at 0.0033 of its largest
    rate and S never fell."""
    rate = _finite(observed.get("energy_rate_relative_median"))
    falls = _finite(observed.get("entropy_decreasing_fraction"))
    floor = _finite(observed.get("energy_noise_floor_median"))
    # Only where noise on the states cannot hide a broken law: with 0.2 % noise a pumped
    # oscillator's energy rate (0.21 clean) read 0.014 (0 at 1 %) beside a residual ratio
    # of 7.3.
    if (rate is None or falls is None or floor is None or rate > ENERGY_RATE
            or falls > ENTROPY_FALLS or floor > NOISE_FLOOR * ENERGY_RATE):
        return reasons
    why = (f"; but along the observed data the learned E changes at only {rate:.2g} of its "
           f"largest rate and S falls on {100 * falls:.0f}% of the pairs, so they break "
           "neither law by the measures of a 'not consistent': however large, the misfit may "
           "be the training's (train again: another --seed, more trajectories, the structure "
           "you know) rather than the structure's")
    return [dict(r, effect=CANNOT_TELL, note=r["note"] + why)
            if r["name"] == "residual_ratio" and r["passed"] is False else r for r in reasons]
