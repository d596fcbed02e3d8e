"""Training pairs held once: the states of the data plus, for every pair, the rows of
:math:`x_n` and :math:`x_{n+1}` in them (:class:`PairRows` on the host, :class:`PairStore` on
device, from which the compiled training step gathers its minibatches).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ._errors import MetriplexError
from .data import Pairs, Trajectories, check_width
from ._loss_base import Batch, Runs, Window

if TYPE_CHECKING:
    from jax.typing import DTypeLike
    from numpy.typing import ArrayLike


class PairRows(NamedTuple):
    """Data pairs as rows of one state array (host side): pair ``k`` is
    ``(x[first[k]], x[second[k]])`` over ``dt[k]``. Consecutive samples of a trajectory share
    their row, so trajectory data cost their states once, not twice."""

    x: np.ndarray  # (N, n)
    first: np.ndarray  # (P,) int
    second: np.ndarray  # (P,) int
    dt: np.ndarray  # (P,)

    @property
    def count(self) -> int:
        return int(self.first.shape[0])

    @property
    def in_runs(self) -> bool:
        """Whether every pair is two consecutive rows (trajectory data), so that a run of
        rows is a run of pairs (:meth:`PairStore.take_runs`)."""
        return bool(np.all(self.second == self.first + 1))

    @classmethod
    def of(cls, data: Trajectories | Pairs | tuple[ArrayLike, ArrayLike, ArrayLike],
           n: int | None, what: str) -> "PairRows":
        """The pairs of ``data`` (:class:`Trajectories`, :class:`Pairs` or ``(x0, x1, dt)``),
        checked: shapes, ``n`` variables, finite states, finite positive steps."""
        if isinstance(data, Trajectories):
            same = data.trajectory[1:] == data.trajectory[:-1]
            first = np.flatnonzero(same)
            rows = cls(data.x, first, first + 1, np.diff(data.t)[same])
        elif isinstance(data, Pairs) or (isinstance(data, tuple) and len(data) == 3):
            x0, x1, dt = (np.asarray(a) for a in data)
            if x0.ndim != 2 or x0.shape != x1.shape or dt.shape != x0.shape[:1]:
                raise MetriplexError(
                    f"{what} pairs need x0, x1 of shape (N, n) and dt of shape (N,); got "
                    f"{x0.shape}, {x1.shape}, {dt.shape}."
                )
            k = np.arange(len(dt))
            rows = cls(np.concatenate([x0, x1]), k, k + len(dt), dt)
        else:
            raise MetriplexError(
                f"fit needs Trajectories, Pairs or a tuple (x0, x1, dt); got "
                f"{type(data).__name__}."
            )
        index = np.int32 if len(rows.x) < 2**31 - 1 else np.int64
        rows = rows._replace(first=rows.first.astype(index), second=rows.second.astype(index))
        rows.check(n, what)
        return rows

    def check(self, n: int | None, what: str) -> None:
        if self.count == 0:
            raise MetriplexError(f"{what} data hold no pairs; each trajectory needs >= 2 samples.")
        if n is not None:
            check_width(self.x.shape[1], n)
        bad = ~np.isfinite(self.dt) | (self.dt <= 0)
        if np.any(bad):
            raise MetriplexError(
                f"every dt must be finite and > 0; {what} data have dt = {self.dt[bad][:3]}. "
                "Sort samples by time and drop duplicates."
            )
        if not np.all(np.isfinite(self.x)):
            raise MetriplexError(f"{what} data contain NaN or inf; clean them before training.")

    def batch(self, idx: ArrayLike, scale: ArrayLike, dtype: DTypeLike,
              window_shape: tuple[int, int] | None = None) -> Batch:
        """The pairs ``idx`` (a few thousand: evaluation subsets) as a :class:`Batch`, with
        the :class:`Window` of ``window_shape`` as :meth:`PairStore.take` gathers it."""
        idx = np.asarray(idx)

        def put(a):
            return jnp.asarray(np.asarray(a, jnp.dtype(dtype)))

        window = None
        if window_shape is not None:
            w, k = window_shape
            x0, targets, dt, mask = _window(np, self.x, self.first, self.second, self.dt,
                                            _ahead(self), idx[:w], k)
            window = Window(put(x0), put(targets), put(dt), jnp.asarray(mask))
        return Batch(put(self.x[self.first[idx]]), put(self.x[self.second[idx]]),
                     put(self.dt[idx]), jnp.asarray(scale, dtype), window)


class PairStore(NamedTuple):
    """All training pairs on device, as :class:`PairRows` hold them (the states once, two
    index arrays); :meth:`take` gathers a minibatch inside the compiled step."""

    x: jax.Array
    first: jax.Array
    second: jax.Array
    dt: jax.Array
    scale: jax.Array
    ahead: jax.Array  # (P,) int: how many of the next pairs continue pair k's trajectory
    step_from: jax.Array  # (N,) the dt of the pair that starts at each row, 0 where none

    @classmethod
    def of(cls, rows: PairRows, scale: ArrayLike, dtype: DTypeLike) -> "PairStore":
        def put(a):
            return jnp.asarray(np.asarray(a, jnp.dtype(dtype)))  # one host copy at most

        step_from = np.zeros(len(rows.x), np.float64)
        if rows.in_runs:
            step_from[rows.first] = rows.dt
        return cls(put(rows.x), jnp.asarray(rows.first), jnp.asarray(rows.second),
                   put(rows.dt), jnp.asarray(scale, dtype), jnp.asarray(_ahead(rows)),
                   put(step_from))

    @property
    def count(self) -> int:
        return int(self.first.shape[0])

    def take(self, idx: jax.Array, window_shape: tuple[int, int] | None = None) -> Batch:
        """The pairs ``idx`` as a :class:`Batch`; with ``window_shape`` ``(W, K)``, also the
        :class:`Window` of the ``K`` steps that follow the first state of each of the first
        ``W`` pairs (masked past their trajectory's end)."""
        window = None
        if window_shape is not None:
            w, k = window_shape
            window = _window(jnp, self.x, self.first, self.second, self.dt, self.ahead,
                             idx[:w].astype(self.first.dtype), k)
        return Batch(self.x[self.first[idx]], self.x[self.second[idx]], self.dt[idx],
                     self.scale, window)

    def take_runs(self, start: jax.Array, pairs: int) -> Batch:
        """Runs of ``pairs`` consecutive pairs from the rows ``start`` ``(R,)`` (data whose
        :attr:`PairRows.in_runs`): ``R * pairs`` pairs from ``R * (pairs + 1)`` states, with
        :class:`Runs` so the loss evaluates each state once. A "pair" that crosses into the
        next trajectory (or past the last row) has weight 0 and a unit step. Every pair of the
        data is in a run from any of the ``pairs`` rows up to its own, so starts drawn
        uniformly over the rows draw each pair equally often (but the first ``pairs - 1``)."""
        R = start.shape[0]
        last = self.x.shape[0] - 1
        rows = jnp.minimum(start[:, None] + jnp.arange(pairs + 1, dtype=start.dtype)[None, :],
                           last)
        step = self.step_from[rows[:, :-1]].reshape(-1)
        valid = step > 0  # no pair starts at a trajectory's last row, nor at the clipped last
        local = (jnp.arange(R, dtype=start.dtype)[:, None] * (pairs + 1)
                 + jnp.arange(pairs, dtype=start.dtype)[None, :]).reshape(-1)
        states = self.x[rows.reshape(-1)]
        return Batch(states[local], states[local + 1], jnp.where(valid, step, 1.0).astype(
            self.dt.dtype), self.scale, None, valid.astype(self.dt.dtype),
            Runs(states, local, local + 1))


def _window(xp, x, first, second, dt, ahead, start, steps: int) -> Window:
    """The :class:`Window` of ``steps`` pairs from each pair ``start``, gathered with the array
    module ``xp`` (NumPy on the host, ``jax.numpy`` inside the compiled step); rows past the
    end of a trajectory are clipped to valid pairs and masked."""
    j = xp.arange(steps, dtype=first.dtype)
    pairs = xp.minimum(start[:, None] + j[None, :], first.shape[0] - 1)
    return Window(x[first[start]], x[second[pairs]], dt[pairs],
                  j[None, :] <= ahead[start][:, None])


def _ahead(rows: PairRows) -> np.ndarray:
    """For each pair, how many of the pairs after it continue its trajectory (pair ``k + 1``
    starts where pair ``k`` ends)."""
    P = rows.count
    ends = np.flatnonzero(rows.second[:-1] != rows.first[1:])  # last pair of each run
    ends = np.append(ends, P - 1)
    k = np.arange(P)
    return (ends[np.searchsorted(ends, k)] - k).astype(rows.first.dtype)
