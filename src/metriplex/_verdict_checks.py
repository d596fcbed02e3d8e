"""The checks of :func:`metriplex.verdict.verdict`, each a ``reasons`` entry.

What each check means, and its limit, is documented in the docstring of
:mod:`metriplex.verdict` (the table there); this module builds the entries in that table's
order: the soundness of the evidence (:func:`_soundness_checks`), the residual comparison
(:func:`_residual_checks`) and whether the fitted model is GENERIC
(:func:`_structure_checks`). ``th`` is the verdict's :class:`metriplex.verdict.Thresholds`.
The outcome names live here and are public from :mod:`metriplex.verdict`.
"""

from __future__ import annotations

from typing import Any

from ._fit_loop import TIME_BUDGET, ending
from ._reference import _finite

CONSISTENT = "consistent"
NOT_CONSISTENT = "not consistent"
CANNOT_TELL = "cannot tell"


#: The checks whose failure leaves the evidence unsound (cannot tell whatever else fails), and
#: those that are symptoms of a misfit as much as a lack of evidence (verdict's ``_outcome``).
_EVIDENCE = {"held_out_pairs", "training_converged", "reference_residual", "training_range",
             "training_coverage", "training_roughness", "training_pairs",
             "training_trajectories"}
_SYMPTOMS = {"rollout_failures", "step_sensitivity"}


#: What a NOT-consistent statement adds: the two common causes, a model fitted to other data
#: (a user's test set from other parameters) and, on data from a real system, a variable
#: missing (a damped oscillator recorded in (q, p) alone is not GENERIC in those variables).
MISSING_VARIABLE = ("If the model was trained on other data than these (another system, other "
                    "parameters), train on these. Otherwise, a system that loses energy to, or "
                    "gains it from, something outside the data (heat in a medium, a drive) has "
                    "no GENERIC model in these variables: add the variable that takes it (an "
                    "entropy, a temperature, a bath's energy), if it was recorded.")


#: The checks that fail where a learned S leaves the split of the motion open, and what a
#: "cannot tell" then adds: GENERIC data with nothing given got the same failed checks as
#: data that are not GENERIC (found by a new-user check of the verdict).
_SPLIT_CHECKS = {"degeneracy_L_gradS", "jacobi", "entropy_production", "reversible_share"}
UNIDENTIFIED_SPLIT = ("With S learned, trajectories alone do not fix how the motion splits "
                      "into L grad E and M grad S (any flow that conserves the learned E can "
                      "be written as L grad E), so such checks fail on GENERIC data too: give "
                      "what is known, such as the entropy variables (--entropy sum:I,J), "
                      "--poisson zero for one with no reversible motion, or, for one that "
                      "conserves its energy and has no entropy, --entropy zero --friction zero.")


#: What a "cannot tell" adds where the learned L failed the Jacobi check (three of seven
#: learned L of the zoo): the means to ask "is it GENERIC?". Only means measured to work are
#: named: on oscillator-family the Jacobi penalty (--jacobi exact, weight 1 and 100) left the
#: residual at 0.52 and 0.45 (docs/zoo.md, *The verdict across systems*).
NOT_POISSON = ("The learned L is not a Poisson bivector there; a network's L trains with no "
               "Jacobi penalty by default, and the penalty (--jacobi exact) need not bring it "
               "under the limit. Give L where it is known (--poisson canonical:K or "
               "file:L.npy); where L is linear in the state, --poisson lie-poisson (trained "
               "with the exact penalty by default); with "
               "three variables, --poisson casimir3 builds it Poisson by construction; a "
               "known L that depends on the state (e.g. spins' cross products) in Python, "
               "metriplex.KnownPoisson(fn) in the model given to metriplex.fit (not saved "
               "to a model file).")


#: What a NOT-consistent statement adds first where S is given and the observed data decrease
#: it: the flaw is in the entropy given, not a variable missing (found by a check of the verdict
#: on data whose entropy's sign was flipped).
GIVEN_ENTROPY_FALLS = ("The entropy given (--entropy sum:...) decreases along the observed data: "
                       "check its sign, and that it is an entropy of this system.")


def _reason(name, value, threshold, passed, effect, note) -> dict[str, Any]:
    return {"name": name, "value": value, "threshold": threshold, "passed": passed,
            "effect": effect, "note": note}


def _fmt(v) -> str:
    """A check's value as the statements write it: JSON's words, whole numbers, 2 digits."""
    if v is None or isinstance(v, bool):
        return {None: "null", True: "true", False: "false"}[v]
    return str(v) if isinstance(v, int) else f"{v:.2g}"


