"""The rollout error in standard deviations: part of :func:`metriplex.evaluate`'s report
(``rollout_error_standardised``). The relative L2 error ``|pred - obs| / |obs|`` shrinks with
any offset of a variable (a temperature near 300 K, a position of 1e4), so it is reported
beside one that does not: every variable measured about its mean over the data, in its
standard deviation there."""

from __future__ import annotations

import numpy as np

from .data import state_statistics


def standardised_errors(pred: np.ndarray, obs: np.ndarray, lengths: np.ndarray,
                        x: np.ndarray) -> list[float]:
    r"""Per trajectory, :math:`|D^{-1}(\hat x - x)| / |D^{-1}(x - \bar x)|` over its states,
    with :math:`\bar x` and :math:`D` of the data's states ``x`` as
    :func:`~metriplex.data.state_statistics` gives them (a constant variable in its own units); ``inf`` for a rollout that failed.
    ``pred`` and ``obs``: padded ``(K, T, n)``; ``lengths``: each trajectory's length."""
    mean, d, _ = state_statistics(x)
    out = []
    for k, T in enumerate(lengths):
        p, o = pred[k, :T], obs[k, :T]
        if not np.all(np.isfinite(p)):
            out.append(float("inf"))
            continue
        num = np.linalg.norm((p - o) / d)
        den = np.linalg.norm((o - mean) / d)
        out.append(float(num / max(den, 1e-300)))
    return out


def standardised_error_over_time(pred: np.ndarray, obs: np.ndarray, mean: np.ndarray,
                                 d: np.ndarray) -> np.ndarray:
    r"""One trajectory's standardised error at each time, :math:`|D^{-1}(\hat x(t) - x(t))|`
    over the root mean square of :math:`|D^{-1}(x - \bar x)|` along it (``mean`` and ``d`` as
    :func:`~metriplex.data.state_statistics` gives them): its root mean square over the times is
    the trajectory's :func:`standardised_errors`. Non-finite where the rollout is."""
    den = float(np.sqrt(np.mean(np.sum(((obs - mean) / d) ** 2, axis=-1))))
    with np.errstate(over="ignore", invalid="ignore"):  # blown-up states: inf; failed: NaN
        return np.linalg.norm((pred - obs) / d, axis=-1) / max(den, 1e-300)
