r"""Trajectory files besides the native long table: HDF5 and MATLAB ``.mat``.

Both hold the same observations as the long table of docs/design.md, 'Trajectory data' (rows
of ``trajectory``, ``t``, ``x``), laid out the way users of those formats already store them.

**HDF5** (``.h5``, ``.hdf5``), read and written::

    /                      attrs: names (n strings), format, format_version
    /trajectory_0          attrs: trajectory (int id, optional)
        t                  (T_0,)    strictly increasing times
        x                  (T_0, n)  states
    /trajectory_1 ...      any group names; trajectories may have different lengths

Groups are read in natural order (``run2`` before ``run10``). The integer attribute
``trajectory`` on every group gives the ids; without it on all groups, ids are ``0, 1, ...`` in
that order. ``names`` may sit on the root or on each group (they must then agree); without it
the variables are called ``x0, x1, ...``.

**MATLAB** (``.mat``, v4/v5/v7 via :func:`scipy.io.loadmat`, v7.3 via ``h5py``), read in two
layouts; shapes are MATLAB's ``size()``:

1. *Snapshots* — the layout of the published structure-preserving-network (SPNN) datasets
   (``Z``, ``t_vec``, ``dt``, ``L``, ``M``): one array of trajectories × variables × snapshots,
   ``(K, n, T)``, or variables × snapshots ``(n, T)`` for one trajectory, named one of
   ``Z, z, X, x, data, states``. Times come from a vector named one of
   ``t_vec, tvec, t, time, times, ts`` — shared ``(T,)``/``(1, T)``/``(T, 1)`` or per trajectory
   ``(K, T)`` — or from a step named one of ``dt, Dt, DT, delta_t`` (scalar, or ``(K,)`` per
   trajectory; times are then ``0, dt, 2 dt, ...``). With both, the vector is used and the step
   must match its spacing (to 0.1 %). ``dt=STEP`` (the command line's ``--dt``) replaces all of
   these by ``0, STEP, 2 STEP, ...``: for a file without times, or whose time vector does not
   fit its snapshots (e.g. 1 × 150 for 300 snapshots). Optional: ``trajectory_ids`` ``(K,)``;
   constant operators ``L`` and ``M`` ``(n, n)``, dense or sparse (see
   :func:`read_mat_operators`).
2. *Long table* — the layout of docs/design.md, 'Trajectory data': ``trajectory`` ``(N,)``,
   ``t`` ``(N,)``, ``x`` ``(N, n)``; ragged lengths allowed (with ``dt``, ``t`` is not read).

In both, variable names are an optional cell array of strings (or a char matrix) named one of
``names, var_names, variables, labels``. When the file's top level holds none of these
variables but exactly one struct, its fields are read instead (``data.Z``, ``data.dt``, ...).
:func:`write_mat` writes the snapshot layout when all trajectories have the same length and the
long table otherwise, so both round-trip exactly.

Every reader checks the file against these rules and raises :class:`MetriplexError` naming the
rule, the value found and the fix; no h5py, SciPy or NumPy traceback reaches the user. Loading
never unpickles or runs code from the file.
"""

from __future__ import annotations

import os
import re
import warnings
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from ._errors import MetriplexError
from .data import Trajectories, uniform_times

FORMAT_NAME = "metriplex-trajectories"
HDF5_FORMAT_VERSION = 1

STATE_KEYS = ("Z", "z", "X", "x", "data", "states")
TIME_KEYS = ("t_vec", "tvec", "t", "time", "times", "ts")
STEP_KEYS = ("dt", "Dt", "DT", "delta_t")
NAME_KEYS = ("names", "var_names", "variables", "labels")
OPERATOR_KEYS = ("L", "M")

_HDF5_LAYOUT = (
    "one group per trajectory holding datasets `t` (T,) and `x` (T, n), variable names in an "
    "attribute `names`"
)


# -- shared helpers ---------------------------------------------------------------------------

def _q(path) -> str:
    return repr(str(path))


