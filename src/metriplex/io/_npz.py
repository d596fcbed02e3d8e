"""The long table as NPZ, the native format: arrays ``trajectory`` (N,), ``t`` (N,), ``x``
(N, n) and optionally ``names`` (n,) (docs/design.md, 'Trajectory data'). Without
``trajectory``, ``x`` may also be stacked: one trajectory ``(T, n)`` or trajectories ×
snapshots × variables ``(K, T, n)``, with ``t`` of ``(T,)`` or ``(K, T)``. A scalar time step
(``dt``, ``Dt``, ``DT`` or ``delta_t``) may replace ``t`` (times ``0, dt, 2 dt, ...``) or stand
beside it (then it must match its steps). Nothing is unpickled.
"""

from __future__ import annotations

import io as _io
import os
from pathlib import Path

import numpy as np

from .._errors import MetriplexError
from ..data import Trajectories, uniform_times
from ._checks import STEP_KEYS, _shape, file_step, stacked_table, steps_agree
from ._files import atomic_write


def read_npz(path: Path, *, dt: float | None = None) -> Trajectories:
    """The long table from NPZ: ``trajectory`` (N,), ``t`` (N,), ``x`` (N, n), ``names`` (n,);
    with ``dt``, ``t`` may be left out and is replaced by ``k * dt`` (see
    :func:`metriplex.io.read`)."""
    path = Path(path)
    where = f"NPZ file {str(path)!r}"
    # Our own handle: np.load leaks the one it opens when the archive is unreadable.
    with open(path, "rb") as fh:
        try:
            z = np.load(fh, allow_pickle=False)
        except Exception as e:  # zipfile/format errors differ by numpy version
            raise MetriplexError(
                f"{str(path)!r} is not a readable NPZ file ({type(e).__name__}: {e}). It may be "
                "truncated or of another format; write it with metriplex.write or numpy.savez."
            ) from None
        if not isinstance(z, np.lib.npyio.NpzFile):
            raise MetriplexError(
                f"{str(path)!r} holds one bare array of shape {z.shape}, not an NPZ archive; the "
                "long table needs named arrays: np.savez(path, trajectory=..., t=..., x=..., "
                "names=...)."
            )
        with z:
            arrays = _npz_arrays(z, where, need_t=dt is None and not set(STEP_KEYS) & set(z.files))
    step_key, step = file_step(arrays, where)
    if dt is None and step is not None and "t" not in arrays:
        dt = step  # the file's own step: times 0, dt, 2 dt, ...
    names = ()
    if "names" in arrays:
        raw = arrays["names"]
        if raw.dtype.kind not in "US":
            raise MetriplexError(
                f"array `names` of {where} must hold strings; it holds {raw.dtype} values "
                f"{raw.reshape(-1)[:5].tolist()}. Save np.array(names, dtype=str)."
            )
        names = tuple(s.decode() if isinstance(s, bytes) else str(s) for s in raw.reshape(-1))
    if "trajectory" not in arrays:
        arrays.update(stacked_table(arrays, where, dt))
    t = arrays["t"] if dt is None else uniform_times(arrays["trajectory"], dt)
    if step is not None and dt is None:
        steps_agree(np.asarray(t).reshape(-1), np.asarray(arrays["trajectory"]).reshape(-1),
                    step, step_key, where)
    try:
        return Trajectories(arrays["trajectory"], t, arrays["x"], names)
    except MetriplexError as e:
        raise MetriplexError(f"{where}: {e}") from None


def _npz_arrays(z, where: str, need_t: bool = True) -> dict[str, np.ndarray]:
    found = sorted(z.files)
    # Without `trajectory`: one trajectory of x (T, n), or trajectories of x (K, T, n).
    optional = {"trajectory"} if "x" in found else set()
    missing = [k for k in ("trajectory", "t", "x")
               if k not in found and (need_t or k != "t") and k not in optional]
    if missing:
        raise MetriplexError(
            f"{where} lacks the array(s) {missing}; the long table needs `trajectory` (N,), "
            f"`t` (N,) and `x` (N, n), optionally `names` (n,). Found {found}."
            + (" For evenly spaced samples without times, save the step beside `x` (dt=STEP) "
               "or pass --dt STEP (read(path, dt=STEP) in Python)." if missing == ["t"] else "")
            + (_states_hint(z, found) if "x" in missing else "")
        )
    unknown = [k for k in found if k not in ("trajectory", "t", "x", "names", *STEP_KEYS)]
    if unknown:
        raise MetriplexError(
            f"{where} holds unknown array(s) {unknown}; the long table holds only "
            "`trajectory`, `t`, `x` and `names`. If they are state variables, make them "
            "columns of `x`; otherwise remove them."
        )
    arrays = {}
    for k in found:
        try:
            arrays[k] = z[k]
        except Exception as e:
            if isinstance(e, ValueError) and "allow_pickle" in str(e):
                raise MetriplexError(
                    f"array `{k}` of {where} is stored as Python objects (pickle), which "
                    "metriplex never loads because unpickling runs code. Save it as numbers, "
                    "or names as strings: np.array(names, dtype=str)."
                ) from None
            raise MetriplexError(
                f"array `{k}` of {where} is damaged ({type(e).__name__}: {e}); the file may be "
                "truncated. Write it again."
            ) from None
    return arrays


def _states_hint(z, found: list[str]) -> str:
    """Where ``x`` is missing: the stacked layouts, and the arrays that may hold the states."""
    def shape(k):
        try:  # the header alone: a pickled or damaged array is reported when it is read
            return z[k].shape if z[k].dtype.kind in "iuf" else None
        except Exception:
            return None
    maybe = [(k, sh) for k in found if k not in ("t", "trajectory")
             and (sh := shape(k)) is not None and len(sh) in (2, 3)]
    return (" Without `trajectory`, `x` may also be stacked: one trajectory (T, n) or "
            "trajectories x snapshots x variables (K, T, n), with `t` (T,) or a step `dt`"
            + (f"; {', '.join(f'`{k}` {_shape(np.empty(sh))}' for k, sh in maybe)} may hold "
               f"the states: save it as `x` (z = np.load(path); np.savez(new_path, "
               f"x=z['{maybe[0][0]}'], ...))" if maybe else "") + ".")


def write_npz(path: str | os.PathLike, data: Trajectories) -> None:
    """Write ``data`` as the long table in NPZ (atomically)."""
    buf = _io.BytesIO()
    np.savez(buf, trajectory=data.trajectory, t=data.t, x=data.x, names=np.array(data.names))
    with atomic_write(path, "wb") as f:
        f.write(buf.getvalue())
