"""Reading and writing trajectories and model files.

Trajectories: the long table (docs/design.md, 'Trajectory data') in NPZ or CSV; also read from
and written to HDF5 (one group per trajectory) and MATLAB ``.mat`` (see ``_formats``). Model files are a
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
import secrets
from pathlib import Path
from typing import Any, Iterator

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np

from ._errors import MetriplexError
from ._model import GenericModel, float_dtype, with_dtype
from .data import Trajectories, check_time_step, uniform_times

MAGIC = b"METRIPLEX-MODEL\n"
FORMAT_VERSION = 1


@contextlib.contextmanager
def atomic_write(path: str | os.PathLike, mode: str = "wb") -> Iterator[Any]:
    """Open a temporary file beside ``path``; rename it over ``path`` only on success."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = _create_temporary(path)
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


def _create_temporary(path: Path) -> tuple[int, str]:
    """A new file beside ``path`` created with mode 0666, so that the user's umask (and a
    folder's default ACL) applies as to any file they write: ``tempfile.mkstemp`` would give
    0600, and the renamed result would be unreadable to the user's group."""
    for _ in range(100):
        tmp = str(path.parent / f".{path.name}.{secrets.token_hex(4)}.tmp")
        try:
            return os.open(tmp, os.O_RDWR | os.O_CREAT | os.O_EXCL | getattr(os, "O_BINARY", 0),
                           0o666), tmp
        except FileExistsError:
            continue
    raise FileExistsError(f"cannot create a temporary file beside {str(path)!r}")


def write_json(path, obj) -> None:
    """Strict JSON (what every reader accepts): a NaN or infinite number is written as ``null``;
    the file that holds it says why (e.g. ``rollout_failures`` beside a null error)."""
    with atomic_write(path, "w") as f:
        json.dump(_strict(obj), f, indent=2, default=_json_default, allow_nan=False)
        f.write("\n")


def _strict(o):
    if isinstance(o, dict):
        return {k: _strict(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_strict(v) for v in o]
    if isinstance(o, (np.ndarray, jax.Array)):
        return _strict(np.asarray(o).tolist())
    if isinstance(o, (float, np.floating)) and not np.isfinite(o):
        return None
    return o


def _json_default(o):
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, (np.floating,)):
        return float(o)
    if isinstance(o, (np.ndarray, jax.Array)):
        return np.asarray(o).tolist()
    raise TypeError(f"not JSON-serialisable: {type(o).__name__}")


# -- trajectories -----------------------------------------------------------------------------