def _check_file(path, kind: str) -> Path:
    path = Path(path)
    if not path.is_file():
        what = "is a folder" if path.is_dir() else "does not exist"
        raise MetriplexError(f"{kind} file {_q(path)} {what}; give the path of a data file.")
    if path.stat().st_size == 0:
        raise MetriplexError(
            f"{kind} file {_q(path)} is empty (0 bytes); it holds no trajectories."
        )
    return path


def natural_key(name: str) -> tuple:
    """Sort key that orders embedded numbers by value: ``run2`` before ``run10``."""
    parts = re.split(r"(\d+)", name)
    # re.split puts text at even and digits at odd positions, so the tuples always compare.
    return tuple(int(p) if i % 2 else p.lower() for i, p in enumerate(parts)) + (name,)


def _build(path, kind: str, trajectory, t, x, names) -> Trajectories:
    """Trajectories from the arrays read, with the file named in any error it raises."""
    try:
        return Trajectories(trajectory, t, x, tuple(names))
    except MetriplexError as e:
        raise MetriplexError(f"{kind} file {_q(path)}: {e}") from None


def _shape(a) -> str:
    return "×".join(str(s) for s in np.shape(a)) or "scalar"


def _describe(v) -> str:
    if isinstance(v, dict):
        return f"struct with fields {', '.join(v) or '(none)'}"
    if isinstance(v, np.ndarray):
        kinds = {"f": "numeric", "i": "integer", "u": "integer", "b": "logical", "c": "complex",
                 "U": "char", "S": "char", "O": "cell", "V": "struct array"}
        return f"{kinds.get(v.dtype.kind, str(v.dtype))} {_shape(v)}"
    return type(v).__name__


def _found(variables: dict) -> str:
    if not variables:
        return "no variables at all"
    return "; ".join(f"{k} ({_describe(v)})" for k, v in variables.items())


def _real(v, what: str, where: str) -> np.ndarray:
    """``v`` as a float64 array, or an error saying what it is instead."""
    if isinstance(v, dict):
        raise MetriplexError(
            f"{what} in {where} is a struct; it must be a numeric array. Store the numbers "
            "themselves under that name."
        )
    if isinstance(v, _Unsupported):
        raise MetriplexError(
            f"{what} in {where} is a {v.cls}, which metriplex does not read; store it as a "
            "plain double array."
        )
    if hasattr(v, "toarray"):  # a MATLAB sparse matrix
        v = v.toarray()
    a = np.asarray(v)
    if a.dtype.kind == "c":
        raise MetriplexError(
            f"{what} in {where} holds complex numbers ({_shape(a)}); states and times must be "
            "real. Store the real part (or real and imaginary parts as separate variables)."
        )
    if a.dtype.kind not in "fiu":
        raise MetriplexError(
            f"{what} in {where} must hold numbers; it is {_describe(a)} (dtype {a.dtype}). "
            "Convert it to a numeric (double) array."
        )
    if a.size == 0:
        raise MetriplexError(f"{what} in {where} is empty ({_shape(a)}); it holds no values.")
    return a.astype(np.float64)


def _vector(a: np.ndarray, what: str, where: str, length: int | None = None) -> np.ndarray:
    """A row, column or 1-D array as 1-D; anything else is an error."""
    if sum(s != 1 for s in a.shape) > 1:
        raise MetriplexError(
            f"{what} in {where} must be a vector; it is {_shape(a)}. Store it as one row or "
            "one column."
        )
    a = a.reshape(-1)
    if length is not None and len(a) != length:
        raise MetriplexError(
            f"{what} in {where} has {len(a)} entries; {length} are needed (one per "
            f"{'row' if what != 'names' else 'variable'})."
        )
    return a


