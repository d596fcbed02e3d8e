"""The checks that several readers share: a value read from a file as a float64 array, a
vector or a list of names, or a :class:`MetriplexError` that names the value, the file and the
fix; and the :class:`Trajectories` built from what was read, with the file named in its errors.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import scipy.sparse

from .._errors import MetriplexError
from ..data import Trajectories


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


class _Unsupported:
    def __init__(self, cls: str) -> None:
        self.cls = cls

    def __repr__(self):
        return self.cls


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
    if scipy.sparse.issparse(v):  # a MATLAB sparse matrix
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
            "Convert it to a numeric (double) array" + (
                "; trajectories of different lengths cannot be one array: store the long "
                "table instead, `trajectory` and `t` (one entry per sample) and `x` (samples × "
                "variables)" if a.dtype == object else "") + "."
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


def _h5_reason(e: Exception) -> str:
    msg = str(e).strip() or type(e).__name__
    return msg if len(msg) < 200 else msg[:200] + "..."


#: The names a file's time step goes by (a scalar, or one per trajectory in .mat files).
STEP_KEYS = ("dt", "Dt", "DT", "delta_t")


def file_step(arrays: dict, where: str) -> tuple[str | None, float | None]:
    """``(name, value)`` of the one scalar time step among ``arrays`` (named one of
    :data:`STEP_KEYS`), ``(None, None)`` where there is none; refused where it is not one
    positive finite number, or where two names give one."""
    keys = [k for k in STEP_KEYS if k in arrays]
    if not keys:
        return None, None
    if len(keys) > 1:
        raise MetriplexError(f"{where} holds the time steps {keys}; keep one of them.")
    raw = np.asarray(arrays[keys[0]])
    if raw.size != 1 or raw.dtype.kind not in "iuf" or not np.isfinite(raw).all() \
            or float(raw.reshape(-1)[0]) <= 0:
        raise MetriplexError(
            f"time step `{keys[0]}` of {where} must be one positive finite number; got "
            f"{_describe(raw)} {raw.reshape(-1)[:5].tolist()}. Save the step as a number "
            "(np.savez(..., dt=0.1)), or remove it and pass --dt STEP.")
    return keys[0], float(raw.reshape(-1)[0])


def steps_agree(t: np.ndarray, trajectory: np.ndarray, step: float, name: str,
                where: str) -> None:
    """Refuse times ``t`` (one per row of ``trajectory``) whose steps differ from the file's
    ``step`` (named ``name``) beyond 0.1 %: one of the two is wrong."""
    same = trajectory[1:] == trajectory[:-1]
    steps = np.diff(np.asarray(t, np.float64))[same]
    bad = np.flatnonzero(np.abs(steps - step) > 1e-3 * step)
    if len(bad):
        raise MetriplexError(
            f"time step `{name}`={step!r} of {where} disagrees with its times `t`, which step by "
            f"{float(steps[bad[0]])!r} at row {int(np.flatnonzero(same)[bad[0]]) + 1}. Remove the "
            "wrong one, or pass --dt STEP to use the grid t = k*STEP instead of both.")


def stacked_table(arrays: dict, where: str, dt: float | None) -> dict[str, np.ndarray]:
    """The long table (``trajectory``, ``x`` and, without ``dt``, ``t``) of ``arrays`` that hold
    ``x`` stacked, without ``trajectory``: ``(T, n)`` is one trajectory, ``(K, T, n)`` K of
    them, with ``t`` of ``(T,)`` (shared) or ``(K, T)`` (unless ``dt`` replaces it); for the
    NPZ and HDF5 readers."""
    x = arrays["x"]
    if x.ndim not in (2, 3):
        raise MetriplexError(
            f"array `x` of {where} is {x.ndim}-D {x.shape}; without `trajectory` it must be one "
            "trajectory (T, n) or trajectories x snapshots x variables (K, T, n).")
    xs = x[None] if x.ndim == 2 else x
    K, T, n = xs.shape
    out = {"trajectory": np.repeat(np.arange(K), T), "x": xs.reshape(K * T, n)}
    if dt is None:
        t = np.asarray(arrays["t"])
        if t.shape not in ((T,), (K, T)):
            raise MetriplexError(
                f"array `t` of {where} is {t.shape}, but `x` {x.shape} has {T} snapshots per "
                f"trajectory: give t of ({T},) (shared) or ({K}, {T}), or `trajectory` (N,) "
                "beside t and x of one row per sample (the long table).")
        out["t"] = np.broadcast_to(t, (K, T)).reshape(-1)
        back = np.flatnonzero(np.diff(t.reshape(-1, T), axis=1) <= 0) if x.ndim == 2 else []
        if len(back):  # a long table without its ids, not one trajectory
            raise MetriplexError(
                f"{where} lacks the array `trajectory`: without it `t` and `x` {x.shape} are one "
                f"trajectory, but t does not increase at row {back[0] + 1} ({t[back[0] + 1]!r} "
                f"after {t[back[0]]!r}). Give `trajectory` (N,), the id of each row's "
                f"trajectory (the long table). Found {sorted(arrays)}.")
    return out