def read(path: str | os.PathLike, *, dt: float | None = None) -> Trajectories:
    """Read trajectories: the long table (``.npz``, ``.csv``), HDF5 (``.h5``, ``.hdf5``) or MATLAB
    (``.mat``). Layouts: docs/design.md, 'Trajectory data', and :mod:`metriplex._formats`.

    ``dt``: give every trajectory the uniform time grid ``t = k * dt`` (``k = 0, 1, ...`` in the
    file's order of its samples) instead of the file's own times, which are then not read (a
    file may lack them, or hold a time vector that does not fit its snapshots). The command
    line's ``--dt``.

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
    readers = _readers()
    if suffix not in readers:
        raise MetriplexError(
            f"cannot read {str(path)!r}: unknown extension {suffix!r}. Supported: "
            f"{', '.join(sorted(readers))}."
        )
    try:
        return readers[suffix](path) if dt is None else readers[suffix](path, dt=dt)
    except MetriplexError as e:
        if str(path) in str(e):
            raise
        raise MetriplexError(f"data file {str(path)!r}: {e}") from None


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
    if suffix == ".npz":
        buf = _io.BytesIO()
        np.savez(buf, trajectory=data.trajectory, t=data.t, x=data.x, names=np.array(data.names))
        with atomic_write(path, "wb") as f:
            f.write(buf.getvalue())
        return
    if suffix == ".csv":
        for name in data.names:
            if name != name.strip() or not name:
                raise MetriplexError(
                    f"cannot write {str(path)!r}: variable name {name!r} has surrounding "
                    "whitespace, which CSV readers strip, so it would not read back. Rename it "
                    "(data.with_names([...])) or write .npz."
                )
        with atomic_write(path, "w") as f:
            csv.writer(f, lineterminator="\n").writerow(["trajectory", "t", *data.names])
            # repr gives the shortest decimal that parses back to the same float64; numbers
            # never need CSV quoting, so rows are joined directly (10x faster than csv.writer).
            f.writelines(
                f"{i},{t!r},{','.join(map(repr, x))}\n"
                for i, t, x in zip(data.trajectory.tolist(), data.t.tolist(), data.x.tolist())
            )
        return
    writers = _writers()
    if suffix not in writers:
        raise MetriplexError(
            f"cannot write {str(path)!r}: unknown extension {suffix!r}. Trajectories are written "
            f"as {', '.join(sorted({'.npz', '.csv', *writers}))}."
        )
    writers[suffix](path, data)


def _writers() -> dict:
    with contextlib.suppress(ImportError):
        from . import _formats

        return dict(_formats.WRITERS)
    return {}


def trajectory_suffixes() -> tuple[str, ...]:
    """The file extensions :func:`write` writes trajectories as."""
    return tuple(sorted({".npz", ".csv", *_writers()}))


# -- outputs, checked before any work --------------------------------------------------------

def _check_writable_folder(folder: Path, target: Path, option: str) -> None:
    """``folder`` (which may not exist yet) can be created and written in."""
    existing = folder
    while not existing.exists() and existing.parent != existing:
        existing = existing.parent
    if not existing.is_dir():
        raise MetriplexError(
            f"cannot write {option} {str(target)!r}: {str(existing)!r} is a file, not a folder. "
            f"Choose another {option}."
        )
    kw = {"effective_ids": True} if os.access in os.supports_effective_ids else {}
    if not os.access(existing, os.W_OK | os.X_OK, **kw):
        raise MetriplexError(
            f"cannot write {option} {str(target)!r}: the folder {str(existing)!r} is not writable "
            f"(permission denied or a read-only file system). Choose another {option}, or make "
            "that folder writable."
        )


def check_output_file(path: str | os.PathLike, *, overwrite: bool = False, option: str = "--out",
                      suffixes: tuple[str, ...] | None = None) -> Path:
    """Fail now, before any work, if the file ``path`` could not be written at the end: it is a
    folder, exists (without ``overwrite``), has an extension not in ``suffixes``, or its folder
    is not writable."""
    path = Path(path)
    if path.is_dir():
        raise MetriplexError(
            f"{option} {str(path)!r} is a folder; {option} takes a file name (such as "
            f"{str(path / ('out' + (suffixes[0] if suffixes else '.json')))!r})."
        )
    if path.exists() and not overwrite:
        raise MetriplexError(
            f"output file {str(path)!r} exists; refusing to overwrite it. Pass --overwrite or "
            f"choose another {option}."
        )
    if suffixes is not None and path.suffix.lower() not in suffixes:
        raise MetriplexError(
            f"cannot write {str(path)!r}: unknown extension {path.suffix.lower() or '(none)'!r}. "
            f"Trajectories are written as {', '.join(suffixes)}."
        )
    _check_writable_folder(path.parent, path, option)
    return path


def check_output_folder(path: str | os.PathLike, option: str = "--out") -> Path:
    """Fail now, before any work, if the folder ``path`` could not be created or written in."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise MetriplexError(
            f"{option} {str(path)!r} is a file, not a folder; {option} names a folder to write "
            "into. Choose another path."
        )
    _check_writable_folder(path, path, option)
    return path


def _readers():
    readers = {".npz": read_npz, ".csv": read_csv}
    with contextlib.suppress(ImportError):
        from . import _formats

        readers.update(_formats.READERS)
    return readers


def read_npz(path: Path, *, dt: float | None = None) -> Trajectories:
    """The long table from NPZ: ``trajectory`` (N,), ``t`` (N,), ``x`` (N, n), ``names`` (n,);
    with ``dt``, ``t`` may be left out and is replaced by ``k * dt`` (see :func:`read`)."""
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
            arrays = _npz_arrays(z, where, need_t=dt is None)
    names = ()
    if "names" in arrays:
        raw = arrays["names"]
        if raw.dtype.kind not in "US":
            raise MetriplexError(
                f"array `names` of {where} must hold strings; it holds {raw.dtype} values "
                f"{raw.reshape(-1)[:5].tolist()}. Save np.array(names, dtype=str)."
            )
        names = tuple(s.decode() if isinstance(s, bytes) else str(s) for s in raw.reshape(-1))
    t = arrays["t"] if dt is None else uniform_times(arrays["trajectory"], dt)
    try:
        return Trajectories(arrays["trajectory"], t, arrays["x"], names)
    except MetriplexError as e:
        raise MetriplexError(f"{where}: {e}") from None


def _npz_arrays(z, where: str, need_t: bool = True) -> dict[str, np.ndarray]:
    found = sorted(z.files)
    missing = [k for k in ("trajectory", "t", "x") if k not in found and (need_t or k != "t")]
    if missing:
        raise MetriplexError(
            f"{where} lacks the array(s) {missing}; the long table needs `trajectory` (N,), "
            f"`t` (N,) and `x` (N, n), optionally `names` (n,). Found {found}."
        )
    unknown = [k for k in found if k not in ("trajectory", "t", "x", "names")]
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


