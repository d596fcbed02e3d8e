"""Files written safely: atomic writes, strict JSON, and output paths checked before any work.

Every file metriplex writes goes through :func:`atomic_write`: to a temporary file in the same
folder, then renamed, so an interrupted write never leaves a half-written file behind. The
commands check their outputs with :func:`check_output_file` and :func:`check_output_folder`
before any work, so that a long run does not fail at its end for want of a writable path.
"""

from __future__ import annotations

import contextlib
import json
import os
import secrets
import tempfile
from pathlib import Path
from typing import Any, Iterator

import jax
import numpy as np

from .._errors import MetriplexError


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


def write_json(path: str | os.PathLike, obj: Any) -> None:
    """Strict JSON (what every reader accepts): a NaN or infinite number is written as ``null``;
    the file that holds it says why (e.g. ``rollout_failures`` beside a null error)."""
    with atomic_write(path, "w") as f:
        json.dump(json_safe(obj), f, indent=2, default=_json_default, allow_nan=False)
        f.write("\n")


def json_safe(o: Any) -> Any:
    """``o`` with arrays as lists and every NaN or infinite number as ``None``: what strict
    JSON (``allow_nan=False``) can hold, the same for files and printed summaries."""
    if isinstance(o, dict):
        return {k: json_safe(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [json_safe(v) for v in o]
    if isinstance(o, (np.ndarray, jax.Array)):
        return json_safe(np.asarray(o).tolist())
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
    if not os.access(existing, os.W_OK | os.X_OK, **kw) or not _can_create_in(existing):
        raise MetriplexError(
            f"cannot write {option} {str(target)!r}: the folder {str(existing)!r} is not writable "
            f"(permission denied or a read-only file system). Choose another {option}, or make "
            "that folder writable."
        )


def _can_create_in(folder: Path) -> bool:
    """Whether a file can be created in ``folder``, tried with an empty probe file that is removed
    at once: ``os.access`` says yes where the file system refuses (``/proc``, some network and
    read-only mounts, or root in a folder without write permission)."""
    try:
        fd, probe = tempfile.mkstemp(prefix=".metriplex-probe-", dir=folder)
    except OSError:
        return False
    os.close(fd)
    with contextlib.suppress(OSError):
        os.unlink(probe)
    return True


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
            + ("Trajectories are written as " if suffixes != (".json",) else "Metrics are "
               "written as ") + f"{', '.join(suffixes)}."
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
