"""Work that runs beside the main thread: how many threads the CPU gives (:func:`cpu_threads`)
and a function that carries the caller's JAX settings that a program depends on into another
thread (:func:`in_this_threads_config`).

JAX runs compiled programs of several threads side by side, and a rollout (many small
operations, one step after the other) keeps one core busy: on the CPU, two batches of
rollouts in two threads take the time of one. The results do not depend on it (each program
is the same on the same inputs). A training chunk is not such a program: it already keeps
about 1.3 of 2 cores busy (oscillator-bath, batch 256), and scoring the held-out rollouts in
a thread beside it saved nothing measurable there (2026-11-28; not kept)."""

from __future__ import annotations

import os
from typing import Any, Callable

import jax


def cpu_threads() -> int:
    """The cores this process may use when JAX computes on the CPU; 1 on an accelerator, whose
    programs gain nothing from being started by several threads."""
    if jax.default_backend() != "cpu":
        return 1
    cores = os.sched_getaffinity(0) if hasattr(os, "sched_getaffinity") else None
    return max(1, len(cores) if cores else (os.cpu_count() or 1))


def in_this_threads_config(fn: Callable[..., Any]) -> Callable[..., Any]:
    """``fn``, to be run by another thread under this thread's JAX settings that a program
    depends on: x64 mode, matmul precision, default device, dtype and rank promotion (JAX's
    context managers for them, such as the library's own precision, are per thread)."""
    x64 = jax.config.jax_enable_x64
    precision = jax.config.jax_default_matmul_precision
    device = jax.config.jax_default_device
    dtypes = jax.config.jax_numpy_dtype_promotion
    ranks = jax.config.jax_numpy_rank_promotion

    def run(*args: Any) -> Any:
        with (jax.enable_x64(x64), jax.default_matmul_precision(precision),
              jax.default_device(device), jax.numpy_dtype_promotion(dtypes),
              jax.numpy_rank_promotion(ranks)):
            return fn(*args)

    return run
