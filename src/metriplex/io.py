"""Reading and writing trajectories and model files.

Trajectories use the long table of DESIGN.md §2 in NPZ (native) or CSV. Model files are a
JSON header followed by ``equinox.tree_serialise_leaves`` bytes: loading reads numbers only and
never executes code (no pickle). Every file is written atomically: to a temporary file in the
same folder, then renamed, so an interrupted write never leaves a half-written file behind.
"""

from __future__ import annotations

import contextlib
import csv
import io as _io
import json
import os
import tempfile
from pathlib import Path
from typing import Any, Iterator

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np

from ._errors import MetriplexError
from ._model import GenericModel
from .data import Trajectories

MAGIC = b"METRIPLEX-MODEL\n"
FORMAT_VERSION = 1


@contextlib.contextmanager
def atomic_write(path: str | os.PathLike, mode: str = "wb") -> Iterator[Any]:
    """Open a temporary file beside ``path``; rename it over ``path`` only on success."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, mode) as f:
            yield f
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def write_json(path, obj) -> None:
    with atomic_write(path, "w") as f:
        json.dump(obj, f, indent=2, default=_json_default)
        f.write("\n")


def _json_default(o):
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, (np.floating,)):
        return float(o)
    if isinstance(o, (np.ndarray, jax.Array)):
        return np.asarray(o).tolist()
    raise TypeError(f"not JSON-serialisable: {type(o).__name__}")


# -- trajectories -----------------------------------------------------------------------------

def read(path: str | os.PathLike) -> Trajectories:
    """Read trajectories from ``.npz`` or ``.csv`` (long table); HDF5 and ``.mat`` if available.

    ```python
    data = mx.read("data.npz")
    ```
    """
    path = Path(path)
    if not path.exists():
        raise MetriplexError(f"data file {str(path)!r} does not exist; check the path.")
    if path.is_dir():
        raise MetriplexError(f"{str(path)!r} is a folder; give a data file (.npz, .csv, ...).")
    if path.stat().st_size == 0:
        raise MetriplexError(f"data file {str(path)!r} is empty; it holds no trajectories.")
    suffix = path.suffix.lower()
    readers = _readers()
    if suffix not in readers:
        raise MetriplexError(
            f"cannot read {str(path)!r}: unknown extension {suffix!r}. Supported: "
            f"{', '.join(sorted(readers))}."
        )
    return readers[suffix](path)


def write(path: str | os.PathLike, data: Trajectories) -> None:
    """Write trajectories as the long table (``.npz`` or ``.csv``), atomically."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix == ".npz":
        buf = _io.BytesIO()
        np.savez(buf, trajectory=data.trajectory, t=data.t, x=data.x, names=np.array(data.names))
        with atomic_write(path, "wb") as f:
            f.write(buf.getvalue())
    elif suffix == ".csv":
        with atomic_write(path, "w") as f:
            w = csv.writer(f, lineterminator="\n")
            w.writerow(["trajectory", "t", *data.names])
            for i, t, x in zip(data.trajectory, data.t, data.x):
                w.writerow([int(i), repr(float(t)), *(repr(float(v)) for v in x)])
    else:
        raise MetriplexError(
            f"cannot write {str(path)!r}: trajectories are written as .npz or .csv; got "
            f"{suffix!r}."
        )


def _readers():
    readers = {".npz": read_npz, ".csv": read_csv}
    with contextlib.suppress(ImportError):
        from . import _formats

        readers.update(_formats.READERS)
    return readers


def read_npz(path: Path) -> Trajectories:
    try:
        z = np.load(path, allow_pickle=False)
    except Exception as e:  # zipfile/format errors differ by numpy version
        raise MetriplexError(f"{str(path)!r} is not a readable NPZ file ({e}).") from None
    with z:
        missing = [k for k in ("trajectory", "t", "x") if k not in z.files]
        if missing:
            raise MetriplexError(
                f"NPZ file {str(path)!r} lacks the array(s) {missing}; the long table needs "
                "`trajectory` (N,), `t` (N,) and `x` (N, n), optionally `names` (n,). Found "
                f"{sorted(z.files)}."
            )
        names = tuple(str(s) for s in z["names"]) if "names" in z.files else ()
        return Trajectories(z["trajectory"], z["t"], z["x"], names)