def read_csv(path: Path, *, dt: float | None = None) -> Trajectories:
    """The long table from CSV: header ``trajectory,t,<name_1>,...``, one row per state; with
    ``dt``, the ``t`` column is replaced by ``k * dt`` (see :func:`read`)."""
    import warnings

    path = Path(path)
    where = f"CSV file {str(path)!r}"

    def check_header(row: list[str]) -> list[str]:
        header = [c.strip() for c in row]
        if len(header) < 3 or header[0] != "trajectory" or header[1] != "t":
            hint = ""
            with contextlib.suppress(ValueError):
                [float(c) for c in header]
                hint = " The first line holds numbers: the header line is missing."
            raise MetriplexError(
                f"{where} must start with the header `trajectory,t,<name_1>,...` (at least one "
                f"state column); got {','.join(header)!r}.{hint} Add, rename or reorder the "
                "columns."
            )
        names = header[2:]
        for k, name in enumerate(names):
            if not name:
                raise MetriplexError(
                    f"{where}: header column {k + 3} has no name; every state column needs one."
                )
            if name in names[:k]:
                raise MetriplexError(
                    f"{where}: header column {k + 3} repeats the variable name {name!r}; names "
                    "must be unique."
                )
        return header

    def build(arr: np.ndarray, header: list[str]) -> Trajectories:
        t = arr[:, 1] if dt is None else uniform_times(arr[:, 0], dt)
        try:
            return Trajectories(arr[:, 0], t, arr[:, 2:], tuple(header[2:]))
        except MetriplexError as e:
            raise MetriplexError(f"{where}: {e}") from None

    # Fast path: NumPy's C parser (correctly rounded, as float() is) reads a clean body at once.
    # Whatever it rejects (quoted cells included: they may hide a truncated quote) is read again
    # line by line below, to say exactly what and where.
    first = arr = None
    with contextlib.suppress(Exception):
        with open(path, newline="", encoding="utf-8-sig") as f:
            reader = csv.reader(f, strict=True)
            first = next((r for r in reader if r and any(c.strip() for c in r)), None)
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # "input contained no data"
                arr = np.loadtxt(
                    f, delimiter=",", comments=None, dtype=np.float64, ndmin=2
                )
    if (
        first is not None
        and arr is not None
        and arr.shape[0] > 0
        and arr.shape[1] == len(first)
        and np.all(np.isfinite(arr))
        and np.all(arr[:, 0] == np.round(arr[:, 0]))
    ):
        return build(arr, check_header(first))

    rows, lines = [], []
    try:
        with open(path, newline="", encoding="utf-8-sig") as f:
            reader = csv.reader(f, strict=True)
            for r in reader:
                if r and any(c.strip() for c in r):
                    rows.append(r)
                    lines.append(reader.line_num)
    except UnicodeDecodeError as e:
        raise MetriplexError(
            f"{where} is not UTF-8 text (byte {e.start} cannot be decoded); it may be binary or "
            "another format. Save it as UTF-8 CSV."
        ) from None
    except csv.Error as e:
        raise MetriplexError(
            f"{where} is not valid CSV ({e}); it may be truncated. Save it again as plain CSV."
        ) from None
    if not rows:
        raise MetriplexError(f"{where} is empty; it holds no header and no rows.")
    header = check_header(rows[0])
    body, body_lines = rows[1:], lines[1:]
    if not body:
        raise MetriplexError(f"{where} has a header but no data rows.")
    width = len(header)
    for r, line in zip(body, body_lines):
        if len(r) != width:
            raise MetriplexError(
                f"{where}, line {line}, has {len(r)} columns; the header has {width}. Every row "
                "needs `trajectory`, `t` and one value per state variable (a short last line "
                "means a truncated file)."
            )
    arr = np.empty((len(body), width))
    for k, (r, line) in enumerate(zip(body, body_lines)):
        for j, (name, c) in enumerate(zip(header, r)):
            try:
                arr[k, j] = v = float(c)
            except ValueError:
                v = None
            if j == 1 and dt is not None:  # the file's times are not used
                arr[k, j] = 0.0
                continue
            if v is None or v != v or v in (float("inf"), float("-inf")):
                what = "is empty" if not c.strip() else f"holds {c.strip()!r}"
                raise MetriplexError(
                    f"{where}, line {line}, column {name!r} {what}; every cell must be a "
                    "finite number. Fix or remove that row (interpolate missing samples)."
                )
    bad = np.flatnonzero(arr[:, 0] != np.round(arr[:, 0]))
    if len(bad):
        raise MetriplexError(
            f"{where}, line {body_lines[bad[0]]}: trajectory id {body[bad[0]][0].strip()!r} is "
            "not an integer; ids label trajectories 0, 1, 2, ..."
        )
    return build(arr, header)