def _soundness_checks(report: dict[str, Any], trajectories: int, converged: bool | None,
                      stopped: str | None, th, held_out: int = 0,
                      fraction: float = 0.2) -> list[dict[str, Any]]:
    """``held_out_pairs``, ``rollout_failures``, ``training_converged`` and, where ``report``
    measured it, ``step_sensitivity``: is the evidence sound? ``held_out``: the number of pairs
    that the black-box reference did not train on, where both models are compared;
    ``fraction``: the share of the trajectories it holds out."""
    enough = held_out >= th.held_out_pairs
    if enough:
        note = (f"{held_out} pairs held out from the reference's training, on which both "
                "models are compared")
    elif fraction == 0:
        note = ("the reference holds out nothing (validation fraction 0), so the residuals "
                "would be compared where it trained; hold out a fraction of the trajectories")
    else:
        note = (f"only {held_out} pairs are held out from the reference's training "
                f"({trajectories} trajectories in the data; a share of {fraction:g} of them, or "
                "of a single one's samples, is held out): too little data to compare residuals "
                "on; give more or longer trajectories")
    reasons = [_reason("held_out_pairs", held_out, th.held_out_pairs, enough, CANNOT_TELL,
                       note)]
    k = int(report.get("trajectories", trajectories))
    n_failed = int(report.get("rollout_failures", 0))
    reasons.append(_reason(
        "rollout_failures", n_failed, 0, n_failed == 0, CANNOT_TELL,
        f"{n_failed} of {k} rollouts of the structured model failed (blew up, or an implicit "
        "step did not converge): its figures along rollouts are incomplete; find why with "
        "`metriplex rollout` (try --solver newton or a smaller time step), or retrain"
        if n_failed else f"all {k} rollouts of the structured model completed"))
    if converged is None:
        conv_note, conv_pass = "how training ended is not known (no training history)", None
    elif converged:
        conv_note, conv_pass = f"training converged ({stopped or 'on a plateau'})", True
    else:
        how = stopped or "stopped before a plateau"
        conv_note, conv_pass = (f"training did not converge ({how}): more training may "
                                "still improve the fit; train longer (" + (
            "--resume with a larger --max-minutes: the budget counts the time already "
            "trained; it goes on with the training cut, then any left of --repeats)"
            if ending(how) == TIME_BUDGET else "--steps, or --resume)")), False
    reasons.append(_reason("training_converged", converged, True, conv_pass, CANNOT_TELL,
                           conv_note))
    sens = report.get("step_sensitivity", "absent")
    if sens != "absent":
        sens = _finite(sens)
        if sens is None:
            sens_pass, sens_note = None, ("not measured: " + report.get("null_reasons", {}).get(
                "step_sensitivity", "no rollout completed"))
        else:
            sens_pass = sens <= th.step_sensitivity
            sens_note = (f"refining the time step 4x changes {_fmt(sens)} of the structured "
                         "model's predicted motion" + (
                             "" if sens_pass else ": its predictions hold only for its scheme "
                             "at the data's step (a field fitted to that scheme, a step coarse "
                             "for the data, or a learned field wild between the samples), so it "
                             "is not a model of dx/dt there; if `train` noted coarse steps, "
                             "sample more finely (or train with --scheme hermite where it did "
                             "not), else train " + ("on more trajectories" if converged
                                                    else "longer or on more trajectories")
                             + _every_note(report.get("every", 1))))
        reasons.append(_reason("step_sensitivity", sens, th.step_sensitivity, sens_pass,
                               CANNOT_TELL, sens_note))
    return reasons


def _every_note(every: int) -> str:
    """What the step check's advice adds where evaluate read every ``every``-th sample."""
    if every <= 1:
        return ""
    return (f"; here the rollouts step {every} samples at a time (evaluate --every {every}), "
            "so first try a smaller --every")


