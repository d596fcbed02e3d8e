"""The verdict's check that the structured model predicts the judged data at all
(``rollout_skill``): its rollouts beside the prediction :math:`x(t) = x(0)`.

A field fitted pair by pair can leave a small residual on every held-out pair and still roll
out worse than not moving at all: a new-user check fitted a Van der Pol oscillator (a limit
cycle, which no GENERIC model has) whose residuals passed, and was told "consistent" while
its rollouts erred 1.65 against x(0)'s 1.35. Such a fit proves nothing either way.
"""

from __future__ import annotations

from typing import Any

from ._reference import _finite
from ._verdict_checks import CANNOT_TELL, _reason


def _skill_check(report: dict[str, Any], th) -> list[dict[str, Any]]:
    """``rollout_skill``: the completed rollouts' mean relative L2 over that of predicting
    ``x(t) = x(0)`` on the same trajectories (an offset cancels: both have the same
    denominators); none where either is unknown. ``th``: the verdict's ``Thresholds``."""
    model = _finite(report.get("rollout_error_mean_completed"))
    base = _finite(report.get("constant_prediction_error_mean_completed"))
    if model is None or base is None or base <= 0.0:
        return []
    value = model / base
    passed = value <= th.rollout_skill
    note = (f"the structured model's completed rollouts err by {value:.2g} of what predicting "
            "x(t) = x(0) errs on the same trajectories" + ("" if passed else
            ": it does not predict these data, so that its residuals fit them says nothing "
            "of GENERIC (a system such a structure cannot represent, or a model short of "
            "training or of data); train longer or on more trajectories, and compare its "
            "rollouts with the data (`metriplex rollout`)"))
    return [_reason("rollout_skill", value, th.rollout_skill, passed, CANNOT_TELL, note)]
