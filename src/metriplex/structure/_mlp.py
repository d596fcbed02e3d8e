"""A small MLP whose hidden layers are shared by potentials, Poisson and friction networks.

The structured outputs (antisymmetric L, lower-triangular B) are assembled by folding the fixed
assembly into the last layer's weights once per batch (a signed gather of the weight rows),
never by a gather or scatter per sample: XLA's CPU backward of gathers costs ~30x its forward
(see docs/design.md, 'Performance rules'), so the per-sample work stays one matmul.
"""

from __future__ import annotations

import functools
from typing import Any, Callable, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np

from .._errors import MetriplexError
from ..data import state_statistics
from .._types import Matrix

@jax.custom_jvp
def softplus(z: jax.Array) -> jax.Array:
    r"""``jax.nn.softplus`` (same values) with the derivative :math:`\sigma(z)` as its rule.

    ``jax.nn.softplus`` differentiates through ``logaddexp``, whose rule costs two
    exponentials and several selects per unit; GENERIC losses differentiate every hidden unit
    two or three times, so the lean rule (``logistic``, whose own rule is
    :math:`\sigma(1-\sigma)`) is measurably cheaper (docs/performance.md).
    """
    return jax.nn.softplus(z)


@softplus.defjvp
def _softplus_jvp(primals, tangents):
    (z,), (t,) = primals, tangents
    return softplus(z), jax.nn.sigmoid(z) * t


ACTIVATIONS = {
    "softplus": softplus,
    "tanh": jnp.tanh,
    "gelu": jax.nn.gelu,
    "silu": jax.nn.silu,
}


#: The hidden stack of every learned block unless its constructor is told otherwise:
#: ``DEPTH`` layers of ``WIDTH`` units with the smooth ``ACTIVATION`` (docs/zoo.md measured
#: widths 32, 64 and 128 and kept 64). A spec saved without an activation means ``ACTIVATION``.
WIDTH, DEPTH, ACTIVATION = 64, 2, "softplus"


def activation_fn(name: str) -> Callable[[jax.Array], jax.Array]:
    if name not in ACTIVATIONS:
        raise MetriplexError(
            f"activation must be one of {sorted(ACTIVATIONS)} (all C^inf, as GENERIC needs "
            f"smooth gradients); got {name!r}."
        )
    return ACTIVATIONS[name]


class Hidden(eqx.Module):
    """Hidden layers of an MLP: ``in_size -> width -> ... -> width`` (``depth`` layers)."""

    layers: tuple[eqx.nn.Linear, ...]
    activation: str = eqx.field(static=True)

    def __init__(self, in_size: int, width: int, depth: int, activation: str, *,
                 key: jax.Array) -> None:
        if width < 1 or depth < 1:
            raise MetriplexError(
                f"network width and depth must be >= 1; got width={width}, depth={depth}."
            )
        activation_fn(activation)
        keys = jr.split(key, depth)
        sizes = [in_size] + [width] * depth
        self.layers = tuple(
            eqx.nn.Linear(sizes[i], sizes[i + 1], key=keys[i]) for i in range(depth)
        )
        self.activation = activation

    def __call__(self, z: jax.Array) -> jax.Array:
        act = activation_fn(self.activation)
        for layer in self.layers:
            z = act(layer(z))
        return z


def standardise(x: jax.Array, shift: tuple[float, ...] | None,
                scale: tuple[float, ...] | None) -> jax.Array:
    if shift is None:
        return x
    return (x - jnp.asarray(shift, x.dtype)) / jnp.asarray(scale, x.dtype)


def network_spec(kind: str, hidden: Hidden, **entries: Any) -> dict[str, Any]:
    """The spec (model-file entry) of a block built on ``hidden``: its ``kind``, the stack's
    ``width``, ``depth`` and ``activation``, then the block's own ``entries`` in their order."""
    return {
        "kind": kind,
        "width": hidden.layers[-1].out_features,
        "depth": len(hidden.layers),
        "activation": hidden.activation,
        **entries,
    }


def check_states(z: np.ndarray, size: int) -> np.ndarray:
    """``z`` as the ``(N, size)`` states of a block's ``data=``, or a clear error."""
    z = np.asarray(z)
    if z.ndim != 2 or z.shape[1] != size:
        raise MetriplexError(
            f"a block's data= must be states of shape (N, {size}), one column per input of the "
            f"block (its n variables, or its features); got shape {z.shape}.")
    return z


def data_statistics(z: np.ndarray, size: int | None = None,
                    ) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """Mean and scale per column (:func:`metriplex.data.state_statistics`: constant columns get
    scale 1), as the static tuples a block keeps; ``z`` must be ``(N, size)`` where given."""
    mean, scale, _ = state_statistics(z if size is None else check_states(z, size))
    return tuple(float(v) for v in mean), tuple(float(v) for v in scale)


