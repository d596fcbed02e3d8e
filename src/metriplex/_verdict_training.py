"""The verdict's checks on the data a model was trained on (:func:`metriplex.verdict.verdict`
with ``trained_on``, the :class:`~metriplex.Units` of the training data): do the judged data
stay where the model was trained (``training_range``, ``training_coverage``), and were the
training data rougher than these (``training_roughness``)? Each makes a misfit no evidence
against the structure, since the black-box reference trains on the judged data themselves.
``th`` is the verdict's :class:`metriplex.verdict.Thresholds`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from ._reference import _finite
from ._verdict_checks import CANNOT_TELL, _fmt, _reason
from .data import roughness

if TYPE_CHECKING:
    from ._units import Units
    from .data import Trajectories


def _training_checks(data, trained_on, rel_gen: float | None, *, misfit: bool | None, th,
                     reference_pairs: int | None = None) -> list[dict[str, Any]]:
    """The ``training_range``, ``training_coverage``, ``training_roughness`` and
    ``training_pairs`` entries (none without ``trained_on``); ``misfit``: the residual ratio
    failed (``None``: it was not judged); ``reference_pairs``: the pairs the reference trained
    on."""
    if trained_on is None:
        return []
    return _range_check(data, trained_on, th) + _coverage_check(
        data, trained_on, ratio_failed=misfit, th=th) + _roughness_check(
        data, trained_on, rel_gen, ratio_failed=misfit, th=th) + _pairs_check(
        trained_on, reference_pairs, ratio_failed=misfit, th=th) + _trajectories_check(
        trained_on, ratio_failed=misfit, th=th)


def _converged_where_misfit(reasons: list[dict[str, Any]],
                           ratio_passed: bool | None) -> list[dict[str, Any]]:
    """``reasons`` with ``training_converged`` not judged where the residual ratio passed, as
    the other training checks: a model that fits the data as well as the reference and is
    GENERIC shows them consistent with GENERIC however its training ended (more training could
    only fit better), while the misfit of one still improving is no evidence against it. A
    new-user check's exactly GENERIC oscillator, its kept training judged good (held-out 0.014)
    and every structure check passing at a residual ratio of 0.072, was "cannot tell" because
    ``--max-minutes`` had cut it."""
    return [{**r, "passed": None, "note": f"{r['note']}; {_unjudged(False)}"}
            if r["name"] == "training_converged" and r["passed"] is False and ratio_passed
            else r for r in reasons]


def _unjudged(ratio_failed: bool | None) -> str:
    """Why a check judged only where the residual ratio failed is not judged: the ratio passed
    (``False``), or was itself not judged (``None``: the reference fits badly; a new-user check
    read "the residual ratio passes" beside the ratio's own "not judged")."""
    return ("not judged: the residual ratio passes" if ratio_failed is False
            else "not judged: nor is the residual ratio (the reference fits badly)")


def _trajectories_check(trained_on, *, ratio_failed: bool | None, th) -> list[dict[str, Any]]:
    """``training_trajectories``, where the number of the model's training trajectories is
    known (``trained_on.trajectories``): a model of one or two trajectories has learned the
    curves of states they visit, which the per-variable range and coverage checks cannot tell
    from the whole box (new-user check 17: one long trajectory of exactly GENERIC data, judged
    on eight others inside its box, "NOT consistent ... add the variable"). Judged only where
    the residual ratio failed."""
    k = trained_on.trajectories
    if k is None:
        return []
    if not ratio_failed:
        passed, note = None, _unjudged(ratio_failed)
    else:
        passed = k >= th.training_trajectories
        note = (f"the model trained on {k} trajector{'y' if k == 1 else 'ies'}" + (
            "" if passed else ": it learned the states along them, and from other initial "
            "states it extrapolates, while the reference trains on these data, so its worse "
            "fit is no evidence against GENERIC; train on more trajectories, from other "
            "initial states, to decide"))
    return [_reason("training_trajectories", k, th.training_trajectories, passed, CANNOT_TELL,
                    note)]


def _pairs_check(trained_on, reference_pairs: int | None, *, ratio_failed: bool | None,
                 th) -> list[dict[str, Any]]:
    """``training_pairs``, where the model's training pairs are known (``trained_on.pairs``):
    their number against the ``reference_pairs`` that the reference trained on, from these
    data. A model fitted to two trajectories, judged beside a field fitted to six of the data
    it is judged on, fits them worse whatever its structure (new-user check 14: exactly
    GENERIC data called not consistent). Judged only where the residual ratio failed."""
    if trained_on.pairs is None or not reference_pairs:
        return []
    value = trained_on.pairs / reference_pairs
    if not ratio_failed:
        passed, note = None, _unjudged(ratio_failed)
    else:
        passed = value >= th.training_pairs
        note = (f"the model trained on {trained_on.pairs} pairs of samples, the reference on "
                f"{reference_pairs} pairs of these data" + ("" if passed else
                ": a structured model fitted to far fewer data than the field it is compared "
                "with need not fit as well, whatever its structure, so its worse fit is no "
                "evidence against GENERIC; train on more trajectories (or on these data) to "
                "decide"))
    return [_reason("training_pairs", value, th.training_pairs, passed, CANNOT_TELL, note)]


#: How far from the training data's mean, in their standard deviations, a state counts as
#: beyond them for ``training_coverage`` (a uniform spread reaches 1.7, a Gaussian one goes
#: beyond 3 at 0.3 % of its states).
BEYOND = 3.0


def beyond_share(data: Trajectories, trained_on: Units) -> tuple[float, str]:
    """The share of ``data``'s states beyond ``BEYOND`` standard deviations of the training
    data's mean (``trained_on``, their :class:`~metriplex.Units`) in some variable, and beyond
    the training data's own extent there where it is known (``Units.low``, ``high``), and the
    variable most often beyond. A damped motion's rare large first swings lie beyond 3
    standard deviations in its training data too (4 % of a new-user check's states): judged
    data that reach no further are no extrapolation."""
    x = np.asarray(data.x, dtype=np.float64)
    shift, scale = np.asarray(trained_on.shift), np.asarray(trained_on.scale)
    z = (x - shift) / scale
    up = down = np.full(len(shift), BEYOND)
    if trained_on.low is not None and trained_on.high is not None:
        up = np.maximum(up, (np.asarray(trained_on.high) - shift) / scale)
        down = np.maximum(down, (shift - np.asarray(trained_on.low)) / scale)
    beyond = np.isfinite(z) & ((z > up) | (-z > down))
    share = float(np.mean(np.any(beyond, axis=1))) if len(x) else 0.0
    return share, data.names[int(np.argmax(np.sum(beyond, axis=0)))]


def _coverage_check(data, trained_on, *, ratio_failed: bool | None, th) -> list[dict[str, Any]]:
    """``training_coverage``: the share of ``data``'s states beyond ``BEYOND`` standard
    deviations of the training data's mean (``trained_on``) in some variable. A model trained
    on few trajectories (one long one, say) misses states that others reach well within
    ``training_range``, and its misfit there is how it extrapolates, while the reference trains
    on these data. Judged only where the residual ratio failed (``ratio_failed``)."""
    share, most = beyond_share(data, trained_on)
    if not ratio_failed:
        passed, note = None, _unjudged(ratio_failed)
    else:
        passed = share <= th.training_coverage
        note = (f"{share:.1%} of these states lie beyond {BEYOND:g} standard deviations of "
                "the training data's mean, and beyond the training data's range, in some "
                "variable" + ("" if passed else
                f" (most often {most}): the model was not trained where these data go, so "
                "its misfit is how it extrapolates, no evidence against GENERIC (the "
                "reference trains on these data); train on trajectories that cover these "
                "states (more of them, from more initial states)"))
    return [_reason("training_coverage", share, th.training_coverage, passed, CANNOT_TELL,
                    note)]


def _range_check(data, trained_on, th) -> list[dict[str, Any]]:
    """``training_range``, where the units of the model's training data (``trained_on``) are
    known: do ``data`` stay where the model was trained? Beyond, its residuals say how it
    extrapolates, while the reference trains on these very data."""
    far, _, var = trained_on.farthest(data.x)
    passed = far <= th.training_range
    note = (f"the data lie within {far:.2g} standard deviations of the training data's mean"
            if passed else
            f"the data reach states the model was never trained on ({data.names[var]} at "
            f"{far:.2g} training standard deviations from its training mean): there the "
            "structured model extrapolates while the reference trains on these data, so a "
            "worse fit is no evidence against GENERIC; evaluate on data within the training "
            "range, or train on these")
    return [_reason("training_range", far, th.training_range, passed, CANNOT_TELL, note)]


def _roughness_check(data, trained_on, rel_gen: float | None, *, ratio_failed: bool | None,
                     th) -> list[dict[str, Any]]:
    """``training_roughness``, where the roughness of the model's training data is known
    (``trained_on.roughness``): were they rougher than ``data`` (noisier, or sampled more
    coarsely), so that a residual beyond the reference's, which trains on these data, is what
    the model could learn rather than what its structure allows? Judged only where the
    residual ratio failed (``ratio_failed``): a model that fits well needs no excuse."""
    rough = trained_on.roughness
    if rough is None:
        return []
    here = roughness(data)
    value = None if not here else _finite(rough / here)
    if not ratio_failed or value is None or rel_gen is None:
        passed, note = None, (
            _unjudged(ratio_failed) if not ratio_failed
            else "not judged: these data's roughness is unknown")
    else:
        passed = not (value > th.training_roughness and rel_gen <= rough)
        note = (f"the training data's rates were {_fmt(rough)} rough (noise gives 1), these "
                f"data's {_fmt(here)}" + ("" if passed else
                f", and the structured model's residual here ({_fmt(rel_gen)}) is within the "
                "training data's roughness: a model learnt from data that noisy (or that "
                "coarsely sampled) need not fit these better, whatever its structure; train on "
                "data as clean as these to decide"))
    return [_reason("training_roughness", value, th.training_roughness, passed, CANNOT_TELL,
                    note)]
