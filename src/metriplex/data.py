r"""Trajectory data: the long table (docs/design.md, 'Trajectory data'), training pairs, and
splits by trajectory.

A :class:`Trajectories` holds one row per observed state: ``trajectory`` (integer id), ``t``
(time) and ``x`` (the ``n`` state variables). Rows of one trajectory are ordered by strictly
increasing ``t``; spacing may vary and trajectories may have different lengths (ragged).
Training pairs are consecutive rows of the same trajectory, each with its own ``dt``.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any, Iterator, NamedTuple, Sequence

import numpy as np

from ._data_rules import checked_columns
from ._errors import MetriplexError, expect_integer
# How rough the observed rates are, and the pair spacing chosen by it; public from here.
from ._roughness import SPACINGS as SPACINGS
from ._roughness import noise_level as noise_level
from ._roughness import pair_spacing as pair_spacing
from ._roughness import range_beyond_noise as range_beyond_noise
from ._roughness import roughness as roughness
from ._roughness import state_noise as state_noise

if TYPE_CHECKING:
    from numpy.typing import ArrayLike, DTypeLike


#: A variable whose standard deviation is at most this fraction of its own largest magnitude is
#: constant: below it, the spread is rounding (float32 keeps about 7 digits), and dividing by it
#: would turn rounding into signal. Each variable is judged by its own size, so one in small
#: units beside one in large units is not called constant.
CONSTANT_RTOL = 1e-8


def state_statistics(*parts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-variable ``(mean, scale, varying)`` of states (arrays of shape ``(N, n)``, all
    ``parts`` taken together): ``scale`` is the standard deviation, the unit in which losses,
    residuals, errors and network inputs are measured, and 1 where the variable is constant
    (``varying`` False; :data:`CONSTANT_RTOL`). The one place where the data's scales are
    computed. Block by block in float64 (Chan's pooled update), so large float32 data need no
    float64 copy."""
    rows = 1 << 16
    count, mean, m2, peak = 0, 0.0, 0.0, 0.0  # peak: per variable
    for part in parts:
        part = np.asarray(part)
        for b in range(0, len(part), rows):
            block = np.asarray(part[b : b + rows], dtype=np.float64)
            k = len(block)
            mu = block.mean(axis=0)
            delta = mu - mean
            mean = mean + delta * (k / (count + k))
            m2 = m2 + ((block - mu) ** 2).sum(axis=0) + delta**2 * (count * k / (count + k))
            count += k
            peak = np.maximum(peak, np.abs(block).max(axis=0))
    s = np.sqrt(m2 / count)
    varying = s > CONSTANT_RTOL * peak
    return np.asarray(mean, dtype=np.float64), np.where(varying, s, 1.0), varying


def state_scale(*parts: np.ndarray) -> np.ndarray:
    """Per-variable standard deviation of states, 1 for constant variables: the ``scale`` of
    :func:`state_statistics`."""
    return state_statistics(*parts)[1]


def time_scale(pairs: "Pairs | Trajectories", scale: np.ndarray | None = None) -> float:
    r"""The data's time scale :math:`\tau`: the time over which a typical variable moves by one
    of its standard deviations.

    With observed rates :math:`v_i = (x_{n+1,i} - x_{n,i})/\Delta t_n` and the state scale
    :math:`d_i`, :math:`1/\tau` is the geometric mean over the moving variables of
    :math:`\operatorname{rms}(v_i)/d_i`. It scales with the unit of time (milliseconds instead
    of seconds give a 1000x larger :math:`\tau`) and ignores offsets of the state, so losses
    and networks measured in :math:`\tau` do not depend on either. Data that never move get
    :math:`\tau = 1`.
    """
    states = pairs.x if isinstance(pairs, Trajectories) else pairs.x0
    d = state_scale(states) if scale is None else np.asarray(scale, dtype=np.float64)
    squares, count = np.zeros(len(d)), 0
    for v in observed_rates(pairs):
        squares += np.sum(v**2, axis=0)
        count += len(v)
    rate = np.sqrt(squares / max(count, 1)) / d
    moving = rate > 1e-12 * max(float(rate.max(initial=0.0)), 1e-300)
    if not np.any(moving) or not np.all(np.isfinite(rate)):
        return 1.0
    return float(np.exp(-np.mean(np.log(rate[moving]))))