def _residual_checks(rel_gen: float | None, rel_box: float | None, box_note: str,
                     th, correlation: float | None = None,
                     ) -> tuple[list[dict[str, Any]], float | None]:
    """``(reasons, ratio)``: the ``reference_residual`` check (does the black box fit, so that
    a comparison can blame anyone?), the ``reference_residual_correlation`` check (is what it
    leaves noise, given its residuals' serial ``correlation`` along the held-out trajectories?)
    and the ``residual_ratio`` check of the structured model's relative residual ``rel_gen``
    against the floor set by the black box's ``rel_box``."""
    fits_alone = rel_gen is not None and rel_gen <= th.tolerance
    if fits_alone:
        ref_pass, ref_note = None, (
            f"not needed: the structured model's own relative residual "
            f"{_fmt(rel_gen)} is within the tolerance {th.tolerance:g}")
    elif rel_box is None:
        ref_pass, ref_note = False, (
            "the unconstrained reference could not be trained (non-finite residual"
            f"{box_note}); raise --verdict-steps or check the data")
    else:
        ref_pass = rel_box <= th.reference_residual
        noisy = correlation is not None and correlation <= NOISE_SIGNATURE
        ref_note = (f"the unconstrained reference leaves {_fmt(rel_box)} of the observed rates "
                    f"unexplained{box_note}" + (
                        "" if ref_pass else ": it fits the held-out trajectories badly, so a "
                        "residual comparison can blame neither the structure nor the data" + (
                            f"; its residuals alternate from one pair to the next (lag-one "
                            f"correlation {_fmt(correlation)}), the signature of noise on the "
                            "recorded states: evaluate on every K-th sample (metriplex "
                            "evaluate --every K: the steps' rates then rise above the noise), "
                            "the largest K, doubling from 2, that keeps step_sensitivity under "
                            "its limit (README, Noisy data)" if noisy else
                            " (too few trajectories to generalise from, noise, a coarse time "
                            "step, or too short a reference training: raise --verdict-steps)")))
    reference = _reason("reference_residual", rel_box, th.reference_residual, ref_pass,
                        CANNOT_TELL, ref_note)
    floor, far = max(rel_box if rel_box is not None else 0.0, th.tolerance), \
        _far_beyond(rel_gen, rel_box, th)
    ratio = None if rel_gen is None else rel_gen / floor
    if ratio is None:
        ratio_pass, ratio_note = False, (
            "the structured model's residual on the held-out pairs is not finite")
    elif ref_pass is False:
        ratio_pass, ratio_note = None, "not judged: the reference fits badly"
    else:
        ratio_pass = ratio <= th.residual_ratio and not far
        ratio_note = (f"the structured model leaves {_fmt(rel_gen)} of the held-out rates "
                      f"unexplained, {_fmt(ratio)}x the floor (the reference's {_fmt(rel_box)}, "
                      f"or the tolerance {th.tolerance:g} if larger)" + (
                          f", and {_fmt(rel_gen / rel_box)}x the reference's own: beyond "
                          f"{th.far_residual:g} of the rates, more than {th.far_ratio:g}x an "
                          "unconstrained field of the same capacity is no training budget's "
                          "difference" if far else ""))
    compared = _reason("residual_ratio", ratio, th.residual_ratio, ratio_pass,
                       NOT_CONSISTENT if ratio is not None else CANNOT_TELL, ratio_note)
    # The reference's residual is a floor only where it is noise: a part correlated from pair
    # to pair is dynamics neither model has (a drive, a variable missing), which a structured
    # model that leaves as much would hide (both 0.12, "consistent" before). It weakens only a
    # "consistent". Where the structured model leaves less, the weaker reference is named
    # first if that fits (0.037 against 0.047), the input if both miss much (0.23 vs 0.48).
    if ratio_pass is False:
        noise_pass, noise_note = None, (
            "not needed: the structured model leaves more than the residual ratio allows")
    elif fits_alone or rel_box is None or rel_box <= th.tolerance or correlation is None:
        noise_pass, noise_note = None, (
            "not needed: " + ("the structured model is within the tolerance" if fits_alone
                              else "the reference's residual is within the tolerance"
                              if rel_box is not None and rel_box <= th.tolerance
                              else "too few neighbouring held-out pairs"
                              if correlation is None and rel_box is not None
                              else "no reference residual"))
    else:
        noise_pass = correlation <= th.residual_correlation
        weaker = ("the reference is the weaker fit (too few trajectories for it to generalise, "
                  "or too short a training: raise --verdict-steps)")
        both = "both miss an input, a parameter that changes in time or a missing variable"
        noise_note = (f"the {_fmt(rel_box)} of the rates that the reference leaves unexplained "
                      f"correlates from one pair to the next by {_fmt(correlation)} (noise on "
                      "the states gives about -0.5)" + (
                          "" if noise_pass else ": it is dynamics that the reference misses, "
                          "not noise" + (
                              f"; the structured model leaves less ({_fmt(rel_gen)}): " + (
                                  f"{weaker}, or {both}" if rel_gen <= 3 * th.tolerance else
                                  f"{both}, or {weaker}")
                              if rel_gen is not None and rel_gen < rel_box else
                              ": an input or a parameter that changes in time, a variable "
                              "missing from the data, or too few trajectories for the "
                              "reference to generalise; a structured model that leaves as "
                              "much may miss it too")))
    noise = _reason("reference_residual_correlation", correlation, th.residual_correlation,
                    noise_pass, CANNOT_TELL, noise_note)
    return [reference, noise, compared], ratio


