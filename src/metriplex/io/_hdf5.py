"""Trajectories in HDF5 (``.h5``, ``.hdf5``), read and written: the observations of the long
table of docs/design.md, 'Trajectory data' (rows of ``trajectory``, ``t``, ``x``), laid out the
way users of HDF5 already store them:

```text
/                      attrs: names (n strings), format, format_version
/trajectory_0          attrs: trajectory (int id, optional)
    t                  (T_0,)    strictly increasing times
    x                  (T_0, n)  states
/trajectory_1 ...      any group names; trajectories may have different lengths
```

An ``x`` stored variables × times ``(n, T)`` is read as ``(T, n)`` where its ``t`` says so
(``T != n``). Datasets ``x`` and ``t`` at the root, with no groups, are read as in NPZ: ``x``
stacked ``(K, T, n)`` or ``(T, n)``, ``t`` of ``(T,)`` or ``(K, T)``.

Groups are read in natural order (``run2`` before ``run10``). The integer attribute
``trajectory`` on every group gives the ids; without it on all groups, ids are ``0, 1, ...`` in
that order. ``names`` may sit on the root or on each group (they must then agree); without it
the variables are called ``x0, x1, ...``.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

from .._errors import MetriplexError
from ..data import Trajectories, uniform_times
from ._checks import (_build, _check_file, _h5_reason, _q, _real, _text, _vector,
                      stacked_table)
from ._files import atomic_write

FORMAT_NAME = "metriplex-trajectories"
HDF5_FORMAT_VERSION = 1

_HDF5_LAYOUT = (
    "one group per trajectory holding datasets `t` (T,) and `x` (T, n), variable names in an "
    "attribute `names`"
)


def natural_key(name: str) -> tuple:
    """Sort key that orders embedded numbers by value: ``run2`` before ``run10``."""
    parts = re.split(r"(\d+)", name)
    # re.split puts text at even and digits at odd positions, so the tuples always compare.
    return tuple(int(p) if i % 2 else p.lower() for i, p in enumerate(parts)) + (name,)


def read_hdf5(path: str | os.PathLike, *, dt: float | None = None) -> Trajectories:
    """Read trajectories from an HDF5 file laid out as in this module's docstring.

    ``dt``: every trajectory gets the uniform grid ``t = k * dt`` instead of its dataset ``t``,
    which may then be missing.

    ```python
    data = mx.read("runs.h5")
    ```
    """
    import h5py

    path = _check_file(path, "HDF5")
    try:
        f = h5py.File(path, "r")
    except OSError as e:
        raise MetriplexError(
            f"{_q(path)} is not a readable HDF5 file ({_h5_reason(e)}). Check that it is HDF5 "
            "and was copied completely; re-export it if it was truncated."
        ) from None
    try:
        with f:
            return _read_hdf5(f, path, dt)
    except MetriplexError:
        raise
    except (OSError, KeyError, ValueError, TypeError, RuntimeError) as e:
        raise MetriplexError(
            f"HDF5 file {_q(path)} is damaged: reading it failed ({_h5_reason(e)}). It may be "
            "truncated; re-export it."
        ) from None


def _read_hdf5(f, path: Path, dt: float | None = None) -> Trajectories:
    import h5py

    where = f"HDF5 file {_q(path)}"
    groups, others = [], []
    for name in f:
        (groups if isinstance(f.get(name), h5py.Group) else others).append(name)
    if not groups and "x" in others and set(others) <= {"x", "t"}:  # x stacked at the root
        if dt is None and "t" not in others:
            raise MetriplexError(
                f"{where} holds `x` at its root and no times `t`: for evenly spaced samples pass "
                "--dt STEP (read(path, dt=STEP) in Python), or store `t` beside `x`.")
        table = stacked_table({k: np.asarray(f[k][()]) for k in others}, where, dt)
        t = table["t"] if dt is None else uniform_times(table["trajectory"], dt)
        names = _h5_names(f, where) if "names" in f.attrs else ()
        return _build(path, "HDF5", table["trajectory"], t, table["x"], names)
    if others:
        raise MetriplexError(
            f"{where} holds {sorted(others)} at its root, which are not trajectory groups; the "
            f"layout is {_HDF5_LAYOUT}, or datasets `x` (K, T, n) and `t` (T,) alone at the "
            "root. Move each trajectory's `t` and `x` into its own group (metriplex.write("
            "\"file.h5\", data) writes this layout), or name the root datasets `x` and `t`."
        )
    if not groups:
        raise MetriplexError(
            f"{where} holds no groups, so no trajectories; the layout is {_HDF5_LAYOUT}."
        )
    version = f.attrs.get("format_version")
    if _text(f.attrs.get("format", b"")) == FORMAT_NAME and version is not None:
        if int(np.asarray(version).reshape(-1)[0]) > HDF5_FORMAT_VERSION:
            raise MetriplexError(
                f"{where} has format_version {version}; this metriplex reads version "
                f"{HDF5_FORMAT_VERSION}. Upgrade metriplex."
            )
    groups.sort(key=natural_key)
    names = _h5_names(f, where) if "names" in f.attrs else None
    names_from = "the root"
    ts, xs, ids = [], [], []
    for g_name in groups:
        g = f[g_name]
        gw = f"group {g_name!r} of {where}"
        members = sorted(g)
        extra = [m for m in members if m not in ("t", "x")]
        missing = [m for m in ("t", "x") if m not in members and (dt is None or m != "t")]
        if missing:
            raise MetriplexError(
                f"{gw} lacks the dataset(s) {missing}; it holds {members or 'nothing'}. Each "
                f"trajectory group needs `t` (T,) and `x` (T, n)."
            )
        if extra:
            raise MetriplexError(
                f"{gw} holds unknown member(s) {extra} besides `t` and `x`. Remove them, or "
                "store them as attributes; a trajectory group holds exactly `t` and `x`."
            )
        x = _h5_array(g, "x", gw)
        if dt is None:
            t = _vector(_h5_array(g, "t", gw), "dataset `t`", gw)
        else:
            t = np.arange(len(x)) * dt
        if x.ndim == 1:
            x = x[:, None]
        if dt is None and x.ndim == 2 and x.shape[1] == len(t) != x.shape[0]:
            x = x.T  # stored variables x times: the times say which axis is which
        if x.ndim != 2 or x.shape[0] != len(t):
            raise MetriplexError(
                f"dataset `x` in {gw} has shape {x.shape}; with {len(t)} times in `t` it must be "
                f"({len(t)}, n), one row per time (or (n, {len(t)}))."
            )
        if xs and x.shape[1] != xs[0].shape[1]:
            raise MetriplexError(
                f"every trajectory needs the same number of state variables; in {where} group "
                f"{groups[0]!r} has {xs[0].shape[1]} and group {g_name!r} has {x.shape[1]} "
                "columns in `x`."
            )
        if "names" in g.attrs:
            g_names = _h5_names(g, gw)
            if names is not None and g_names != names:
                raise MetriplexError(
                    f"the variable names of {gw} ({g_names}) differ from those of {names_from} "
                    f"({names}); give every trajectory the same names, or set them once on the "
                    "root."
                )
            if names is None:
                names, names_from = g_names, f"group {g_name!r}"
        tid = g.attrs.get("trajectory")
        ids.append(None if tid is None else _h5_id(tid, gw))
        ts.append(t)
        xs.append(x)
    if all(i is not None for i in ids):
        uniq, counts = np.unique(ids, return_counts=True)
        dup = uniq[counts > 1].tolist()
        if dup:
            raise MetriplexError(
                f"in {where}, several groups carry the same `trajectory` id attribute {dup}; "
                "ids must be unique. Renumber them or delete the attributes (groups are then "
                "numbered in natural order)."
            )
    else:
        ids = list(range(len(groups)))
    traj = np.concatenate([np.full(len(t), i, dtype=np.int64) for i, t in zip(ids, ts)])
    return _build(path, "HDF5", traj, np.concatenate(ts), np.concatenate(xs), names or ())


def _h5_array(g, name: str, where: str) -> np.ndarray:
    import h5py

    ds = g[name]
    if not isinstance(ds, h5py.Dataset):
        raise MetriplexError(
            f"`{name}` in {where} is a group; it must be a numeric dataset."
        )
    return _real(ds[()], f"dataset `{name}`", where)


def _h5_names(obj, where: str) -> list[str]:
    raw = obj.attrs["names"]
    a = np.asarray(raw)
    if a.dtype.kind not in "USO":
        raise MetriplexError(
            f"attribute `names` of {where} must hold strings; got {a.dtype} values {a!r:.80}."
        )
    return [_text(s) for s in a.reshape(-1)]


def _h5_id(v, where: str) -> int:
    a = np.asarray(v)
    if a.size != 1 or a.dtype.kind not in "iuf" or float(a.reshape(-1)[0]) != int(a.reshape(-1)[0]):
        raise MetriplexError(
            f"attribute `trajectory` of {where} must be one integer id; got {a!r:.80}."
        )
    return int(a.reshape(-1)[0])


def write_hdf5(path: str | os.PathLike, data: Trajectories) -> None:
    """Write ``data`` as HDF5, one group per trajectory (atomically)."""
    import h5py

    # Rows are sorted by trajectory id (Trajectories guarantees it), so each is one slice.
    ids, starts = np.unique(data.trajectory, return_index=True)
    stops = [*starts[1:], len(data.trajectory)]
    width = max(len(str(i)) for i in ids)
    with atomic_write(path, "w+b") as fh:
        with h5py.File(fh, "w") as f:
            f.attrs["format"] = FORMAT_NAME
            f.attrs["format_version"] = HDF5_FORMAT_VERSION
            f.attrs["names"] = np.array(data.names, dtype=h5py.string_dtype())
            for i, a, b in zip(ids.tolist(), starts, stops):
                g = f.create_group(f"trajectory_{i:0{width}d}")
                g.attrs["trajectory"] = np.int64(i)
                g.create_dataset("t", data=data.t[a:b])
                g.create_dataset("x", data=data.x[a:b])