@functools.lru_cache(maxsize=None)
def skew_assembly(n: int) -> np.ndarray:
    """(n*n, n(n-1)/2) matrix mapping the strict upper triangle to a flat antisymmetric matrix.

    Exactly n(n-1)/2 outputs parametrise an antisymmetric matrix: the diagonal is zero by
    construction, so no output is wasted on it (the seed paper used n(n+1)/2).
    """
    rows, cols = np.triu_indices(n, k=1)
    m = len(rows)
    P = np.zeros((n * n, m))
    P[rows * n + cols, np.arange(m)] = 1.0
    P[cols * n + rows, np.arange(m)] = -1.0
    return P


@functools.lru_cache(maxsize=None)
def lower_assembly(n: int) -> np.ndarray:
    """(n*n, n(n+1)/2) matrix mapping outputs to a flat lower-triangular matrix."""
    rows, cols = np.tril_indices(n)
    m = len(rows)
    P = np.zeros((n * n, m))
    P[rows * n + cols, np.arange(m)] = 1.0
    return P


@functools.lru_cache(maxsize=None)
def signed_rows(n: int, triangle: str) -> tuple[np.ndarray, np.ndarray]:
    """``(rows, sign)`` with ``P == sign[:, None] * onehot(rows)`` for the assembly ``P`` of
    ``triangle`` (``"skew"`` or ``"lower"``): the one output each flat matrix entry takes, and
    its sign (0 for an entry that takes none, e.g. the skew diagonal)."""
    # From the triangle's indices, never the dense (n^2, m) assembly: 6 GB at n = 201.
    rows, sign = np.zeros((n, n), dtype=np.int64), np.zeros((n, n))
    i, j = np.triu_indices(n, k=1) if triangle == "skew" else np.tril_indices(n)
    rows[i, j], sign[i, j] = np.arange(len(i)), 1.0
    if triangle == "skew":
        rows[j, i], sign[j, i] = np.arange(len(i)), -1.0
    return rows.reshape(-1), sign.reshape(-1)


class FoldedHead(eqx.Module):
    """Final linear layer with a fixed assembly folded in: returns ``diag(r) P (W h + b)``.

    ``P`` is :func:`skew_assembly` or :func:`lower_assembly`; ``r`` (``row_scale``) carries the
    congruence of the state normalisation (see :mod:`metriplex.structure.scaling`).
    """

    weight: jax.Array
    bias: jax.Array
    n: int = eqx.field(static=True)
    triangle: str = eqx.field(static=True)
    row_scale: tuple[float, ...] | None = eqx.field(static=True)

    def __init__(self, width: int, n: int, triangle: str, row_scale: Sequence[float] | None,
                 init_scale: float, *, key: jax.Array) -> None:
        self.n = n
        self.triangle = triangle
        m = n * (n - 1) // 2 if triangle == "skew" else n * (n + 1) // 2
        lim = init_scale / np.sqrt(width)
        self.weight = jr.uniform(key, (m, width), minval=-lim, maxval=lim)
        self.bias = jnp.zeros((m,))
        self.row_scale = None if row_scale is None else tuple(float(v) for v in row_scale)

    def __call__(self, h: jax.Array) -> Matrix:
        rows, sign = signed_rows(self.n, self.triangle)
        if self.row_scale is not None:
            sign = np.asarray(self.row_scale) * sign
        sign = jnp.asarray(sign, h.dtype)
        # P W: every row of P holds at most one +-1, so P W is a signed gather of W's rows
        # (exact, as the product was). It does not depend on the sample, so under vmap it is
        # computed once per batch, and its backward is one scatter-add of n^2 x width per step;
        # the dense product cost n^2 x m x width = O(n^4 width) and an n^2 x m constant.
        weight = sign[:, None] * self.weight[rows]
        bias = sign * self.bias[rows]
        return (weight @ h + bias).reshape(self.n, self.n)


def folded_network(in_size: int, n: int, triangle: str, *, width: int, depth: int,
                   activation: str, scaling: Any, init_scale: float,
                   key: jax.Array) -> tuple[Hidden, FoldedHead]:
    """The hidden stack (``in_size`` inputs) and the folded head (see :class:`FoldedHead`) of a
    learned ``n x n`` matrix of ``triangle``, whose rows carry the congruence of ``scaling``
    (its ``row_scale`` for that triangle), a :class:`~metriplex.structure.scaling.Scaling`
    (whose module imports this one) or ``None``."""
    hkey, okey = jr.split(key)
    row_scale = None if scaling is None else scaling.row_scale(triangle)
    return (Hidden(in_size, width, depth, activation, key=hkey),
            FoldedHead(width, n, triangle, row_scale, init_scale, key=okey))


def check_variables(n: int, at_least: int, what: str, fix: str = "") -> None:
    """Raise unless a state of ``n`` variables is large enough for the block ``what``."""
    if n < at_least:
        raise MetriplexError(f"{what} needs n >= {at_least} variables; got {n}."
                             + (f" {fix}" if fix else ""))