# -- model files ------------------------------------------------------------------------------

def save(path: str | os.PathLike, model: GenericModel, *, n: int, names=(), extra=None) -> None:
    """Write ``model`` as a JSON header + Equinox leaves (atomic; no pickle)."""
    from ._version import __version__

    header = {
        "format": "metriplex-model",
        "format_version": FORMAT_VERSION,
        "library_version": __version__,
        "n": int(n),
        "names": list(names),
        "dtype": str(float_dtype(model, default=jnp.float32)),
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
    if not isinstance(header, dict):
        raise MetriplexError(
            f"the header of model file {str(path)!r} is corrupted: a JSON object is needed, got "
            f"{type(header).__name__}. Re-save or re-train the model."
        )
    version = header.get("format_version")
    if version != FORMAT_VERSION:
        raise MetriplexError(
            f"model file {str(path)!r} has format version {version!r}; this metriplex reads "
            f"version {FORMAT_VERSION}. Re-train or use the metriplex version that wrote it "
            f"({header.get('library_version', 'unknown')})."
        )
    _check_header(header, path)
    return header


#: Floating-point types a model file may hold.
MODEL_DTYPES = ("float32", "float64")


def _check_header(header: dict[str, Any], path) -> None:
    """The fields that :func:`load` needs, each with the type it needs."""

    def bad(field: str, rule: str) -> MetriplexError:
        got = "it is missing" if field not in header else f"got {header[field]!r}"
        return MetriplexError(
            f"the header of model file {str(path)!r} is damaged: field {field!r} must be "
            f"{rule}; {got}. Re-save the model with metriplex.save, or re-train it."
        )

    n = header.get("n")
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise bad("n", "the number of state variables, a positive integer")
    names = header.get("names", [])
    if not isinstance(names, list) or not all(isinstance(v, str) for v in names) or (
        names and len(names) != n
    ):
        raise bad("names", f"a list of {n} variable names (or empty)")
    if header.get("dtype", "float32") not in MODEL_DTYPES:
        raise bad("dtype", " or ".join(repr(d) for d in MODEL_DTYPES))
    spec = header.get("model")
    blocks = ("energy", "entropy", "poisson", "friction")
    if not isinstance(spec, dict) or not all(isinstance(spec.get(b), dict) for b in blocks):
        raise bad("model", "the architecture: an object with the blocks " + ", ".join(blocks))


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
                f"model file {str(path)!r} holds float64 weights, which JAX reads only with "
                "x64 enabled: call `jax.config.update('jax_enable_x64', True)` before creating "
                "any array (the metriplex command line does this itself)."
            )
        try:
            # Shapes and dtypes only: building the networks' random initial weights for real
            # costs seconds of small compilations, and the file's weights replace them anyway.
            like = eqx.filter_eval_shape(
                lambda: with_dtype(
                    GenericModel.from_spec(header["model"], header["n"], key=jr.key(0)), dtype)
            )
        except MetriplexError as e:
            raise MetriplexError(f"model file {str(path)!r}: {e}") from None
        except (KeyError, TypeError, ValueError) as e:
            raise MetriplexError(
                f"the header of model file {str(path)!r} describes no model this metriplex can "
                f"build ({type(e).__name__}: {e}). Re-save the model with metriplex.save, or "
                "re-train it."
            ) from None
        try:
            model = eqx.tree_deserialise_leaves(f, like)
        except Exception as e:
            raise MetriplexError(
                f"model file {str(path)!r} is truncated or corrupted: its weights do not match "
                f"its header ({type(e).__name__}). Re-save or re-train the model."
            ) from None
        extra = len(f.read())
        if extra:
            raise MetriplexError(
                f"model file {str(path)!r} is corrupted: {extra} bytes follow the weights that "
                "its header describes. Re-save or re-train the model."
            )
    _check_finite_weights(model, path)
    return model


def _check_finite_weights(model: GenericModel, path) -> None:
    """A model with a NaN or infinite weight gives NaN everywhere: refuse it at once."""
    leaves = jax.tree_util.tree_leaves(eqx.filter(model, eqx.is_inexact_array))
    total = sum(int(np.size(a)) for a in leaves)
    bad = sum(int(np.size(a) - np.count_nonzero(np.isfinite(np.asarray(a)))) for a in leaves)
    if bad:
        raise MetriplexError(
            f"model file {str(path)!r} holds {bad} non-finite weights (NaN or infinite) of "
            f"{total}; such a model gives NaN everywhere and cannot be evaluated or rolled out. "
            "It was saved from a training that diverged, or the file is damaged: re-train (for "
            "example with a lower --lr)."
        )
