"""The one registry of trajectory formats, file suffix -> reader and writer (:data:`FORMATS`),
and what goes through it: :func:`read`, :func:`write`, :func:`trajectory_suffixes`. A new
format is one module in ``metriplex/io/`` (a reader that returns :class:`Trajectories` and a
writer that takes them) and one line in :data:`FORMATS`.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Callable

import numpy as np

from .._errors import MetriplexError
from ..data import Trajectories, check_time_step, uniform_times
from ._csv import read_csv, write_csv
from ._hdf5 import read_hdf5, write_hdf5
from ._mat import read_mat, write_mat
from ._npy import read_npy
from ._npz import read_npz, write_npz

#: Each format: its suffixes (lower case), its reader, its writer and its layout in one line
#: (what the command line's help says of it).
FORMATS: tuple[tuple[tuple[str, ...], Callable[..., Trajectories],
                     Callable[..., None] | None, str], ...] = (
    ((".npz",), read_npz, write_npz,
     "arrays trajectory (N,), t (N,), x (N, n), optional names (n,); or x (K, T, n), t (T,)"),
    ((".csv",), read_csv, write_csv,
     "columns trajectory,t,<name_1>,...,<name_n> (integer trajectory id, time, the state)"),
    ((".h5", ".hdf5"), read_hdf5, write_hdf5,
     "one group per trajectory, each with datasets t (T,) and x (T, n)"),
    ((".mat",), read_mat, write_mat,
     "snapshots (trajectories x variables x snapshots) with a time vector or step"),
    ((".npy",), read_npy, None,
     "states only, trajectories x snapshots x variables (K, T, n) or (T, n); with --dt"),
)

#: Suffix -> reader and suffix -> writer, from :data:`FORMATS`.
READERS: dict[str, Callable[..., Trajectories]] = {s: r for ss, r, _, _ in FORMATS for s in ss}
WRITERS: dict[str, Callable[..., None]] = {s: w for ss, _, w, _ in FORMATS for s in ss
                                           if w is not None}  # .npy holds no times


def suffixes_text() -> str:
    """Every suffix that :func:`write` writes, in a phrase: ``".npz, .csv, .h5, .hdf5 or
    .mat"``."""
    suffixes = [s for ss, _, w, _ in FORMATS for s in ss if w is not None]
    return ", ".join(suffixes[:-1]) + " or " + suffixes[-1]


def layouts_text() -> str:
    """One line per format of :data:`FORMATS`: its suffixes and its layout."""
    return "\n".join(f"  {'/'.join(ss):<11} {layout}" for ss, _, _, layout in FORMATS)


def read(path: str | os.PathLike, *, dt: float | None = None) -> Trajectories:
    """Read trajectories: the long table (``.npz``, ``.csv``), HDF5 (``.h5``, ``.hdf5``), MATLAB
    (``.mat``) or states alone (``.npy``, with ``dt``). Layouts: docs/design.md, 'Trajectory
    data', :mod:`metriplex.io._hdf5`, :mod:`metriplex.io._mat` and :mod:`metriplex.io._npy`.

    ``dt``: give every trajectory the uniform time grid ``t = k * dt`` (``k = 0, 1, ...`` in the
    file's order of its samples), for a file that lacks times or holds a time vector that does
    not fit its snapshots. A file whose own times have other steps (by more than 0.1 %) is
    refused, so that a wrong step never replaces correct times unnoticed. The command line's
    ``--dt``.

    A malformed file raises :class:`MetriplexError` naming the file, the rule it breaks, the
    value found and the fix.

    ```python
    data = mx.read("data.npz")
    data = mx.read("database.mat", dt=0.01)
    ```
    """
    if dt is not None:
        dt = check_time_step(dt)
    path = Path(path)
    if not path.exists():
        raise MetriplexError(f"data file {str(path)!r} does not exist; check the path.")
    if path.is_dir():
        raise MetriplexError(f"{str(path)!r} is a folder; give a data file (.npz, .csv, ...).")
    if path.stat().st_size == 0:
        raise MetriplexError(f"data file {str(path)!r} is empty; it holds no trajectories.")
    suffix = path.suffix.lower()
    if suffix not in READERS:
        raise MetriplexError(
            f"cannot read {str(path)!r}: unknown extension {suffix!r}. Supported: "
            f"{', '.join(sorted(READERS))}."
        )
    try:
        if dt is None:
            return READERS[suffix](path)
        try:
            own = READERS[suffix](path)
        except MetriplexError:  # no usable times (none, or a vector that does not fit)
            return READERS[suffix](path, dt=dt)
        _check_own_steps(own, dt)
        return Trajectories(own.trajectory, uniform_times(own.trajectory, dt), own.x, own.names)
    except MetriplexError as e:
        if str(path) in str(e):
            raise
        raise MetriplexError(f"data file {str(path)!r}: {e}") from None


def _check_own_steps(own: Trajectories, dt: float) -> None:
    """Refuse ``dt`` for data whose own times have another step: ``dt`` is for files without
    usable times, and replacing correct ones by a wrong step would train a model of other
    dynamics without a word. Every step is compared: equal to ``dt`` within 0.1 %, or within
    the rounding of the times as stored (float32 times wobble step by step), is no
    contradiction. Times are taken as float32 only where every one of them is a float32
    number: on a float64 clock near 1.7e9 s, float32's rounding (128 s) would hide any gap."""
    same = own.trajectory[1:] == own.trajectory[:-1]
    steps = np.diff(own.t)[same]
    t = np.asarray(own.t, dtype=np.float64)
    stored = np.float32 if np.array_equal(t, t.astype(np.float32)) else np.float64
    rounding = 8 * np.finfo(stored).eps * np.abs(t[1:][same])
    if len(steps) and np.any(np.abs(steps - dt) > np.maximum(1e-3 * dt, rounding)):
        lo, hi = float(np.min(steps)), float(np.max(steps))
        found = f"{lo:.6g}" if hi - lo <= 1e-3 * abs(hi) else f"{lo:.6g} to {hi:.6g}"
        raise MetriplexError(
            f"--dt {dt:g} would replace the file's own times, whose steps are {found}. --dt is "
            "for files without times (or a .mat time vector that does not fit its snapshots). "
            "Leave out --dt to use the file's times, or convert the times in the file if they "
            "are in another unit.")


def write(path: str | os.PathLike, data: Trajectories) -> None:
    """Write trajectories, atomically: the long table (``.npz``, ``.csv``), HDF5 (``.h5``,
    ``.hdf5``) or MATLAB (``.mat``). :func:`read` gives back the same trajectories exactly.
    """
    if not isinstance(data, Trajectories):
        raise MetriplexError(
            f"write() takes a Trajectories; got {type(data).__name__}. Build one with "
            "Trajectories.from_list([(t, x), ...], names=...)."
        )
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in WRITERS:
        raise MetriplexError(
            f"cannot write {str(path)!r}: unknown extension {suffix!r}. Trajectories are written "
            f"as {', '.join(sorted(WRITERS))}."
        )
    WRITERS[suffix](path, data)


def trajectory_suffixes() -> tuple[str, ...]:
    """The file extensions :func:`write` writes trajectories as."""
    return tuple(sorted(WRITERS))
