"""Model files: :data:`MAGIC`, a JSON header on one line (format version, library version,
``n``, variable names, dtype, the architecture's spec, extra fields), then the model's leaves
as written by ``equinox.tree_serialise_leaves``. Loading reads numbers only and never executes
code (no pickle); the header's fields, the weights' dtype and their finiteness are checked.
"""

from __future__ import annotations

import io as _io
import json
import os
from pathlib import Path
from typing import Any, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np

from .._errors import MetriplexError
from .._model import GenericModel, float_dtype, weights, with_dtype
from .._version import __version__
from ._files import atomic_write

MAGIC = b"METRIPLEX-MODEL\n"
FORMAT_VERSION = 1


def save(path: str | os.PathLike, model: GenericModel, *, n: int,
         names: Sequence[str] = (), extra: dict[str, Any] | None = None) -> None:
    """Write ``model`` as a JSON header + Equinox leaves (atomic; no pickle), replacing a file
    at ``path`` as ``numpy.save`` does (the command line refuses that without
    ``--overwrite``). ``n``: its number of state variables; ``names``: none, or one string per
    variable; ``extra``: fields kept in the header (strict JSON). Checked before anything is
    written, as :func:`load` checks."""
    _check_saveable(path, model, n, names)
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
    try:
        line = json.dumps(header, allow_nan=False)
    except (TypeError, ValueError) as e:
        raise MetriplexError(
            f"cannot save the model: its extra fields are not strict JSON ({e}). Give numbers, "
            "strings, lists and dicts of them, without NaN or infinity."
        ) from None
    buf = _io.BytesIO()
    buf.write(MAGIC)
    buf.write(line.encode() + b"\n")
    eqx.tree_serialise_leaves(buf, model)
    with atomic_write(path, "wb") as f:
        f.write(buf.getvalue())


def _check_saveable(path, model, n, names) -> None:
    """Refuse a model file that :func:`load` would refuse, before writing it."""
    if not isinstance(model, GenericModel):
        raise MetriplexError(
            f"save writes a GenericModel (or a ground-truth system's .model); got "
            f"{type(model).__name__}."
        )
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise MetriplexError(f"save needs n, the number of state variables, >= 1; got {n!r}.")
    size = model.size()
    if size is not None and size != n:
        raise MetriplexError(
            f"save got n={n}, but the model has {size} state variables; pass n={size}."
        )
    names = list(names)
    if names and (len(names) != n or not all(isinstance(v, str) for v in names)):
        raise MetriplexError(
            f"save's names must be empty or {n} strings, one per variable; got {names!r}."
        )
    if Path(path).is_dir():
        raise MetriplexError(
            f"cannot save the model to {str(path)!r}: it is a folder; give a file name such as "
            f"{str(Path(path) / 'model.mpx')!r}."
        )


def read_header(path: str | os.PathLike) -> dict[str, Any]:
    """The header of a model file (or of a run folder's ``model.mpx``), checked as
    :func:`load` checks it; the weights are not read."""
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
        data = Path(path).suffix.lower() in (".npz", ".csv", ".h5", ".hdf5", ".mat")
        raise MetriplexError(
            f"{str(path)!r} is not a metriplex model file (wrong magic bytes); it may be "
            "corrupted or of another format." + (
                " Its name is that of a data file: the commands take the run folder (or "
                "model file) first and the data second, e.g. `metriplex evaluate RUN DATA`."
                if data else "")
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
    leaves = weights(model)
    total = sum(int(np.size(a)) for a in leaves)
    bad = sum(int(np.size(a) - np.count_nonzero(np.isfinite(np.asarray(a)))) for a in leaves)
    if bad:
        raise MetriplexError(
            f"model file {str(path)!r} holds {bad} non-finite weights (NaN or infinite) of "
            f"{total}; such a model gives NaN everywhere and cannot be evaluated or rolled out. "
            "It was saved from a training that diverged, or the file is damaged: re-train (for "
            "example with a lower --lr)."
        )
