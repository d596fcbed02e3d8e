"""MATLAB files loaded into plain values, for :mod:`metriplex.io._mat` to check: v4 to v7 through
:func:`scipy.io.loadmat`, v7.3 (HDF5, arrays stored column-major) through ``h5py``. Structs
become dicts, sparse matrices dense arrays, and a class metriplex does not read an
:class:`~metriplex.io._checks._Unsupported` that the checks name. Nothing is unpickled.
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

import numpy as np

from .._errors import MetriplexError
from ._checks import _h5_reason, _q, _text, _Unsupported


def _sparse_arrays() -> dict[str, bool]:
    """``loadmat``'s ``spmatrix=False`` where SciPy has the choice (sparse arrays, the default
    from SciPy 1.20, which warns of the change before): both kinds are read dense alike."""
    import inspect

    import scipy.io

    has_choice = "spmatrix" in inspect.signature(scipy.io.loadmat).parameters
    return {"spmatrix": False} if has_choice else {}


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
                verify_compressed_data_integrity=True, **_sparse_arrays(),
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
