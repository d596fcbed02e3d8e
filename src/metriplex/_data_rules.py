"""The rules the columns of :class:`~metriplex.Trajectories` must satisfy (docs/design.md,
'Trajectory data'), each refusal naming the rule, the value and the fix."""

from __future__ import annotations

from typing import Any

import numpy as np

from ._errors import MetriplexError


def checked_columns(trajectory: Any, t: Any, x: Any, names: Any
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, tuple[str, ...]]:
    """``(trajectory, t, x, names)`` as int64 ids, float64 times (numpy dates and durations
    in seconds) and states sorted by trajectory (stably: file order within one), and one name
    per variable; refused where a rule fails."""
    traj = raw = np.asarray(trajectory)
    t_given = np.asarray(t)
    if t_given.dtype.kind in "mM":  # dates or durations: seconds, whatever numpy's unit
        t_given = t_given.astype(t_given.dtype.str[:3] + "[ns]").astype(np.int64) / 1e9
    t = np.asarray(t_given, dtype=np.float64)
    x = np.asarray(x)
    if x.ndim == 1:
        x = x[:, None]
    if x.dtype.kind not in "fiu":
        raise MetriplexError(f"state values must be numbers; got dtype {x.dtype}.")
    x = np.asarray(x, np.float64)  # no copy of float64 data (large files: memory)
    if traj.ndim != 1 or t.ndim != 1 or x.ndim != 2:
        raise MetriplexError(
            "trajectory and t must be 1-D and x 2-D (rows x variables); got shapes "
            f"{traj.shape}, {t.shape}, {x.shape}."
        )
    if not (len(traj) == len(t) == len(x)):
        raise MetriplexError(
            f"trajectory, t and x must have one entry per row; got {len(traj)}, {len(t)} "
            f"and {len(x)} rows."
        )
    if len(t) == 0:
        raise MetriplexError("the data hold no rows; a file with at least one trajectory of "
                             "two or more samples is needed.")
    if traj.dtype.kind == "f":
        if not np.all(np.isfinite(traj)) or np.any(traj != np.round(traj)):
            raise MetriplexError(
                "trajectory ids must be integers; got non-integer values such as "
                f"{traj[np.flatnonzero(traj != np.round(traj))[:1]]}."
            )
    if traj.dtype.kind not in "iuf":
        raise MetriplexError(f"trajectory ids must be integers; got dtype {traj.dtype}.")
    traj = traj.astype(np.int64)
    names = tuple(str(s) for s in names) or tuple(f"x{i}" for i in range(x.shape[1]))
    if len(names) != x.shape[1]:
        raise MetriplexError(
            f"got {len(names)} variable names for {x.shape[1]} state columns; give one name "
            "per column."
        )
    if len(set(names)) != len(names):
        raise MetriplexError(f"variable names must be unique; got {list(names)}.")
    for arr, what in ((t, "t"), (x, "x")):
        bad = ~np.isfinite(arr)
        if np.any(bad):
            rows = np.flatnonzero(bad.reshape(len(arr), -1).any(axis=1))
            row = int(rows[0])
            others = (f" {len(rows) - 1} other row{'s' if len(rows) > 2 else ''} "
                      f"({', '.join(map(str, rows[1:6].tolist()))}"
                      f"{', ...' if len(rows) > 6 else ''}) {'have' if len(rows) > 2 else 'has'} "
                      "them too." if len(rows) > 1 else "")
            raise MetriplexError(
                f"data must be finite; {what} has NaN or inf at row {row} (trajectory "
                f"{traj[row]}, t={t[row]}).{others} Remove or interpolate those samples."
            )
    # Stable sort by trajectory id keeps rows of a trajectory in file order.
    if np.any(traj[1:] < traj[:-1]):  # already sorted (the usual case): no copies
        order = np.argsort(traj, kind="stable")
        traj, t, x = traj[order], t[order], x[order]
    ids, starts, counts = np.unique(traj, return_index=True, return_counts=True)
    for i, s, c in zip(ids, starts, counts):
        if c < 2:
            raise MetriplexError(
                f"every trajectory needs at least two samples: a training pair, or for "
                f"rollout and evaluate the times to predict at; trajectory {i} has {c}. Drop "
                f"it, or merge it with its neighbour; to predict from an initial state alone, "
                f"repeat it at every time wanted (rollout reads only each trajectory's first "
                f"state and its times)."
            )
        dt = np.diff(t[s : s + c])
        if np.any(dt <= 0):
            k = int(np.flatnonzero(dt <= 0)[0])
            raise MetriplexError(
                f"`t` must be strictly increasing within each trajectory; trajectory {i} "
                f"has t[{k + 1}]={float(t[s + k + 1])!r} <= t[{k}]={float(t[s + k])!r}. "
                + _why_not_increasing(np.flatnonzero(raw == i), t_given, float(t[s + k]))
            )
    return traj, t, x, names


def _why_not_increasing(rows: np.ndarray, t_given: np.ndarray, at: float) -> str:
    """The likely cause and fix where a trajectory's times do not increase: two recordings
    under one id (its rows in separate blocks, some times repeated), float32 times too coarse
    for their size, rows out of order (every time distinct: sort them), or repeated samples
    (float32 times: stored so, or every one of them a float32 value beyond 2**24, as the
    readers' float64 copy of a float32 column is)."""
    blocks = np.split(rows, np.flatnonzero(np.diff(rows) > 1) + 1)
    times = np.asarray(t_given[rows], np.float64)
    distinct = len(np.unique(times)) == len(times)
    # Data rows from 0, not a CSV's file lines (those count the header and any blank line).
    spans = (", ".join(f"{b[0]}-{b[-1]}" for b in blocks[:3])
             + " counted from 0 after any header")
    if len(blocks) > 1 and not distinct:
        return (f"Its rows stand in {len(blocks)} separate blocks (rows {spans}) and repeat "
                "times: two recordings under one id? Give each its own trajectory id.")
    if t_given.dtype == np.float32 or (abs(at) >= 2.0**24
                                      and np.all(times == times.astype(np.float32))):
        return (f"The times are float32, which at t = {at:.4g} resolve only "
                f"{float(np.spacing(np.float32(at))):.3g}: store them as float64, or measured "
                "from the first sample.")
    if distinct:
        where = f" (in {len(blocks)} separate blocks, rows {spans})" if len(blocks) > 1 else ""
        return (f"Its {len(rows)} rows{where} are not in time order, and no time repeats: sort "
                "the rows by trajectory and time (pandas: df.sort_values(['trajectory', "
                "'t'])).")
    return "Some times repeat: drop the duplicated samples, or split the trajectory."
