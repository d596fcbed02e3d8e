r"""Local blocks for states made of cells: a chain of masses, a ring of conducting cells, a
discretised bar. The energy and the friction are sums of terms that each read two
neighbouring cells, so that a network sees a handful of variables however many cells there are.

:class:`Lattice` states the layout: ``n = fields x cells`` variables stored field by field, as a
chain's :math:`(q_1..q_N, p_1..p_N, s_1..s_N)`, so that cell :math:`i` holds the variables
:math:`i, i + N, i + 2N, \dots` The bonds join neighbouring cells, :math:`(i, i+1)`; in a ring
(``periodic``) also :math:`(N, 1)`; in an open chain the two end cells each have one more bond,
to the outside (a wall, or nothing), whose missing cell reads as zeros. Every bond has its own
network (nothing assumes the cells alike), or, with ``shared``, one network serves them all.

- :class:`LocalPotential`: :math:`E(x) = \sigma\sum_b \varphi_b(x_b)`, :math:`x_b` the
  standardised variables of bond :math:`b`'s two cells.
- :class:`LocalFriction`: :math:`M = f D\big[\sum_b S_b^\top F_bF_b^\top S_b\big]D` with
  :math:`F_b = \tilde P_b B_b(x_b)`, :math:`B_b` lower-triangular from bond :math:`b`'s network
  and :math:`\tilde P_b` the projector against the bond's part of :math:`D\nabla E`. Symmetric
  positive semi-definite and :math:`M\nabla E = 0` to rounding for any weights: each term
  annihilates :math:`\nabla E` on its own, as heat conduction between two cells, or friction
  that heats the cell it acts in, does.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import TYPE_CHECKING, Any, ClassVar, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np

from .._errors import MetriplexError, expect_integer
from .._types import Array, Float, Matrix, Scalar, State
from ._abstract import AbstractFriction, AbstractPotential
from ._mlp import ACTIVATION, DEPTH, WIDTH, Hidden, data_statistics, lower_assembly, network_spec
from ._mlp import standardise
from ._projection import check_eps, eps_squared
from ._registry import network_kwargs, register
from .confinement import Confinement
from .scaling import Scaling, scaling_spec, standardise_state

if TYPE_CHECKING:
    from numpy.typing import ArrayLike


@dataclasses.dataclass(frozen=True)
class Lattice:
    """``cells`` cells of ``n // cells`` fields each, stored field by field; ``periodic``: a
    ring (the last cell bonds to the first) instead of an open chain; ``shared``: the cells
    are alike, and one network serves every bond (in an open chain it also reads whether
    each side of the bond is outside), so that each sees the data of all bonds."""

    cells: int
    n: int
    periodic: bool = False
    shared: bool = False

    def __post_init__(self) -> None:
        expect_integer(self.cells, what="a lattice's cells", least=2,
                       fix="Example: --energy local:10 for ten cells.")
        if self.n % self.cells:
            counts = [k for k in range(2, self.n // 2 + 1) if self.n % k == 0]
            raise MetriplexError(
                f"a lattice of {self.cells} cells needs a number of variables that is a "
                f"multiple of {self.cells} (the same fields in every cell, stored field by "
                f"field, and no variable outside the cells); the data have n={self.n}. "
                + (f"The cell counts this n allows: {', '.join(map(str, counts))}. " if counts
                   else "") + "A state with variables of its own beside the cells (one bath "
                "that every cell heats, a recorded parameter) is no lattice: leave the local "
                "blocks out for it.")

    @property
    def fields(self) -> int:
        """The number of variables per cell."""
        return self.n // self.cells

    @property
    def bonds(self) -> int:
        """The number of bonds: one per cell in a ring, one more in an open chain."""
        return self.cells if self.periodic else self.cells + 1

    def selection(self) -> np.ndarray:
        """The one-hot ``(bonds, 2 fields, n)`` map from a state to its bonds' variables (first
        cell's fields, then the second's); rows of a missing cell are zero."""
        return _selection(self.cells, self.n, self.periodic)

    def pool(self, shift: Sequence[float], scale: Sequence[float]
             ) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """For a ``shared`` lattice, per-variable statistics (mean and standard deviation)
        replaced by those of each field over all cells, so that alike cells are standardised
        alike; unchanged otherwise."""
        if not self.shared:
            return tuple(shift), tuple(scale)
        m = np.asarray(shift, float).reshape(self.fields, self.cells)
        sd = np.asarray(scale, float).reshape(self.fields, self.cells)
        mean = m.mean(axis=1, keepdims=True)
        pooled = np.sqrt(np.mean(sd**2 + (m - mean) ** 2, axis=1, keepdims=True))
        ones = np.ones((1, self.cells))
        return (tuple(float(v) for v in (mean * ones).ravel()),
                tuple(float(v) for v in (pooled * ones).ravel()))

    def to_json(self) -> dict[str, Any]:
        """What a block's spec records of the lattice (``n`` is the model's)."""
        return {"cells": self.cells, "periodic": self.periodic, "shared": self.shared}

    @classmethod
    def from_json(cls, obj: dict[str, Any], n: int) -> "Lattice":
        """The lattice that :meth:`to_json` wrote, for a state of ``n`` variables."""
        return cls(int(obj["cells"]), n, bool(obj.get("periodic", False)),
                   bool(obj.get("shared", False)))


@functools.lru_cache(maxsize=None)
def _selection(cells: int, n: int, periodic: bool) -> np.ndarray:
    fields = n // cells
    pairs = ([(i, (i + 1) % cells) for i in range(cells)] if periodic
             else [(i - 1, i) for i in range(cells + 1)])
    S = np.zeros((len(pairs), 2 * fields, n))
    for b, pair in enumerate(pairs):
        for side, cell in enumerate(pair):
            if 0 <= cell < cells:
                for f in range(fields):
                    S[b, side * fields + f, cell + f * cells] = 1.0
    return S


class _Bonds(eqx.Module):
    """The bond networks, ``2 fields -> width^depth -> out``: one per bond, stored stacked
    (leading axis: the bond) and evaluated in one vmap; or, for a ``shared`` lattice, one for
    all bonds, which in an open chain also reads two flags, whether each side is outside."""

    hidden: Hidden
    out: eqx.nn.Linear
    lattice: Lattice = eqx.field(static=True)

    def __init__(self, lattice: Lattice, out_size: int, *, width: int, depth: int,
                 activation: str, init_scale: float, key: jax.Array) -> None:
        in_size = 2 * lattice.fields + (2 if lattice.shared and not lattice.periodic else 0)

        def make(k: jax.Array) -> tuple[Hidden, eqx.nn.Linear]:
            hk, ok = jr.split(k)
            out = eqx.nn.Linear(width, out_size, key=ok)
            out = eqx.tree_at(lambda l: (l.weight, l.bias), out,
                              (init_scale * out.weight, init_scale * out.bias))
            return Hidden(in_size, width, depth, activation, key=hk), out

        self.lattice = lattice
        self.hidden, self.out = (make(key) if lattice.shared
                                 else eqx.filter_vmap(make)(jr.split(key, lattice.bonds)))

    def __call__(self, z: Float[Array, "bonds inputs"]) -> Float[Array, "bonds outputs"]:
        if not self.lattice.shared:
            return eqx.filter_vmap(lambda h, o, zb: o(h(zb)))(self.hidden, self.out, z)
        if not self.lattice.periodic:
            outside = np.zeros((self.lattice.bonds, 2))
            outside[0, 0] = outside[-1, 1] = 1.0
            z = jnp.concatenate([z, jnp.asarray(outside, z.dtype)], axis=1)
        return jax.vmap(lambda zb: self.out(self.hidden(zb)))(z)


def _windows(S: np.ndarray, z: State) -> Float[Array, "bonds variables"]:
    # A one-hot matmul, not a gather: XLA's CPU backward of a gather is slow (docs/design.md).
    return jnp.einsum("bwn,n->bw", jnp.asarray(S, z.dtype), z)


@register("potential", "local")
class LocalPotential(AbstractPotential):
    r"""A learned energy of a lattice: :math:`E = \sigma\big(\sum_b \varphi_b(z_b) + W\big)`,
    one MLP :math:`\varphi_b` per bond of ``lattice`` reading the standardised variables
    :math:`z_b` of the bond's two cells (zeros for the outside of an open chain); ``W`` the
    optional ``confinement`` wall, ``output_scale`` :math:`\sigma` as in
    :class:`~metriplex.structure.MLPPotential`.
    """

    nets: _Bonds
    lattice: Lattice = eqx.field(static=True)
    shift: tuple[float, ...] | None = eqx.field(static=True)
    scale: tuple[float, ...] | None = eqx.field(static=True)
    output_scale: float = eqx.field(static=True)
    confinement: Confinement | None

    def __init__(self, lattice: Lattice, *, width: int = WIDTH, depth: int = DEPTH,
                 activation: str = ACTIVATION, data: ArrayLike | None = None,
                 shift: Sequence[float] | None = None, scale: Sequence[float] | None = None,
                 output_scale: float = 1.0, confinement: Confinement | None = None,
                 key: jax.Array) -> None:
        if not (np.isfinite(output_scale) and output_scale > 0):
            raise MetriplexError(
                f"LocalPotential output_scale must be finite and > 0; got {output_scale}.")
        self.lattice = lattice
        if data is not None:
            shift, scale = lattice.pool(*data_statistics(np.asarray(data), lattice.n))
        self.shift = None if shift is None else tuple(float(v) for v in shift)
        self.scale = None if scale is None else tuple(float(v) for v in scale)
        self.output_scale = float(output_scale)
        self.confinement = confinement
        self.nets = _Bonds(lattice, 1, width=width, depth=depth,
                           activation=activation, init_scale=1.0, key=key)

    def __call__(self, x: State) -> Scalar:
        z = standardise(x, self.shift, self.scale)
        y = jnp.sum(self.nets(_windows(self.lattice.selection(), z)))
        if self.confinement is not None:
            y = y + self.confinement(x)
        return y if self.output_scale == 1.0 else self.output_scale * y

    def spec(self) -> dict[str, Any]:
        return network_spec(
            "local", self.nets.hidden, lattice=self.lattice.to_json(), shift=self.shift,
            scale=self.scale, output_scale=self.output_scale,
            confinement=None if self.confinement is None else self.confinement.to_json())

    @classmethod
    def from_spec(cls, spec: dict[str, Any], n: int, *, key: jax.Array) -> "LocalPotential":
        """The block that ``spec`` (the output of :meth:`spec`) describes, for ``n`` variables;
        ``key`` draws weights that the model file then overwrites."""
        wall = spec.get("confinement")
        return cls(Lattice.from_json(spec["lattice"], n), width=spec["width"],
                   depth=spec["depth"], activation=spec.get("activation", ACTIVATION),
                   shift=spec.get("shift"), scale=spec.get("scale"),
                   output_scale=spec.get("output_scale", 1.0),
                   confinement=None if wall is None else Confinement.from_json(wall), key=key)


@register("friction", "local")
class LocalFriction(AbstractFriction):
    r"""A learned friction of a lattice, :math:`M\nabla E = 0` and :math:`M \succeq 0` by
    construction (module docstring): per bond :math:`b` a lower-triangular :math:`\tilde B_b`
    from the bond's network, projected against :math:`h_b = S_bD\nabla E`,

    .. math:: F_b = \tilde B_b - \hat h_b(\hat h_b^\top\tilde B_b),\quad
              \hat h_b = h_b/\sqrt{|h_b|^2+\varepsilon^2},\qquad
              M = f D\Big[\sum_b S_b^\top F_bF_b^\top S_b\Big]D

    (``f`` and ``D`` those of the scaling). :math:`M\nabla E` vanishes to rounding wherever
    every bond's :math:`|h_b| \gg \varepsilon`; :math:`M \to` the unprojected sum smoothly where
    it does not.
    """

    nets: _Bonds
    lattice: Lattice = eqx.field(static=True)
    n: int = eqx.field(static=True)
    scaling: Scaling | None = eqx.field(static=True)
    eps: float | None = eqx.field(static=True)

    def __init__(self, lattice: Lattice, *, width: int = WIDTH, depth: int = DEPTH,
                 activation: str = ACTIVATION, scaling: Scaling | None = None,
                 eps: float | None = None, key: jax.Array) -> None:
        check_eps(eps)
        self.lattice = lattice
        self.n = lattice.n
        if scaling is not None and lattice.shared:  # alike cells standardised alike
            scaling = Scaling(*lattice.pool(scaling.shift, scaling.scale), scaling.factor)
        self.scaling = scaling
        self.eps = None if eps is None else float(eps)
        w = 2 * lattice.fields
        # Small initial factors, as CholeskyFriction's: training starts near reversible motion.
        self.nets = _Bonds(lattice, w * (w + 1) // 2, width=width, depth=depth,
                           activation=activation, init_scale=0.1, key=key)

    uses_gradient: ClassVar[bool] = True

    def __call__(self, x: State, grad_energy: State) -> Matrix:
        S = self.lattice.selection()
        w = S.shape[1]
        a = self.nets(_windows(S, standardise_state(x, self.scaling)))
        B = (a @ jnp.asarray(lower_assembly(w).T, x.dtype)).reshape(-1, w, w)
        d = (jnp.ones(self.n, x.dtype) if self.scaling is None
             else jnp.asarray(self.scaling.scale, x.dtype))
        h = _windows(S, d * grad_energy)
        e2 = eps_squared(self.eps, x.dtype)
        h_hat = h * jax.lax.rsqrt(jnp.sum(h * h, axis=1, keepdims=True) + e2)
        F = B - h_hat[:, :, None] * jnp.einsum("bw,bwk->bk", h_hat, B)[:, None, :]
        G = jnp.einsum("bwn,bwk->bnk", jnp.asarray(S, x.dtype), F)  # S_b^T F_b, (bonds, n, w)
        Mt = jnp.einsum("bnk,bmk->nm", G, G)
        f = 1.0 if self.scaling is None else self.scaling.factor
        return f * (d[:, None] * Mt * d[None, :])

    def spec(self) -> dict[str, Any]:
        return network_spec("local", self.nets.hidden, lattice=self.lattice.to_json(),
                            scaling=scaling_spec(self.scaling), eps=self.eps)

    @classmethod
    def from_spec(cls, spec: dict[str, Any], n: int, *, key: jax.Array) -> "LocalFriction":
        """The block that ``spec`` (the output of :meth:`spec`) describes, for ``n`` variables;
        ``key`` draws weights that the model file then overwrites."""
        return cls(Lattice.from_json(spec["lattice"], n), **network_kwargs(spec),
                   eps=spec.get("eps"), key=key)