def _strings(v, what: str, where: str) -> list[str]:
    """Variable names from a cell array of strings, a char matrix, or an array of str/bytes."""
    if isinstance(v, dict):
        raise MetriplexError(
            f"{what} in {where} is a struct; it must be a list (cell array) of strings."
        )
    a = np.asarray(v)
    if a.dtype.kind in "US":
        # A MATLAB char matrix pads its rows with spaces; a cell array would keep them.
        return [_text(s).rstrip(" ") for s in a.reshape(-1)]
    if a.dtype.kind == "O":
        out = []
        for s in a.reshape(-1):
            s = np.asarray(s)
            if s.dtype.kind not in "US" or s.size > 1:
                raise MetriplexError(
                    f"{what} in {where} must hold one string per variable; entry {len(out)} is "
                    f"{_describe(s)}. Store the names as a cell array of char vectors."
                )
            out.append(_text(s.reshape(-1)[0]) if s.size else "")
        return out
    raise MetriplexError(
        f"{what} in {where} must be strings (a cell array of char vectors); it is "
        f"{_describe(a)}."
    )


def _text(s) -> str:
    return s.decode("utf-8") if isinstance(s, bytes) else str(s)


# -- HDF5 -------------------------------------------------------------------------------------

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


def _h5_reason(e: Exception) -> str:
    msg = str(e).strip() or type(e).__name__
    return msg if len(msg) < 200 else msg[:200] + "..."


