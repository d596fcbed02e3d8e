"""The C allocator of the ``metriplex`` command: large blocks given back to the system when
freed (``metriplex train``'s peak memory on large data)."""

from __future__ import annotations

import sys

#: Blocks from this size up are mapped on their own and given back to the system when freed.
MMAP_THRESHOLD = 1 << 20


def return_large_blocks() -> None:
    """Fix glibc's threshold for blocks mapped on their own (``mallopt(M_MMAP_THRESHOLD)``) at
    :data:`MMAP_THRESHOLD`, where the user has not set it (``MALLOC_MMAP_THRESHOLD_``,
    ``GLIBC_TUNABLES``); nothing elsewhere.

    glibc raises the threshold to the size of every mapped block freed (up to 32 MB), after
    which data-sized arrays of a few MB (a training's states in float32, its pair indices,
    rollouts) come from the heap, and the heap keeps what they free: on a 400 x 2001 pendulum
    over 100 MB that no array held, at the peak of ``metriplex train`` (docs/performance.md,
    'Memory of a training run'). A fixed threshold costs a few hundred more ``mmap`` calls
    in a run of 26 000. The library itself leaves the process's allocator alone."""
    import os

    if not sys.platform.startswith("linux") or "MALLOC_MMAP_THRESHOLD_" in os.environ \
            or "malloc.mmap_threshold" in os.environ.get("GLIBC_TUNABLES", ""):
        return
    import ctypes

    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):  # no C library to ask (or not one with mallopt)
        return
    M_MMAP_THRESHOLD = -3
    mallopt(ctypes.c_int(M_MMAP_THRESHOLD), ctypes.c_int(MMAP_THRESHOLD))
