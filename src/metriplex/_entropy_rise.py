"""The learned entropy along a model's rollouts, in :func:`metriplex.evaluate`'s report: how
much more of it they make than the data show (``entropy_rise_over_data_spread``,
``entropy_rise_over_data_rise``), and how far a step of it may fall by rounding alone
(``entropy_step_rounding``)."""

from __future__ import annotations

from typing import Any

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


#: The least rise of the learned entropy along the data, on average over the trajectories and in
#: units of its range over the data's states, against which a rollout's rise is compared
#: (``entropy_rise_over_data_rise``): below it the data barely raise S (a reversible fit).
LEAST_DATA_RISE = 1e-3


def entropy_rise_ratio(S: np.ndarray, S_data: np.ndarray, lengths: np.ndarray,
                       failed: np.ndarray, null_reasons: dict[str, str]) -> float | None:
    """How many times as much the learned entropy rises along the completed rollouts as along
    the data over the same steps (sums over those rollouts; the arguments as
    :func:`entropy_rise`): 1 for a model whose entropy tracks the data's. Unlike
    ``entropy_rise_over_data_spread`` it does not shrink where S spreads across the
    trajectories far more than along each: a new-user check's brake, at 290-330 K from one
    trajectory to the next, rose 40 times less along each than that spread, and a model making
    4.5-6 times the data's entropy read 0.066 there. ``None``, with the reason in
    ``null_reasons``, where the data raise S by less than :data:`LEAST_DATA_RISE` of its
    range or no rollout completed two steps."""
    key = "entropy_rise_over_data_rise"
    data = np.concatenate([S_data[k, :T] for k, T in enumerate(lengths)])
    spread = float(np.nanmax(data) - np.nanmin(data)) if np.isfinite(data).any() else 0.0
    rises = [(_rise(S[k], T), _rise(S_data[k], T), _rise_noise(S_data[k], T))
             for k, T in enumerate(lengths) if failed[k] < 0 and T >= 2]
    rises = [r for r in rises if all(np.isfinite(r))]
    along = sum(b for _, b, _ in rises)
    if not rises:
        null_reasons[key] = "no rollout completed two steps with a finite entropy"
    elif not along > LEAST_DATA_RISE * spread * len(rises):
        null_reasons[key] = (f"the data raise the learned entropy by less than "
                             f"{LEAST_DATA_RISE:g} of its range over their states")
    elif not along > 3.0 * np.sqrt(sum(n**2 for _, _, n in rises)):
        null_reasons[key] = "the data's rise of the learned entropy is within the noise on it"
    else:
        return sum(a for a, _, _ in rises) / along
    return None


def _rise(S: np.ndarray, T: int) -> float:
    """The rise of ``S`` over its first ``T`` values: the mean of their last tenth less that of
    their first (one value each at least), so that noise on single states weighs less."""
    k = max(1, T // 10)
    return float(np.mean(S[T - k:T]) - np.mean(S[:k]))


def _rise_noise(S: np.ndarray, T: int) -> float:
    """The standard deviation that noise on the values gives :func:`_rise`, the noise taken
    from their second differences (0 with fewer than four values)."""
    if T < 4:
        return 0.0
    k = max(1, T // 10)
    return float(np.std(np.diff(S[:T], 2)) / np.sqrt(6.0) * np.sqrt(2.0 / k))


#: An entropy step along a rollout counts as a decrease only where it falls by more than this
#: many rounding units of the largest |S| along the rollout, in the model's precision.
ENTROPY_ROUNDING_UNITS = 16


def entropy_step_rounding(S: np.ndarray, dtype: Any) -> float:
    """How far an entropy step along a rollout, ``S`` the entropy at its states, may fall by
    rounding alone: :data:`ENTROPY_ROUNDING_UNITS` units of the largest ``|S|`` in ``dtype``
    (the model's precision, in which the states and ``S`` were computed), and at least
    ``1e-12 max(1, |S|)``. Where the entropy production vanishes (at an equilibrium) a float32
    rollout's entropy steps are rounding of about one unit either way, not a decrease."""
    finite = np.abs(np.asarray(S, dtype=np.float64))
    finite = finite[np.isfinite(finite)]
    top = float(finite.max()) if finite.size else 0.0
    return max(ENTROPY_ROUNDING_UNITS * float(np.finfo(dtype).eps) * top,
               1e-12 * max(1.0, top))
