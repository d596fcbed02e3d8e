"""How rough the observed rates of trajectory data are (:func:`roughness`), the spacing of
training pairs that makes them least rough (:func:`pair_spacing`), and the noise on the
recorded states (:func:`state_noise`) and the range of a quantity along a trajectory beyond
it (:func:`range_beyond_noise`); public from :mod:`metriplex.data`."""

from __future__ import annotations

from typing import Protocol, Sequence

import numpy as np


class _Samples(Protocol):
    """What is read here of a :class:`~metriplex.data.Trajectories` (which imports this
    module, so it is not imported here)."""

    trajectory: np.ndarray
    t: np.ndarray
    x: np.ndarray

    def lengths(self) -> np.ndarray: ...


def roughness(data: _Samples, scale: np.ndarray | None = None, spacing: int = 1,
              rows: int = 1 << 16) -> float | None:
    r"""How much of the data's observed rates changes from one pair to the next as noise does:
    with :math:`v_k = D^{-1}(x_{k+1} - x_k)/\Delta t_k` the standardised rate of pair ``k``
    (``scale`` :math:`D`, by default each variable's standard deviation), the root of
    :math:`\langle|v_{k+1} - v_k|^2\rangle / 3` over :math:`\langle(|v_k|^2 + |v_{k+1}|^2)/2
    \rangle`, over neighbouring pairs of a trajectory, each weighted by the time the two span.
    With ``spacing`` ``k`` > 1, of pairs ``k`` samples apart (those of ``data.interleaved(k)``).

    The weights change nothing on an even time grid. On an uneven one they count each stretch
    of a trajectory by its duration, not by its number of samples, as the error of a rollout
    does: a new-user check's chain sampled at random times (steps from 1e-5 to 1.1) read
    0.15 unweighted, its many short steps hiding the long ones that set its rollouts' error,
    and 0.21 weighted.

    White noise on the recorded states, larger than what the states move per step, gives 1;
    smooth dynamics give about :math:`\omega\Delta t/\sqrt 3` for a motion of frequency
    :math:`\omega` (so a coarser step is rougher too). No unit of time or state changes it.
    ``None`` with fewer than 10 neighbouring pairs, or data that never move.
    """
    d = _spread(data.x) if scale is None else np.asarray(scale, dtype=np.float64)
    k = spacing
    change = power = 0.0
    count, total = 0, len(data.t)
    for s in range(0, max(total - 2 * k, 0), rows):  # pairs (r, r + k), (r + k, r + 2k)
        e = min(s + rows, total - 2 * k)  # for r in [s, e)
        x = np.asarray(data.x[s : e + 2 * k], dtype=np.float64) / d[None, :]
        t = np.asarray(data.t[s : e + 2 * k], dtype=np.float64)
        v = (x[k:] - x[:-k]) / (t[k:] - t[:-k])[:, None]
        tr = data.trajectory[s : e + 2 * k]
        ok = tr[: e - s] == tr[2 * k :]  # rows are grouped by trajectory
        a, b = v[: e - s][ok], v[k:][ok]
        w = (t[2 * k :] - t[: e - s])[ok][:, None]  # the time the two pairs span
        change += float(np.sum(w * (b - a) ** 2))
        power += 0.5 * float(np.sum(w * (a * a + b * b)))
        count += int(ok.sum())
    if count < 10 or not power > 0.0 or not np.isfinite(change):
        return None
    return float(np.sqrt(change / 3.0 / power))


def _spread(x: np.ndarray) -> np.ndarray:
    """Each variable's standard deviation, 1 where it is 0 (such a variable never moves, so
    its scale does not matter here)."""
    s = np.std(np.asarray(x), axis=0, dtype=np.float64)
    return np.where(s > 0, s, 1.0)


#: The pair spacings :func:`pair_spacing` chooses from.
SPACINGS = (1, 2, 3, 4, 6, 8, 12, 16)


def pair_spacing(data: _Samples, spacings: Sequence[int] = SPACINGS) -> int:
    r"""The spacing ``k`` of training pairs, ``k`` samples apart (:meth:`Trajectories.interleaved`),
    at which the data's rates are least rough (:func:`roughness`, in the data's standard
    deviations): 1 for smooth motion, whose roughness grows with ``k``; larger where noise on
    the states, which a ``k`` times longer pair divides by ``k``, outweighs the motion's change
    over ``k`` steps. Only spacings that leave each trajectory at least 8 samples on average
    count.

    On three systems with 1 % noise the pairs 4 samples apart that this chooses were 1.3–2.2×
    more accurate than neighbouring ones (8 apart: 3× less accurate on one of them); on four
    others with 1 % and 5 % noise it was better in 7 of 8 cases. On every clean data set
    measured (the zoo's, those outside it, the reference experiments') it chose 1.
    """
    d = _spread(data.x)
    length = float(np.mean(data.lengths()))
    best, least = 1, roughness(data, d)
    if least is None:
        return 1
    for k in spacings:
        if k > 1 and length / k >= 8:
            r = roughness(data, d, spacing=k)
            if r is not None and r < least:
                best, least = k, r
    return best


