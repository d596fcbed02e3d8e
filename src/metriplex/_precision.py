"""Matrix products at the precision of their dtype.

On NVIDIA GPUs since Ampere (A100, H100, H200) JAX computes float32 matrix products in
TensorFloat-32 by default: inputs rounded to 10 bits of mantissa, a relative error of about
1e-3. metriplex's float32 training reaches errors below that, and its implicit solves stop at a
float32 tolerance of 1e-4, so on such a GPU a float32 discrete-gradient rollout failed steps
that it completes on the CPU (docs/performance.md, *GPU*). The library's entry points
(:func:`~metriplex.fit`, :func:`~metriplex.solve`, :func:`~metriplex.simulate`,
:func:`~metriplex.evaluate`, the verdict, the command line) therefore compute in full float32
(``jax.default_matmul_precision("highest")``), unless the caller chose a precision
(``JAX_DEFAULT_MATMUL_PRECISION``, ``jax.config.update("jax_default_matmul_precision", ...)``
or the context manager around the call): that choice is kept. On the CPU every setting gives
the same float32 products."""

from __future__ import annotations

import contextlib
import functools
from typing import Callable, ContextManager, TypeVar

import jax

F = TypeVar("F", bound=Callable)


def full_precision() -> ContextManager[None]:
    """A context in which matrix products are computed at their dtype's full precision, unless
    a default matmul precision is already set (by the caller, or an enclosing entry point)."""
    if jax.config.jax_default_matmul_precision is not None:
        return contextlib.nullcontext()
    return jax.default_matmul_precision("highest")


def in_full_precision(fn: F) -> F:
    """``fn`` run inside :func:`full_precision` (for the library's entry points)."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        with full_precision():
            return fn(*args, **kwargs)

    return wrapper  # type: ignore[return-value]