def _read_hdf5(f, path: Path, dt: float | None = None) -> Trajectories:
    import h5py

    where = f"HDF5 file {_q(path)}"
    groups, others = [], []
    for name in f:
        (groups if isinstance(f.get(name), h5py.Group) else others).append(name)
    if others:
        raise MetriplexError(
            f"{where} holds {sorted(others)} at its root, which are not trajectory groups; the "
            f"layout is {_HDF5_LAYOUT}. Move each trajectory's `t` and `x` into its own group "
            "(metriplex.write(\"file.h5\", data) writes this layout)."
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
        if x.ndim != 2 or x.shape[0] != len(t):
            hint = (
                " It looks transposed: write x.T." if x.ndim == 2 and x.shape[1] == len(t) else ""
            )
            raise MetriplexError(
                f"dataset `x` in {gw} has shape {x.shape}; with {len(t)} times in `t` it must be "
                f"({len(t)}, n), one row per time.{hint}"
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

    from .io import atomic_write

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


# -- MATLAB -----------------------------------------------------------------------------------

def read_mat(
    path: str | os.PathLike,
    *,
    states: str | None = None,
    time: str | None = None,
    dt: float | None = None,
) -> Trajectories:
    """Read trajectories from a MATLAB ``.mat`` file (layouts in this module's docstring).

    ``states`` and ``time`` name the variables to use when the file's names are not among the
    accepted ones or are ambiguous. ``dt`` gives every trajectory the uniform grid
    ``t = k * dt`` instead of the file's times, which are then not read: for a file that stores
    none, or a time vector that does not fit the snapshots (the command line's ``--dt``).

    ```python
    data = mx.read("database_double_pendulum.mat")
    data = read_mat("sim.mat", states="Y", time="tout")
    ```
    """
    path = _check_file(path, "MAT")
    scope, where = _mat_scope(_load_mat(path), path, states)
    traj, t, x, names = _mat_table(scope, where, states=states, time=time, dt=dt)
    return _build(path, "MAT", traj, t, x, names)


def read_mat_operators(
    path: str | os.PathLike, *, states: str | None = None
) -> dict[str, np.ndarray]:
    r"""The constant GENERIC operators stored beside the data: ``{"L": (n, n), "M": (n, n)}``.

    Published SPNN datasets store the Poisson matrix ``L`` and friction matrix ``M`` of
    :math:`\dot z = L\nabla E + M\nabla S`. Keys are present only for the operators in the
    file; the dict is empty when there are none. Shapes are checked against the state array.

    ```python
    ops = read_mat_operators("database_double_pendulum.mat")
    L = ops.get("L")
    ```
    """
    path = _check_file(path, "MAT")
    scope, where = _mat_scope(_load_mat(path), path, states)
    _, _, x, _ = _mat_table(scope, where, states=states, time=None, dt=1.0)
    n = x.shape[1]
    out = {}
    for key in OPERATOR_KEYS:
        if key not in scope:
            continue
        a = _real(scope[key], f"operator `{key}`", where)
        if a.shape != (n, n):
            raise MetriplexError(
                f"operator `{key}` in {where} is {_shape(a)}; with {n} state variables it must "
                f"be {n}×{n}."
            )
        if not np.all(np.isfinite(a)):
            raise MetriplexError(
                f"operator `{key}` in {where} holds NaN or inf; it must be finite."
            )
        out[key] = a
    return out


def write_mat(
    path: str | os.PathLike,
    data: Trajectories,
    *,
    L: np.ndarray | None = None,
    M: np.ndarray | None = None,
) -> None:
    """Write ``data`` as a MATLAB v5 ``.mat`` file (atomically).

    Equal-length trajectories are written in the SPNN snapshot layout — ``Z`` (K, n, T),
    ``t_vec`` (1, T) when all share one grid (plus ``dt`` when it is uniform) or ``t`` (K, T)
    otherwise — so MATLAB scripts and SPNN code can read them; ragged ones as the long table.
    Both carry ``names`` (cell array) and are read back exactly by :func:`read_mat`.
    """
    import scipy.io

    from .io import atomic_write

    out: dict[str, Any] = {"names": np.array(list(data.names), dtype=object).reshape(1, -1)}
    lengths = data.lengths()
    if np.all(lengths == lengths[0]):
        # Rows are sorted by trajectory id (Trajectories guarantees it): reshape, no copy loop.
        K, T = len(lengths), int(lengths[0])
        ts, xs = data.t.reshape(K, T), data.x.reshape(K, T, data.n)
        out["Z"] = np.ascontiguousarray(xs.transpose(0, 2, 1))
        out["trajectory_ids"] = data.ids.astype(np.float64).reshape(1, -1)
        if np.all(ts == ts[0]):
            out["t_vec"] = ts[:1]
            steps = np.diff(ts[0])
            if np.all(np.abs(steps - steps.mean()) <= 1e-12 * abs(steps.mean())):
                out["dt"] = np.array([[steps.mean()]])
        else:
            out["t"] = ts
    else:
        out["trajectory"] = data.trajectory.astype(np.float64).reshape(-1, 1)
        out["t"] = data.t.reshape(-1, 1)
        out["x"] = data.x
    n = data.n
    for key, op in (("L", L), ("M", M)):
        if op is not None:
            op = np.asarray(op, dtype=np.float64)
            if op.shape != (n, n):
                raise MetriplexError(
                    f"operator `{key}` must be {n}×{n} for {n} state variables; got "
                    f"{_shape(op)}."
                )
            out[key] = op
    with atomic_write(path, "wb") as f:
        scipy.io.savemat(f, out, format="5", do_compression=True, oned_as="row")


def _load_mat(path: Path) -> dict[str, Any]:
    import h5py

    if h5py.is_hdf5(path):
        with open(path, "rb") as fh:
            if not fh.read(6) == b"MATLAB":
                raise MetriplexError(
                    f"{_q(path)} is an HDF5 file without MATLAB's v7.3 header, so its arrays "
                    "cannot be told apart from MATLAB's transposed ones. Give it the suffix .h5 "
                    "(one group per trajectory) or save it from MATLAB with -v7.3."
                )
        return _load_mat73(path)
    import scipy.io
    from scipy.io.matlab import MatReadWarning

    try:
        with warnings.catch_warnings():
            # scipy warns (and carries on) on some damaged files; treat that as damage.
            warnings.simplefilter("error", MatReadWarning)
            raw = scipy.io.loadmat(
                path, squeeze_me=False, chars_as_strings=True, struct_as_record=True,
                verify_compressed_data_integrity=True,
            )
    except NotImplementedError as e:
        raise MetriplexError(f"MAT file {_q(path)} uses an unsupported format ({e}).") from None
    except Exception as e:  # scipy raises many types on damaged files
        raise MetriplexError(
            f"{_q(path)} is not a readable MATLAB file ({type(e).__name__}: "
            f"{_h5_reason(e)}). It may be truncated or of another format; re-save it in MATLAB "
            "with save(..., '-v7') or '-v7.3'."
        ) from None
    return {k: _from_v5(v) for k, v in raw.items() if not k.startswith("__")}


def _from_v5(v):
    """scipy's view of a MATLAB value, with 1×1 structs turned into dicts."""
    if isinstance(v, np.ndarray) and v.dtype.names and v.size == 1:
        rec = v.reshape(-1)[0]
        return {name: _from_v5(rec[name]) for name in v.dtype.names}
    return v


def _load_mat73(path: Path) -> dict[str, Any]:
    """A v7.3 MAT file is HDF5 with arrays stored column-major: reversed axes, tagged classes."""
    import h5py

    try:
        with h5py.File(path, "r") as f:
            return {k: _from_h5mat(f[k], f) for k in f if not k.startswith("#")}
    except MetriplexError:
        raise
    except (OSError, KeyError, ValueError, TypeError, RuntimeError) as e:
        raise MetriplexError(
            f"MATLAB v7.3 (HDF5) file {_q(path)} is damaged: reading it failed "
            f"({_h5_reason(e)}). It may be truncated; re-save it in MATLAB."
        ) from None


class _Unsupported:
    def __init__(self, cls: str):
        self.cls = cls

    def __repr__(self):
        return self.cls


def _from_h5mat(obj, f):
    import h5py

    cls = _text(obj.attrs.get("MATLAB_class", b""))
    if isinstance(obj, h5py.Group):
        if "MATLAB_sparse" in obj.attrs:
            return _h5mat_sparse(obj)
        if cls not in ("", "struct"):
            return _Unsupported(f"MATLAB {cls} object")
        return {k: _from_h5mat(obj[k], f) for k in obj if not k.startswith("#")}
    if obj.attrs.get("MATLAB_empty", 0):
        return np.zeros((0,))
    raw = obj[()]
    if cls == "cell":
        refs = np.asarray(raw).T
        out = np.empty(refs.shape, dtype=object)
        for idx in np.ndindex(refs.shape):
            out[idx] = _from_h5mat(f[refs[idx]], f)
        return out
    a = np.asarray(raw)
    if a.dtype.names and set(a.dtype.names) == {"real", "imag"}:
        a = a["real"] + 1j * a["imag"]
    a = a.T
    if cls == "char":
        rows = a.reshape(a.shape[0], -1) if a.ndim else a.reshape(1, 1)
        return np.array(["".join(map(chr, r)) for r in rows])
    if cls == "logical":
        return a.astype(bool)
    if cls in ("", "double", "single") or cls.startswith(("int", "uint")):
        return a
    return _Unsupported(f"MATLAB {cls}")


def _h5mat_sparse(g):
    """A v7.3 sparse matrix: compressed sparse columns ``data``, ``ir``, ``jc``."""
    jc = np.asarray(g["jc"][()], dtype=np.int64).reshape(-1)
    rows, cols = int(np.asarray(g.attrs["MATLAB_sparse"]).reshape(-1)[0]), len(jc) - 1
    out = np.zeros((rows, cols))
    if "data" in g:
        ir = np.asarray(g["ir"][()], dtype=np.int64).reshape(-1)
        data = np.asarray(g["data"][()]).reshape(-1)
        col = np.repeat(np.arange(cols), np.diff(jc))
        out[ir, col] = data
    return out


def _mat_scope(variables: dict, path: Path, states: str | None) -> tuple[dict, str]:
    """The variables holding the data: the top level, or the fields of its only struct."""
    where = f"MAT file {_q(path)}"
    if not variables:
        raise MetriplexError(f"{where} holds no variables; it holds no trajectories.")
    wanted = (states,) if states else STATE_KEYS + ("trajectory",)
    if any(k in variables and not isinstance(variables[k], dict) for k in wanted):
        return variables, where
    structs = [k for k, v in variables.items() if isinstance(v, dict)]
    if len(structs) == 1:
        return variables[structs[0]], f"struct `{structs[0]}` of {where}"
    return variables, where


def _pick(
    scope: dict, keys: Sequence[str], override: str | None, what: str, where: str,
    option: str | None = None,
):
    """The one variable among ``keys`` present in ``scope`` (or ``override``), or None.

    ``option`` is the read_mat keyword that names the variable, suggested when several are
    present.
    """
    if override is not None:
        if override not in scope:
            raise MetriplexError(
                f"{where} has no variable {override!r} (asked for as {what}); it holds "
                f"{_found(scope)}."
            )
        return override
    present = [k for k in keys if k in scope and not isinstance(scope[k], dict)]
    if len(present) > 1:
        fix = (
            f"Name the one to use, e.g. read_mat(path, {option}={present[0]!r})."
            if option else "Rename or remove all but one."
        )
        raise MetriplexError(f"{where} holds several candidates for {what}: {present}. {fix}")
    return present[0] if present else None


def _mat_table(scope: dict, where: str, *, states, time, dt):
    """``(trajectory, t, x, names)`` rows from the variables of a MAT file."""
    names_key = _pick(scope, NAME_KEYS, None, "the variable names", where)
    names = _strings(scope[names_key], f"`{names_key}`", where) if names_key else []
    if states is None and "trajectory" in scope:
        return (*_mat_long_table(scope, where, dt), names)
    key = _pick(scope, STATE_KEYS, states, "the state array", where, "states")
    if key is None:
        raise MetriplexError(
            f"{where} holds no state array: expected a trajectories × variables × snapshots "
            f"array named one of {', '.join(STATE_KEYS)} (or the long table `trajectory`, `t`, "
            f"`x`); it holds {_found(scope)}. Rename the variable or pass "
            "read_mat(path, states='NAME')."
        )
    Z = _real(scope[key], f"state array `{key}`", where)
    if Z.ndim == 2:
        Z = Z[None]
    if Z.ndim != 3:
        raise MetriplexError(
            f"state array `{key}` in {where} is {_shape(Z)}; it must be trajectories × "
            "variables × snapshots (K×n×T), or variables × snapshots (n×T) for one trajectory."
        )
    K, n, T = Z.shape
    t = _mat_times(scope, where, key, Z.shape, time=time, dt=dt)
    ids = np.arange(K, dtype=np.float64)
    if "trajectory_ids" in scope:
        ids = _vector(_real(scope["trajectory_ids"], "`trajectory_ids`", where),
                      "`trajectory_ids`", where, K)
    traj = np.repeat(ids, T)
    x = Z.transpose(0, 2, 1).reshape(K * T, n)
    if names and len(names) != n:
        raise MetriplexError(
            f"`{names_key}` in {where} lists {len(names)} names {names} but state array `{key}` "
            f"has {n} variables (its second dimension); give one name per variable."
        )
    return traj, t.reshape(-1), x, names


#: The way out when a file's times do not fit its states, in the words of both front ends.
DT_FIX = ("pass --dt STEP on the command line (read(path, dt=STEP) or read_mat(path, dt=STEP) "
          "in Python) to use the uniform grid t = k*STEP instead of the file's times")


def _mat_times(scope, where, key, shape, *, time, dt):
    K, n, T = shape
    if dt is not None:  # replaces whatever times the file holds, which are not read
        if time is not None:
            raise MetriplexError(
                f"time={time!r} names the time vector of {where} and dt={dt!r} replaces the "
                "file's times by a uniform grid; got both. Give one of them."
            )
        step = float(dt)
        if not np.isfinite(step) or step <= 0:
            raise MetriplexError(f"dt must be positive and finite; got {dt!r}.")
        return np.broadcast_to(step * np.arange(T), (K, T))
    t_key = _pick(scope, TIME_KEYS, time, "the time vector", where, "time")
    step_key = _pick(scope, STEP_KEYS, None, "the time step", where)
    step = None
    if step_key is not None:
        step = _vector(_real(scope[step_key], f"time step `{step_key}`", where),
                       f"time step `{step_key}`", where)
        if len(step) not in (1, K):
            raise MetriplexError(
                f"time step `{step_key}` in {where} has {len(step)} entries; give one step, or "
                f"one per trajectory ({K})."
            )
        if not np.all(np.isfinite(step)) or np.any(step <= 0):
            raise MetriplexError(
                f"time step `{step_key}` in {where} must be positive and finite; got "
                f"{step.tolist()[:5]}."
            )
    if t_key is None:
        if step is None:
            raise MetriplexError(
                f"{where} gives no times for state array `{key}`: expected a time vector named "
                f"one of {', '.join(TIME_KEYS)} or a time step named one of "
                f"{', '.join(STEP_KEYS)}; it holds {_found(scope)}. Add one, or {DT_FIX}."
            )
        return np.broadcast_to(step.reshape(-1, 1) * np.arange(T), (K, T))
    tv = _real(scope[t_key], f"time vector `{t_key}`", where)
    if tv.size == T and sum(s != 1 for s in tv.shape) <= 1:
        t = np.broadcast_to(tv.reshape(1, T), (K, T))
    elif tv.shape == (K, T):
        t = tv
    else:
        hint = ""
        if tv.size in (n, K * n) or (tv.ndim == 2 and tv.shape[-1] == n):
            hint = (
                f" Its length matches the second dimension of `{key}`: if `{key}` is stored as "
                "trajectories × snapshots × variables, permute it to trajectories × variables "
                "× snapshots (permute(Z, [1 3 2]) in MATLAB)."
            )
        raise MetriplexError(
            f"time vector `{t_key}` in {where} is {_shape(tv)}; state array `{key}` "
            f"({K}×{n}×{T}) has {T} snapshots, so it must have {T} entries (shared) or be "
            f"{K}×{T} (one row per trajectory).{hint} If the snapshots are evenly spaced, "
            f"{DT_FIX}."
        )
    if step is not None and T > 1:
        steps = np.diff(t, axis=1)
        expect = np.broadcast_to(step.reshape(-1, 1), steps.shape)
        bad = np.abs(steps - expect) > 1e-3 * np.abs(expect)
        if np.all(np.isfinite(steps)) and np.any(bad):
            k, j = np.argwhere(bad)[0]
            raise MetriplexError(
                f"time step `{step_key}`={float(expect[k, j])!r} in {where} disagrees with time "
                f"vector `{t_key}`, whose step {j} in trajectory {k} is {float(steps[k, j])!r}. "
                "Remove the wrong one (the time vector is used when both are present), or "
                f"{DT_FIX}."
            )
    return t


def _mat_long_table(scope: dict, where: str, dt: float | None = None):
    missing = [k for k in ("t", "x") if k not in scope and (dt is None or k != "t")]
    if missing:
        raise MetriplexError(
            f"{where} holds `trajectory`, so it is read as the long table, which needs "
            f"`trajectory` (N), `t` (N) and `x` (N×n); `{'`, `'.join(missing)}` is missing. It "
            f"holds {_found(scope)}."
        )
    traj = _real(scope["trajectory"], "`trajectory`", where)
    traj = _vector(traj, "`trajectory`", where)
    if dt is None:
        t = _vector(_real(scope["t"], "`t`", where), "`t`", where, len(traj))
    else:
        t = uniform_times(traj, dt)
    x = _real(scope["x"], "`x`", where)
    if x.ndim == 1 or (x.shape == (1, len(traj)) and len(traj) > 1):
        x = x.reshape(-1, 1)  # one variable stored as a row vector
    if x.ndim != 2 or x.shape[0] != len(traj):
        hint = " It looks transposed: store x.'." if x.ndim == 2 and x.shape[1] == len(traj) else ""
        raise MetriplexError(
            f"`x` in {where} is {_shape(x)}; with {len(traj)} rows in `trajectory` it must be "
            f"{len(traj)}×n, one row per observed state.{hint}"
        )
    return traj, t, x


READERS = {".h5": read_hdf5, ".hdf5": read_hdf5, ".mat": read_mat}
WRITERS = {".h5": write_hdf5, ".hdf5": write_hdf5, ".mat": write_mat}