#: The order of the differences that :func:`state_noise` takes: white noise gives the same
#: estimate at any order, while smooth motion adds about :math:`(\omega\Delta t/2)^k` of
#: itself at order :math:`k`, so a high order keeps coarse steps from reading as noise
#: (third differences read 1-3 % "noise" on clean data of an adaptive solver's steps, about
#: 18 per period).
NOISE_ORDER = 6


def state_noise(data: _Samples) -> np.ndarray:
    r"""Each variable's noise, an estimate of the standard deviation of white noise on its
    recorded states, from the divided differences of order :math:`k` = ``NOISE_ORDER`` over
    :math:`k + 1` consecutive samples of a trajectory at their own times,
    :math:`d = \sum_j w_j x_j` with :math:`w_j = 1/\prod_{i \ne j}(t_j - t_i)`:
    :math:`\sqrt{\langle(d/|w|)^2\rangle}`. White noise of variance :math:`\sigma^2` gives
    :math:`\sigma^2` on any time grid (on an even one, :math:`d/|w|` is the :math:`k`-th
    difference over :math:`\sqrt{\binom{2k}{k}}`); smooth motion adds about
    :math:`(\omega\Delta t/2)^k` of itself, so on clean data this is an upper bound far below
    the motion. Lower orders where trajectories are shorter; zeros where none has four
    samples."""
    x = np.asarray(data.x, dtype=np.float64)
    return _difference_noise(x, np.asarray(data.t, dtype=np.float64), data.trajectory)


def _difference_noise(x: np.ndarray, t: np.ndarray | None = None,
                      trajectory: np.ndarray | None = None, chunk: int = 1 << 15) -> np.ndarray:
    """The white-noise standard deviation that the normalised divided differences of ``x``
    (rows in order, at times ``t``, by default evenly spaced) give along its first axis, at
    the highest order up to ``NOISE_ORDER`` (and at least 3) that some run of rows of one
    ``trajectory`` (where given) holds; zeros where none does."""
    t = np.arange(len(x), dtype=np.float64) if t is None else t
    for k in range(NOISE_ORDER, 2, -1):
        rows = len(x) - k
        if rows < 1:
            continue
        same = (np.ones(rows, bool) if trajectory is None
                else trajectory[k:] == trajectory[:-k])  # (rows are grouped by trajectory)
        if not np.any(same):
            continue
        total = np.zeros(x.shape[1:])
        for s in range(0, rows, chunk):  # windows starting at rows [s, e) of one trajectory
            e = min(s + chunk, rows)
            ok = same[s:e]
            times = np.stack([t[s + j : e + j][ok] for j in range(k + 1)], axis=1)
            tau = (times - times[:, :1]) / (times[:, -1:] - times[:, :1])  # no unit of time
            gaps = tau[:, :, None] - tau[:, None, :]
            gaps[:, np.arange(k + 1), np.arange(k + 1)] = 1.0
            w = 1.0 / np.prod(gaps, axis=2)
            w /= np.linalg.norm(w, axis=1, keepdims=True)
            d = sum(w[:, j, None] * x[s + j : e + j][ok] for j in range(k + 1))
            total += np.sum(d**2, axis=0)
        return np.sqrt(total / np.count_nonzero(same))
    return np.zeros(x.shape[1:])


def noise_level(data: _Samples) -> float:
    """The noise on the recorded states as a fraction of their spread: the median over the
    variables that move of :func:`state_noise` over each one's standard deviation (0.05 for
    Gaussian noise of 5 % of it; about 0 on clean, finely sampled data)."""
    spread = np.std(np.asarray(data.x), axis=0, dtype=np.float64)
    moving = spread > 0
    if not np.any(moving):
        return 0.0
    return float(np.median(state_noise(data)[moving] / spread[moving]))


def range_beyond_noise(series: np.ndarray, t: np.ndarray | None = None,
                       parts: int = 10) -> float:
    r"""How far a quantity moves along one trajectory (``series``, its values there) beyond
    white noise on it: the range of its means over ``parts`` consecutive stretches (at most one
    per value), less the range that noise alone gives such means,
    :math:`2\sqrt{2\ln m}\,\sigma/\sqrt{n}` for :math:`m` stretches of at least :math:`n`
    values, :math:`\sigma` from the differences of :func:`state_noise` (at the times ``t``
    where given, else evenly spaced); never below 0.
    On smooth values, the range of the stretches' means: about 90 % of a steady drift. The
    true energy of a damped oscillator's GENERIC data with 5 % noise on the states (8
    trajectories of 200 states) spans up to 23 % of its spread along one, noise alone; this
    leaves 0."""
    v = np.asarray(series, dtype=np.float64)
    if len(v) < 4:
        return float(np.ptp(v)) if len(v) else 0.0
    sigma = float(_difference_noise(v[:, None], None if t is None else np.asarray(
        t, dtype=np.float64))[0])
    stretches = np.array_split(v, min(parts, len(v)))
    means = np.array([s.mean() for s in stretches])
    least = min(len(s) for s in stretches)
    noise = 2.0 * np.sqrt(2.0 * np.log(len(stretches))) * sigma / np.sqrt(least)
    return max(float(np.ptp(means)) - noise, 0.0)