def observed_rates(pairs: "Pairs | Trajectories", rows: int = 1 << 16) -> Iterator[np.ndarray]:
    r"""The observed rates :math:`(x_{n+1} - x_n)/\Delta t_n` of every pair, in float64 blocks of
    at most ``rows`` pairs (so large data need no temporary copies of their size)."""
    if isinstance(pairs, Trajectories):  # the pairs of consecutive rows, never built whole
        data = pairs
        for s in range(0, len(data.t) - 1, rows):
            e = min(s + rows, len(data.t) - 1)
            same = data.trajectory[s + 1 : e + 1] == data.trajectory[s:e]
            x = np.asarray(data.x[s : e + 1], np.float64)
            yield (x[1:] - x[:-1])[same] / np.diff(data.t[s : e + 1])[same, None]
        return
    for s in range(0, len(pairs.dt), rows):
        yield (np.asarray(pairs.x1[s : s + rows], np.float64)
               - np.asarray(pairs.x0[s : s + rows], np.float64)) / np.asarray(
            pairs.dt[s : s + rows], np.float64)[:, None]


def check_width(have: int, n: int) -> None:
    """Refuse data of ``have`` state variables for a model of ``n``."""
    if have != n:
        raise MetriplexError(
            f"the data have {have} state variables but the model expects {n}; build the model "
            f"for {have} variables or select matching columns.")


def _samples_apart(k: Any) -> int:
    """``k`` of :meth:`Trajectories.every` and :meth:`Trajectories.interleaved`, checked."""
    return expect_integer(k, what="the number of samples k", least=1, fix="1 keeps every sample.")


def uniform_times(trajectory: ArrayLike, dt: float) -> np.ndarray:
    r"""The uniform time grid :math:`t = k\,\Delta t` of each row: ``k`` counts the rows of the
    same trajectory id before it, in file order (what ``--dt`` gives instead of a file's own
    times)."""
    traj = np.asarray(trajectory)
    if traj.ndim != 1:
        traj = traj.reshape(len(traj), -1)[:, 0] if traj.ndim else traj.reshape(1)
    _, group = np.unique(traj, return_inverse=True)
    group = group.reshape(-1)
    order = np.argsort(group, kind="stable")
    counts = np.bincount(group)
    k = np.empty(len(traj), np.int64)
    k[order] = np.arange(len(traj)) - np.repeat(np.cumsum(counts) - counts, counts)
    return k * float(dt)


def check_time_step(dt: Any, option: str = "dt") -> float:
    """A time step: a positive finite number."""
    if isinstance(dt, bool) or not isinstance(dt, (int, float, np.integer, np.floating)) \
            or not (np.isfinite(dt) and dt > 0):
        raise MetriplexError(f"{option} must be a positive finite time step; got {dt!r}.")
    return float(dt)


class Pairs(NamedTuple):
    r"""Training pairs :math:`(x_n, x_{n+1}, \Delta t_n)` as arrays of equal length."""

    x0: np.ndarray
    x1: np.ndarray
    dt: np.ndarray

    def __len__(self) -> int:  # type: ignore[override]
        return int(self.x0.shape[0])


