"""One training at a time per run folder: a lock file that a crashed run never leaves stuck.

The lock is the file ``RUN/.metriplex.lock``, created atomically (``O_CREAT | O_EXCL``) and
holding who owns it (process id, host, start time, command). While a training runs it also
holds an operating-system lock on that file (``flock`` on POSIX, ``msvcrt.locking`` on
Windows). The operating system drops that lock when the process ends, however it ends, so a
lock file left by a crashed or killed run is recognised as stale and taken over with a note;
two processes can never both take it over. Where the file system offers no such lock (some
network file systems), a lock file whose process is no longer running on this host is stale.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import socket
import sys
import threading
import time
from pathlib import Path

from .._errors import MetriplexError

LOCK_NAME = ".metriplex.lock"

try:  # POSIX
    import fcntl
except ImportError:  # pragma: no cover - Windows
    fcntl = None
try:  # Windows
    import msvcrt
except ImportError:
    msvcrt = None

#: Held locks of this process, by (folder, thread): re-entrant within one thread, so that a
#: command may hold the folder around the library call that also takes it.
_held: dict[tuple[str, int], "RunLock"] = {}
_held_guard = threading.Lock()


class RunFolderInUse(MetriplexError):
    """Another training holds the run folder."""


def _owner_text() -> bytes:
    owner = {
        "pid": os.getpid(),
        "host": socket.gethostname(),
        "started": time.strftime("%Y-%m-%d %H:%M:%S %z"),
        "command": " ".join(sys.argv)[:500],
    }
    return (json.dumps(owner) + "\n").encode()


def _read_owner(fd: int) -> dict:
    try:
        os.lseek(fd, 0, os.SEEK_SET)
        owner = json.loads(os.read(fd, 4096).decode() or "{}")
        return owner if isinstance(owner, dict) else {}
    except (OSError, ValueError):
        return {}


def _describe(owner: dict) -> str:
    if not owner.get("pid"):
        return "an unknown process (the lock file names none)"
    text = f"process {owner['pid']} on host {owner.get('host', '?')}"
    if owner.get("started"):
        text += f", started {owner['started']}"
    if owner.get("command"):
        text += f": {owner['command']}"
    return text


def _os_lock(fd: int) -> bool | None:
    """Take the operating-system lock on ``fd`` without waiting: True (taken), False (another
    process holds it) or None (this file system has no such locks)."""
    try:
        if fcntl is not None:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        elif msvcrt is not None:  # pragma: no cover - Windows
            os.lseek(fd, 1 << 20, os.SEEK_SET)  # a byte beyond the text, so readers can read it
            msvcrt.locking(fd, msvcrt.LK_NBLCK, 1)
        else:  # pragma: no cover
            return None
    except OSError as e:
        if e.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES, errno.EDEADLK):
            return False
        if e.errno in (errno.ENOLCK, errno.EOPNOTSUPP, errno.ENOSYS, errno.EINVAL):
            return None
        raise
    return True


def _process_alive(pid: int) -> bool:
    if os.name != "posix":  # pragma: no cover - os.kill(pid, 0) would terminate it on Windows
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _in_use(folder: Path, owner: dict) -> RunFolderInUse:
    return RunFolderInUse(
        f"run folder {str(folder)!r} is in use by another training ({_describe(owner)}); a run "
        "folder is written by one training at a time. Wait for it to end, or choose another "
        f"--out. If no training runs there any more, delete {str(folder / LOCK_NAME)!r}."
    )


def check_not_in_use(folder: str | os.PathLike) -> None:
    """Raise :class:`RunFolderInUse` if another process holds ``folder`` now (a quick look
    before any work; :meth:`RunLock.acquire` decides). Creates nothing."""
    folder = Path(folder)
    with _held_guard:
        if (os.path.realpath(folder), threading.get_ident()) in _held:
            return
    try:
        fd = os.open(folder / LOCK_NAME, os.O_RDONLY)  # an OS lock needs no write access
    except OSError:  # no lock file (or none we could open: acquire will say why)
        return
    try:
        taken = _os_lock(fd)
        owner = _read_owner(fd)
        if taken is None:
            pid = owner.get("pid")
            taken = not (isinstance(pid, int) and (owner.get("host") != socket.gethostname()
                                                   or _process_alive(pid)))
    finally:
        os.close(fd)  # drops the lock just taken, if any
    if not taken:
        raise _in_use(folder, owner)


class RunLock:
    """Exclusive ownership of a run folder by one training (see the module docstring).

    ```python
    with RunLock("runs/pendulum"):
        ...  # write the run folder
    ```
    ``acquire`` raises :class:`RunFolderInUse` (a :class:`MetriplexError`) naming the owner
    when another process holds the folder; a stale lock is taken over, and ``note`` says so.
    """

    def __init__(self, folder: str | os.PathLike) -> None:
        self.folder = Path(folder)
        self.path = self.folder / LOCK_NAME
        self.note: str | None = None
        self._fd: int | None = None
        self._key = None
        self._nested = False

    def __enter__(self) -> "RunLock":
        return self.acquire()

    def __exit__(self, *exc) -> None:
        self.release()

    def acquire(self) -> "RunLock":
        self.folder.mkdir(parents=True, exist_ok=True)
        key = (os.path.realpath(self.folder), threading.get_ident())
        with _held_guard:
            if key in _held:  # this thread holds it already: nest (release is then a no-op)
                self._key, self._nested = key, True
                return self
        stale: dict = {}  # the owner of a stale lock file removed below
        for _ in range(100):
            created = True
            try:
                fd = os.open(self.path, os.O_RDWR | os.O_CREAT | os.O_EXCL, 0o666)
            except FileExistsError:
                created = False
                try:
                    fd = os.open(self.path, os.O_RDWR)
                except FileNotFoundError:  # released meanwhile: try again
                    continue
                except PermissionError:  # another user's lock file (a shared folder)
                    stale = self._remove_if_stale()
                    continue
            try:
                taken = _os_lock(fd)
                previous = stale if created else _read_owner(fd)
                if taken is None:  # no OS locks here: judge the owner by its process id
                    taken = created or self._stale_on_this_host(previous)
                if not taken:
                    raise _in_use(self.folder, previous)
                # The path may have been released (unlinked) and re-created after our open.
                try:
                    same = os.path.samestat(os.fstat(fd), os.stat(self.path))
                except FileNotFoundError:
                    same = False
                if not same:
                    os.close(fd)
                    continue
                os.ftruncate(fd, 0)
                os.lseek(fd, 0, os.SEEK_SET)
                os.write(fd, _owner_text())
                os.fsync(fd)
            except BaseException:
                with contextlib.suppress(OSError):
                    os.close(fd)
                raise
            self._fd, self._key = fd, key
            if previous.get("pid"):
                self.note = (
                    f"note: took over the lock of run folder {str(self.folder)!r} from "
                    f"{_describe(previous)}, which is no longer running (it crashed or was "
                    "killed; its files there may be incomplete)."
                )
            with _held_guard:
                _held[key] = self
            return self
        raise RunFolderInUse(
            f"could not lock run folder {str(self.folder)!r}: other processes keep creating and "
            "removing its lock. Run one training at a time in it."
        )

    def _remove_if_stale(self) -> dict:
        """For a lock file we may not write: raise if its owner holds it, else remove it (the
        folder is ours to write) and return its owner, for the note."""
        try:
            fd = os.open(self.path, os.O_RDONLY)
        except FileNotFoundError:
            return {}
        try:
            taken = _os_lock(fd)
            owner = _read_owner(fd)
            if taken is None:
                taken = self._stale_on_this_host(owner)
            if not taken:
                raise _in_use(self.folder, owner)
            with contextlib.suppress(FileNotFoundError):
                if os.path.samestat(os.fstat(fd), os.stat(self.path)):
                    os.unlink(self.path)  # while holding it: no other taker can be inside
        finally:
            os.close(fd)
        return owner

    def _stale_on_this_host(self, owner: dict) -> bool:
        pid = owner.get("pid")
        return (isinstance(pid, int) and owner.get("host") == socket.gethostname()
                and not _process_alive(pid))

    def release(self) -> None:
        if self._key is None:
            return
        key, self._key = self._key, None
        if self._nested:
            self._nested = False
            return
        with _held_guard:
            _held.pop(key, None)
        fd, self._fd = self._fd, None
        if os.name == "posix":
            # Unlink while still holding it, then close (which drops the OS lock): a process
            # that opened the old file meanwhile sees, once it holds it, that the path is gone.
            with contextlib.suppress(OSError):
                os.unlink(self.path)
            os.close(fd)
        else:  # pragma: no cover - Windows cannot unlink an open file
            os.close(fd)
            with contextlib.suppress(OSError):
                os.unlink(self.path)

    @property
    def held(self) -> bool:
        return self._key is not None