def read_csv(path: Path) -> Trajectories:
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    rows = [r for r in rows if r and any(c.strip() for c in r)]
    if not rows:
        raise MetriplexError(f"CSV file {str(path)!r} is empty; it holds no header and no rows.")
    header = [c.strip() for c in rows[0]]
    if len(header) < 3 or header[0] != "trajectory" or header[1] != "t":
        raise MetriplexError(
            f"CSV file {str(path)!r} must start with the header `trajectory,t,<name_1>,...`; got "
            f"{','.join(header)!r}. Rename the columns or reorder them."
        )
    body = rows[1:]
    if not body:
        raise MetriplexError(f"CSV file {str(path)!r} has a header but no data rows.")
    width = len(header)
    for k, r in enumerate(body):
        if len(r) != width:
            raise MetriplexError(
                f"CSV row {k + 2} of {str(path)!r} has {len(r)} columns; the header has {width}. "
                "Every row needs `trajectory`, `t` and one value per state variable."
            )
    try:
        arr = np.array([[float(c) for c in r] for r in body])
    except ValueError as e:
        raise MetriplexError(f"CSV file {str(path)!r} holds a non-numeric value ({e}).") from None
    return Trajectories(arr[:, 0], arr[:, 1], arr[:, 2:], tuple(header[2:]))


# -- model files ------------------------------------------------------------------------------

def _dtype_of(model) -> str:
    leaves = jax.tree_util.tree_leaves(eqx.filter(model, eqx.is_inexact_array))
    return str(leaves[0].dtype) if leaves else "float32"


def save(path: str | os.PathLike, model: GenericModel, *, n: int, names=(), extra=None) -> None:
    """Write ``model`` as a JSON header + Equinox leaves (atomic; no pickle)."""
    from . import __version__

    header = {
        "format": "metriplex-model",
        "format_version": FORMAT_VERSION,
        "library_version": __version__,
        "n": int(n),
        "names": list(names),
        "dtype": _dtype_of(model),
        "model": model.spec(),
        "extra": extra or {},
    }
    buf = _io.BytesIO()
    buf.write(MAGIC)
    buf.write(json.dumps(header).encode() + b"\n")
    eqx.tree_serialise_leaves(buf, model)
    with atomic_write(path, "wb") as f:
        f.write(buf.getvalue())


def read_header(path: str | os.PathLike) -> dict[str, Any]:
    path = _model_path(path)
    with open(path, "rb") as f:
        return _header(f, path)


def _model_path(path) -> Path:
    path = Path(path)
    if path.is_dir():
        path = path / "model.mpx"
    if not path.exists():
        raise MetriplexError(
            f"model file {str(path)!r} does not exist; give a run folder made by `metriplex "
            "train` or a .mpx model file."
        )
    return path


def _header(f, path) -> dict[str, Any]:
    if f.read(len(MAGIC)) != MAGIC:
        raise MetriplexError(
            f"{str(path)!r} is not a metriplex model file (wrong magic bytes); it may be "
            "corrupted or of another format."
        )
    line = f.readline()
    try:
        header = json.loads(line)
    except (json.JSONDecodeError, UnicodeDecodeError):
        raise MetriplexError(
            f"the header of model file {str(path)!r} is corrupted (not valid JSON)."
        ) from None
    version = header.get("format_version")
    if version != FORMAT_VERSION:
        raise MetriplexError(
            f"model file {str(path)!r} has format version {version!r}; this metriplex reads "
            f"version {FORMAT_VERSION}. Re-train or use the metriplex version that wrote it "
            f"({header.get('library_version', 'unknown')})."
        )
    return header


def load(path: str | os.PathLike) -> GenericModel:
    """Load a model from a model file or a run folder; nothing but numbers is read.

    ```python
    model = mx.load("runs/pendulum")
    ```
    """
    path = _model_path(path)
    with open(path, "rb") as f:
        header = _header(f, path)
        dtype = jnp.dtype(header.get("dtype", "float32"))
        if dtype == jnp.float64 and not jax.config.jax_enable_x64:
            raise MetriplexError(
                f"model file {str(path)!r} holds float64 weights; enable them first with "
                "`jax.config.update('jax_enable_x64', True)`."
            )
        like = GenericModel.from_spec(header["model"], header["n"], key=jr.key(0))
        like = jax.tree_util.tree_map(
            lambda a: a.astype(dtype) if eqx.is_inexact_array(a) else a, like
        )
        try:
            return eqx.tree_deserialise_leaves(f, like)
        except Exception as e:
            raise MetriplexError(
                f"model file {str(path)!r} is truncated or corrupted: its weights do not match "
                f"its header ({type(e).__name__}). Re-save or re-train the model."
            ) from None