@dataclasses.dataclass(frozen=True, eq=False)
class Trajectories:
    """Observed trajectories in the long-table layout.

    ```python
    data = Trajectories.from_list([(t0, x0), (t1, x1)], names=["q", "p"])
    train, valid = data.split(0.2, seed=0)
    pairs = train.pairs()
    ```
    """

    trajectory: np.ndarray
    t: np.ndarray
    x: np.ndarray
    names: tuple[str, ...] = ()

    def __post_init__(self):
        traj, t, x, names = checked_columns(self.trajectory, self.t, self.x, self.names)
        object.__setattr__(self, "trajectory", traj)
        object.__setattr__(self, "t", t)
        object.__setattr__(self, "x", x)
        object.__setattr__(self, "names", names)

    # -- construction -------------------------------------------------------------------------
    @classmethod
    def from_list(
        cls, trajectories: Sequence[tuple[np.ndarray, np.ndarray]], names: Sequence[str] = ()
    ) -> "Trajectories":
        """From a list of ``(t, x)`` with ``t`` of shape ``(T_k,)`` and ``x`` of ``(T_k, n)``
        (or ``(T_k,)`` for one variable), one pair per trajectory."""
        if len(trajectories) == 0:
            raise MetriplexError("no trajectories given; pass at least one (t, x) pair.")
        ids, ts, xs = [], [], []
        for k, pair in enumerate(trajectories):
            if not isinstance(pair, (tuple, list)) or len(pair) != 2:
                raise MetriplexError(
                    f"Trajectories.from_list takes one (t, x) pair per trajectory; item {k} is "
                    f"{type(pair).__name__} {np.shape(pair)}. Pass [(t0, x0), (t1, x1), ...], or "
                    "Trajectories.from_arrays(ts, xs) for arrays of equal length.")
            t = np.asarray(pair[0], dtype=np.float64).reshape(-1)
            x = np.asarray(pair[1])
            if x.ndim == 1:
                x = x[:, None]
            if x.ndim != 2 or len(x) != len(t):
                raise MetriplexError(
                    f"trajectory {k}: x must have one row per time, shape ({len(t)}, n) for its "
                    f"{len(t)} times; got shape {x.shape}.")
            if xs and x.shape[1] != xs[0].shape[1]:
                raise MetriplexError(
                    f"every trajectory needs the same variables; trajectory 0 has "
                    f"{xs[0].shape[1]} and trajectory {k} has {x.shape[1]}.")
            ids.append(np.full(len(t), k))
            ts.append(t)
            xs.append(x)
        return cls(np.concatenate(ids), np.concatenate(ts), np.concatenate(xs), tuple(names))

    @classmethod
    def from_arrays(cls, ts: np.ndarray, xs: np.ndarray,
                    names: Sequence[str] = ()) -> "Trajectories":
        """From a shared grid ``ts`` (T,) or per-trajectory grids (K, T) and ``xs`` (K, T, n)."""
        xs = np.asarray(xs)
        ts = np.asarray(ts, dtype=np.float64)
        if xs.ndim != 3 or ts.ndim not in (1, 2) or ts.shape[-1] != xs.shape[1] or (
                ts.ndim == 2 and len(ts) not in (1, len(xs))):
            raise MetriplexError(
                "Trajectories.from_arrays takes xs of shape (K, T, n) and ts of shape (T,) or "
                f"(K, T); got xs {xs.shape} and ts {ts.shape}. For trajectories of different "
                "lengths use Trajectories.from_list([(t0, x0), (t1, x1), ...]).")
        ts = np.broadcast_to(ts, xs.shape[:2])
        return cls.from_list(list(zip(ts, xs)), names)

    # -- views ----------------------------------------------------------------------------------
    @property
    def n(self) -> int:
        """The number of state variables."""
        return int(self.x.shape[1])

    @property
    def ids(self) -> np.ndarray:
        """The trajectory ids, sorted, each once."""
        return np.unique(self.trajectory)

    def __len__(self) -> int:
        return len(self.ids)

    def __repr__(self) -> str:
        """A summary, not the arrays: ``Trajectories(32 trajectories of 201 samples; 9
        variables (q1, q2, ...); t from 0 to 20)``; the arrays are ``.trajectory``, ``.t``,
        ``.x``."""
        lengths = self.lengths()
        samples = (f"{lengths[0]}" if lengths.min() == lengths.max()
                   else f"{lengths.min()} to {lengths.max()}")
        names = ", ".join(self.names[:6]) + (", ..." if len(self.names) > 6 else "")
        k = len(lengths)
        return (f"Trajectories({k} trajector{'y' if k == 1 else 'ies'} of {samples} samples; "
                f"{self.n} variable{'' if self.n == 1 else 's'}"
                + (f" ({names})" if names else "")
                + f"; t from {self.t.min():.4g} to {self.t.max():.4g})")

    def _bounds(self) -> tuple[np.ndarray, np.ndarray]:
        # Rows are sorted by trajectory id (see __post_init__), so each is one slice.
        _, starts, counts = np.unique(self.trajectory, return_index=True, return_counts=True)
        return starts, counts

    def __iter__(self) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        for s, c in zip(*self._bounds()):
            yield self.t[s : s + c], self.x[s : s + c]

    def lengths(self) -> np.ndarray:
        """The number of samples of each trajectory, in the order of :attr:`ids`."""
        return self._bounds()[1]

    def constant_variables(self, rtol: float = 1e-12) -> tuple[int, ...]:
        """The variables that stay constant along every trajectory (to ``rtol`` times their
        largest magnitude), such as a parameter recorded with each trajectory; none if every
        variable is constant."""
        starts, _ = self._bounds()
        spread = np.maximum.reduceat(self.x, starts) - np.minimum.reduceat(self.x, starts)
        size = np.max(np.abs(self.x), axis=0)
        constant = np.all(spread <= rtol * size, axis=0)
        return () if np.all(constant) else tuple(int(i) for i in np.flatnonzero(constant))

    def select(self, ids: Sequence[int]) -> "Trajectories":
        """The trajectories whose ids are in ``ids`` (in the order of their ids; ids that the data
        lack are ignored)."""
        m = np.isin(self.trajectory, np.asarray(ids))
        if not m.any() and len(ids):
            have = self.ids
            raise MetriplexError(
                f"none of the ids {[int(i) for i in ids][:8]} is in these data, whose "
                f"{len(have)} trajectories have ids {int(have.min())} to {int(have.max())}; "
                "choose among those."
            )
        return Trajectories(self.trajectory[m], self.t[m], self.x[m], self.names)

    def every(self, k: int) -> "Trajectories":
        """Every ``k``-th sample of each trajectory, from its first: pairs ``k`` samples apart,
        whose rates rise ``k`` times further above noise on the recorded states (and whose
        step resolves the dynamics ``k`` times less finely)."""
        keep = self._positions() % _samples_apart(k) == 0
        return Trajectories(self.trajectory[keep], self.t[keep], self.x[keep], self.names)

    def interleaved(self, k: int) -> "Trajectories":
        """Each trajectory as ``k`` interleaved ones, the ``j``-th holding its samples ``j, j +
        k, j + 2k, ...`` with id ``k * id + j``: pairs ``k`` samples apart, every sample still
        used, but for a trajectory's lone samples (fewer than ``k`` samples at its end)
        (:func:`pair_spacing` chooses ``k`` for noisy data). ``k = 1``: these data, not a
        copy (training holds its states once)."""
        k = _samples_apart(k)
        if k == 1:
            return self
        ids = self.trajectory.astype(np.int64) * k + self._positions() % k
        _, back, count = np.unique(ids, return_inverse=True, return_counts=True)
        order = np.argsort(ids, kind="stable")
        order = order[count[back][order] > 1]  # a lone sample pairs with nothing
        return Trajectories(ids[order], self.t[order], self.x[order], self.names)

    def _positions(self) -> np.ndarray:
        """Each row's place in its trajectory (0 for its first sample)."""
        starts, counts = self._bounds()
        return np.arange(len(self.t)) - np.repeat(starts, counts)

    def pairs(self, dtype: DTypeLike | None = None) -> Pairs:
        """Consecutive rows of the same trajectory, each with its own ``dt``; states in
        ``dtype`` (default: float64, as stored; float32 halves the memory of large data)."""
        same = self.trajectory[1:] == self.trajectory[:-1]
        x = self.x if dtype is None else np.asarray(self.x, dtype)
        return Pairs(x[:-1][same], x[1:][same], np.diff(self.t)[same])

    def padded(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(ts, xs, lengths)`` padded to the longest trajectory by repeating the last row.

        Repeated times give zero steps, which every scheme maps to the same state, so a batched
        rollout on the padded grid equals the rollouts of the ragged trajectories.
        """
        lengths = self.lengths()
        T = int(lengths.max())
        ts = np.empty((len(lengths), T))
        xs = np.empty((len(lengths), T, self.n))
        for k, (t, x) in enumerate(self):
            ts[k, : len(t)], ts[k, len(t) :] = t, t[-1]
            xs[k, : len(t)], xs[k, len(t) :] = x, x[-1]
        return ts, xs, lengths

    def split(self, fraction: float, *, seed: int = 0) -> tuple["Trajectories", "Trajectories | None"]:
        """Split by trajectory into ``(train, validation)``; no pair is shared between them.

        With a single trajectory, its last ``fraction`` of samples becomes the validation part.
        ``fraction == 0`` gives ``(self, None)``.
        """
        if not 0.0 <= fraction < 1.0:
            raise MetriplexError(
                f"the validation fraction must lie in [0, 1); got {fraction}. Use 0 for none."
            )
        if fraction == 0.0:
            return self, None
        ids = self.ids
        if len(ids) == 1:
            t, x = next(iter(self))
            cut = int(round(len(t) * (1 - fraction)))
            if cut < 2 or len(t) - cut < 2:
                return self, None
            return (
                Trajectories.from_list([(t[:cut], x[:cut])], self.names),
                Trajectories.from_list([(t[cut - 1 :], x[cut - 1 :])], self.names),
            )
        rng = np.random.default_rng(seed)
        perm = rng.permutation(ids)
        n_val = min(max(1, int(round(len(ids) * fraction))), len(ids) - 1)
        return self.select(np.sort(perm[n_val:])), self.select(np.sort(perm[:n_val]))

    def fingerprint(self) -> dict:
        """What identifies these data cheaply: ``trajectory_ids``, ``shape`` (rows, variables)
        and ``sha256``, a hash of the ids, times, states and names (a run folder records it,
        and ``--resume`` compares it)."""
        import hashlib
        import json

        h = hashlib.sha256()
        for a in (self.trajectory, self.t, self.x):
            a = np.ascontiguousarray(a)
            h.update(f"{a.dtype.str}{a.shape}".encode())
            h.update(a)
        h.update(json.dumps(list(self.names)).encode())
        return {"trajectory_ids": [int(i) for i in self.ids],
                "shape": [int(len(self.t)), self.n], "sha256": h.hexdigest()}

    def with_names(self, names: Sequence[str]) -> "Trajectories":
        """The same data with the variables called ``names``."""
        return Trajectories(self.trajectory, self.t, self.x, tuple(names))
