"""Training checkpoints: a JSON header (step, history, ...) + Equinox leaves, written atomically."""

from __future__ import annotations

import io as _io
import json
import os
from pathlib import Path
from typing import Any

import equinox as eqx

from ._errors import MetriplexError

MAGIC = b"METRIPLEX-CHECKPOINT\n"


def save(path: str | os.PathLike, tree: Any, meta: dict) -> None:
    from .io._files import _json_default, atomic_write

    buf = _io.BytesIO()
    buf.write(MAGIC)
    buf.write(json.dumps(meta, default=_json_default).encode() + b"\n")
    eqx.tree_serialise_leaves(buf, tree)
    with atomic_write(path, "wb") as f:
        f.write(buf.getvalue())


def read_meta(path: str | os.PathLike) -> dict:
    """The JSON header of the checkpoint at ``path`` (its step ``done``, ``history``, ...),
    without its arrays; ``OSError`` or ``ValueError`` where it cannot be read as one."""
    with open(path, "rb") as f:
        if f.read(len(MAGIC)) != MAGIC:
            raise ValueError(f"{str(path)!r} is not a metriplex checkpoint (bad magic bytes)")
        meta = json.loads(f.readline())
    if not isinstance(meta, dict):
        raise ValueError(f"{str(path)!r} has no checkpoint header")
    return meta


def load(path: str | os.PathLike, like: Any) -> tuple[Any, dict]:
    path = Path(path)
    if not path.exists():
        raise MetriplexError(
            f"no checkpoint at {str(path)!r}; nothing to resume. Start without resuming "
            "(Checkpoint(..., resume=False); on the command line, without --resume)."
        )
    with open(path, "rb") as f:
        if f.read(len(MAGIC)) != MAGIC:
            raise MetriplexError(f"{str(path)!r} is not a metriplex checkpoint (bad magic bytes).")
        try:
            meta = json.loads(f.readline())
            tree = eqx.tree_deserialise_leaves(f, like)
        except Exception as e:
            raise MetriplexError(
                f"checkpoint {str(path)!r} is corrupted or was written for another model or "
                f"optimiser ({type(e).__name__}: {e}). Resume with the same configuration, or "
                "start afresh."
            ) from None
    return tree, meta