#: A lag-one correlation of the reference's residuals at or below this is noise on the states
#: (white noise on the states gives -0.5 for the rates between them).
NOISE_SIGNATURE = -0.3

#: Where the friction drives less than this share of the standardised motion and S is learned
#: (or zero), the flow is L grad E alone: GENERIC with S constant, whatever the learned S and M.
INERT_FRICTION = 1e-6


def _far_beyond(rel_gen: float | None, rel_box: float | None, th) -> bool:
    """Whether the structured model leaves more than ``th.far_residual`` of the rates and more
    than ``th.far_ratio`` times the reference's residual: under the tolerance's floor a clean
    reference hid a damped oscillator fitted as conservative (5.2 % against 0.2 %, ratio 1.7
    to the floor: "consistent"); beside failed rollouts such a gap is the misfit itself."""
    return (rel_gen is not None and rel_box is not None and rel_box > 0
            and rel_gen > th.far_residual and rel_gen > th.far_ratio * rel_box)


def _temperature_check(sr: dict[str, Any], th: Any, why_null: dict[str, str]) -> dict[str, Any]:
    """``temperatures``: the fraction of the data's (state, entropy variable) pairs with a
    negative learned temperature; with L = 0, where E's sign is free, of the states whose
    temperatures have both signs."""
    cold = sr["temperature_negative_fraction"]
    if cold is None:
        return _reason("temperatures", None, th.negative_temperatures, None, CANNOT_TELL,
                       why_null.get("temperature_negative_fraction", ""))
    if (sr.get("identified") or {}).get("temperatures") == "ratios":
        mixed = sr["temperature_mixed_fraction"]
        return _reason(
            "temperatures", mixed, th.negative_temperatures, mixed <= th.negative_temperatures,
            CANNOT_TELL, "with L = 0 the sign of E is free (-E gives the same flow): the "
            "fraction of the data's states whose temperatures dE/ds_i have both signs, which "
            "no sign of E gives" + (": there the learned E is not the energy up to its gauge"
                                    if mixed > th.negative_temperatures else ""))
    return _reason(
        "temperatures", cold, th.negative_temperatures, cold <= th.negative_temperatures,
        CANNOT_TELL, f"fraction of the data's states and entropy variables where the learned "
        f"temperature dE/ds_i is negative (least {sr['temperature_min']:.3g})"
        + (": entropy production feeds the motion, which no physical system does"
           if cold > th.negative_temperatures else ""))


