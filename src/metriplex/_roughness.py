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
    \rangle`, over neighbouring pairs of a trajectory. With ``spacing`` ``k`` > 1, of pairs
    ``k`` samples apart (those of ``data.interleaved(k)``).

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
        change += float(np.sum((b - a) ** 2))
        power += 0.5 * float(np.sum(a * a) + np.sum(b * b))
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


def state_noise(data: _Samples) -> np.ndarray:
    r"""Each variable's noise, an estimate of the standard deviation of white noise on its
    recorded states, from the third differences
    :math:`\Delta^3 x_k = x_{k+3} - 3x_{k+2} + 3x_{k+1} - x_k` along the trajectories:
    :math:`\sqrt{\langle(\Delta^3 x)^2\rangle/20}` (white noise of variance
    :math:`\sigma^2` gives :math:`20\sigma^2`; smooth motion adds only its third derivative
    times :math:`\Delta t^3`, so on clean data this is an upper bound far below the motion).
    Zeros where no trajectory has four samples."""
    x = np.asarray(data.x, dtype=np.float64)
    if len(x) < 4:
        return np.zeros(x.shape[1])
    tr = data.trajectory
    return _third_difference_noise(x, tr[3:] == tr[:-3])  # (rows are grouped by trajectory)


def _third_difference_noise(x: np.ndarray, same: np.ndarray | None = None) -> np.ndarray:
    """The white-noise standard deviation that the third differences of ``x`` (rows in order,
    at least 4) give, along its first axis: only those whose four rows are ``same`` (one
    trajectory) where given; zeros where none is."""
    third = x[3:] - 3 * x[2:-1] + 3 * x[1:-2] - x[:-3]
    if same is not None:
        third = third[same]
    if not len(third):
        return np.zeros(x.shape[1:])
    return np.sqrt(np.mean(third**2, axis=0) / 20.0)


def noise_level(data: _Samples) -> float:
    """The noise on the recorded states as a fraction of their spread: the median over the
    variables that move of :func:`state_noise` over each one's standard deviation (0.05 for
    Gaussian noise of 5 % of it; about 0 on clean, finely sampled data)."""
    spread = np.std(np.asarray(data.x), axis=0, dtype=np.float64)
    moving = spread > 0
    if not np.any(moving):
        return 0.0
    return float(np.median(state_noise(data)[moving] / spread[moving]))


def range_beyond_noise(series: np.ndarray, parts: int = 10) -> float:
    r"""How far a quantity moves along one trajectory (``series``, its values there) beyond
    white noise on it: the range of its means over ``parts`` consecutive stretches (at most one
    per value), less the range that noise alone gives such means,
    :math:`2\sqrt{2\ln m}\,\sigma/\sqrt{n}` for :math:`m` stretches of at least :math:`n`
    values, :math:`\sigma` from the third differences as in :func:`state_noise`; never below 0.
    On smooth values, the range of the stretches' means: about 90 % of a steady drift. The
    true energy of a damped oscillator's GENERIC data with 5 % noise on the states (8
    trajectories of 200 states) spans up to 23 % of its spread along one, noise alone; this
    leaves 0."""
    v = np.asarray(series, dtype=np.float64)
    if len(v) < 4:
        return float(np.ptp(v)) if len(v) else 0.0
    sigma = float(_third_difference_noise(v))
    stretches = np.array_split(v, min(parts, len(v)))
    means = np.array([s.mean() for s in stretches])
    least = min(len(s) for s in stretches)
    noise = 2.0 * np.sqrt(2.0 * np.log(len(stretches))) * sigma / np.sqrt(least)
    return max(float(np.ptp(means)) - noise, 0.0)
