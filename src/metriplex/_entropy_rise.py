"""How much more entropy a model's rollouts make than the data show: part of
:func:`metriplex.evaluate`'s report (``entropy_rise_over_data_spread``)."""

from __future__ import annotations

import numpy as np


def entropy_rise(S: np.ndarray, S_data: np.ndarray, lengths: np.ndarray, failed: np.ndarray,
                 null_reasons: dict[str, str]) -> float | None:
    """The learned entropy's rise along each completed rollout beyond its rise along the data
    over the same steps, averaged over those rollouts, in units of the entropy's
    range over the data's states. ``S`` and ``S_data``: the learned entropy along the rollouts
    and along the data, ``(K, T)``; ``lengths`` and ``failed``: each trajectory's length and
    failed step (-1 where it completed). ``None``, with its reason in ``null_reasons``, where
    the learned entropy is constant over the data's states or no rollout completed two steps
    with a finite entropy."""
    key = "entropy_rise_over_data_spread"
    data = np.concatenate([S_data[k, :T] for k, T in enumerate(lengths)])
    spread = float(np.ptp(data))
    rise = []
    for k, T in enumerate(lengths):
        # a failed rollout (counted in rollout_failures) can reach any state before it fails
        if failed[k] < 0 and T >= 2:
            rise.append(float((S[k, T - 1] - S[k, 0]) - (S_data[k, T - 1] - S_data[k, 0])))
    rise = [r for r in rise if np.isfinite(r)]
    if spread <= 1e-12 * max(1.0, float(np.nanmax(np.abs(data)))):
        null_reasons[key] = "the learned entropy is constant over the data's states"
    elif not rise:
        null_reasons[key] = "no rollout completed two steps with a finite entropy"
    else:
        return float(np.mean(rise)) / spread
    return None