def _structure_checks(sr: dict[str, Any], report: dict[str, Any], th, *,
                      entropy_free: bool = False) -> list[dict[str, Any]]:
    """Is the fitted model GENERIC? The degeneracy, Jacobi, PSD and antisymmetry checks on
    ``sr`` (:func:`metriplex.diagnostics.structure_residuals` in standardised coordinates:
    unit-free) and the entropy production along the rollouts of ``report``. With
    ``entropy_free`` (S learned or zero, not given as data) and a friction that drives none
    of the motion (:data:`INERT_FRICTION`), the checks on S and M do not apply: the same flow
    is GENERIC with S constant (a conservative pendulum was 'cannot tell' for the
    degeneracy of a friction that never acts)."""
    reasons = []
    why_null = sr["null_reasons"]
    for name, key, what in (
            ("degeneracy_L_gradS", "degeneracy_L_gradS_relative", "|L grad S|/(|L||grad S|)"),
            ("degeneracy_M_gradE", "degeneracy_M_gradE_relative", "|M grad E|/(|M||grad E|)"),
            ("jacobi", "jacobi_residual_to_L",
             "Jacobi residual |J|/(3 max(|T|, |L|^2)), T = (dL) L")):
        v = sr[key]
        if v is None:
            reasons.append(_reason(name, None, th.jacobi if name == "jacobi" else th.degeneracy,
                                   True, CANNOT_TELL, why_null.get(key, "")))
            continue
        v = _finite(v)
        limit = th.jacobi if name == "jacobi" else th.degeneracy
        ok = v is not None and v <= limit
        reasons.append(_reason(name, v, limit, ok, CANNOT_TELL,
                               f"{what} at the data's states, standardised: "
                               + ("the learned model is not GENERIC there, so its fit says "
                                  "nothing about GENERIC" if not ok else "within the limit")))
    frac = _finite(report.get("entropy_production_negative_fraction"))
    if frac is None:
        ent_pass, ent_note = None, ("not measured: " + report.get("null_reasons", {}).get(
            "entropy_production_negative_fraction", "no rollout ran two steps"))
    else:
        ent_pass = frac <= th.entropy_production
        n_failed, k = int(report.get("rollout_failures", 0)), report.get("trajectories")
        ent_note = ("fraction of the states along the structured model's rollouts where its own "
                    "flow decreases its entropy"
                    + ("" if not n_failed else f" (up to where they failed: {n_failed} of {k} "
                       "failed, so only the states before the failures are counted)")
                    + ("" if ent_pass else ": a second-law violation of the fitted model"))
    reasons.append(_reason("entropy_production", frac, th.entropy_production, ent_pass,
                           CANNOT_TELL, ent_note))
    rel = sr["friction_min_eigenvalue_relative"]
    neg = None if rel is None else max(0.0, -rel)
    reasons.append(_reason("friction_psd", neg, th.rounding,
                           neg is not None and neg <= th.rounding, CANNOT_TELL,
                           "most negative eigenvalue of M relative to its largest (M must be "
                           "positive semi-definite)"))
    asym = _finite(sr["poisson_antisymmetry_relative"])
    reasons.append(_reason("poisson_antisymmetry", asym, th.rounding,
                           asym is not None and asym <= th.rounding, CANNOT_TELL,
                           "|L + L^T|/|L| (L must be antisymmetric)"))
    reasons.append(_temperature_check(sr, th, why_null))
    share = sr.get("reversible_share")
    reasons.append(_reason(
        "reversible_share", share, th.reversible_share,
        None if share is None else share >= th.reversible_share, CANNOT_TELL,
        why_null.get("reversible_share", "") if share is None else
        "share of the motion at the data's states that L grad E drives (the rest is M grad S)"
        + (": friction carries the motion, which any flow whose entropy grows admits, so the "
           "fit does not identify E" if share < th.reversible_share else "")))
    if _reversible_only(sr, entropy_free):
        inert = (f"not needed: the friction drives none of the motion (L grad E drives "
                 f"{share:.9g} of it), so the flow is L grad E alone, GENERIC with S constant; "
                 "the learned S and M play no part")
        reasons = [_reason(r["name"], None, r["threshold"], None, CANNOT_TELL, inert)
                   if r["name"] in _ENTROPY_AND_FRICTION else r for r in reasons]
    return reasons


#: What a "consistent" adds where S is learned and the friction drives none of the motion
#: (:func:`_reversible_only`): a damped system recorded with its heat bath was fitted by L grad
#: E alone, "consistent" with nothing said of its dissipation (a new-user check, audit 10).
REVERSIBLE_ONLY = ("The fit is reversible: L grad E drives all of the motion and the learned "
                   "friction none, which any flow that conserves the learned E admits (a damped "
                   "system with its heat bath recorded, too), so it identifies neither "
                   "dissipation nor an entropy. Where the data dissipate, give what is known "
                   "(the entropy variables, --entropy sum:I,J; --poisson zero where nothing "
                   "moves reversibly) to learn the split.")


def _reversible_only(sr: dict[str, Any], entropy_free: bool) -> bool:
    """Whether S is learned (or zero) and the friction drives none of the motion (share of
    L grad E at least ``1 - INERT_FRICTION``): the flow is then L grad E alone."""
    share = sr.get("reversible_share")
    return entropy_free and share is not None and share >= 1.0 - INERT_FRICTION


#: The structure checks on S and M, which a friction that never acts makes moot.
_ENTROPY_AND_FRICTION = ("degeneracy_L_gradS", "degeneracy_M_gradE", "entropy_production",
                         "temperatures")


def _said(r: dict[str, Any]) -> str:
    """One check of the verdict in words: ``name = value <= limit (note)``, the comparison
    on the side the value lies (a limit is a maximum or, as for held_out_pairs, a minimum);
    a maximum failed by another rule that its note gives: ``within its limit but failed``."""
    v, lim, failed = r["value"], r["threshold"], r["passed"] is False
    above = isinstance(v, (int, float)) and isinstance(lim, (int, float)) and v > lim
    if failed and not above and r.get("effect") == NOT_CONSISTENT and isinstance(v, float):
        return f"{r['name']} = {v:.3g}, within its limit {_fmt(lim)} but failed ({r['note']})"
    cmp = (">" if above else "<") if failed else (">=" if above else "<=")
    said = "" if lim is None or isinstance(lim, bool) else f" {cmp} {_fmt(lim)}"
    value = _fmt(v)
    if said and isinstance(v, float) and value == _fmt(lim) and v != lim:
        value = f"{v:.4g}"  # not "0.1 > 0.1" for 0.1006 against 0.1
    return f"{r['name']} = {value}{said} ({r['note']})"
