r"""Poisson bivectors :math:`L(x)`: antisymmetric, ideally satisfying the Jacobi identity.

Every Poisson block is called as ``poisson(x, grad_entropy)``; the gradient of the entropy is
passed so that exactly degenerate variants (:math:`L\nabla S = 0` by construction) can use it.
"""

from __future__ import annotations

import abc
from typing import Any, ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._errors import MetriplexError
from .._types import Matrix, State
from ._mlp import ACTIVATION, DEPTH, WIDTH
from ._mlp import FoldedHead, Hidden, check_variables, folded_network, network_spec, softplus
from ._abstract import AbstractPoisson
from ._fixed import AbstractFunctionMatrix, AbstractZeroMatrix
from ._registry import network_kwargs, register
from ._projection import AbstractProjected
from .scaling import Scaling, scaling_spec, standardise_state


class _AbstractSkewNetwork(AbstractPoisson):
    """What the learned Poisson networks share: a hidden stack on standardised states and a
    folded skew head (:func:`~metriplex.structure._mlp.folded_network`), built from the same
    options and saved as the same spec under their own kind."""

    hidden: Hidden
    head: FoldedHead
    n: int = eqx.field(static=True)
    scaling: Scaling | None = eqx.field(static=True)

    def __init__(
        self, n: int, *,
        width: int = WIDTH, depth: int = DEPTH, activation: str = ACTIVATION,
        scaling: Scaling | None = None,
        key: jax.Array,
    ) -> None:
        self._check(n)
        self.n = n
        self.scaling = scaling
        self.hidden, self.head = folded_network(
            n, n, "skew", width=width, depth=depth, activation=activation,
            scaling=scaling, init_scale=1.0, key=key,
        )

    @staticmethod
    @abc.abstractmethod
    def _check(n: int) -> None:
        """Raise unless the block can be built for ``n`` variables."""

    def _network(self, x: State) -> Matrix:
        return self.head(self.hidden(standardise_state(x, self.scaling)))

    def spec(self) -> dict[str, Any]:
        return network_spec(self.kind, self.hidden, scaling=scaling_spec(self.scaling))

    @staticmethod
    def spec_options(spec: dict[str, Any]) -> dict[str, Any]:
        """The constructor's options saved in ``spec``."""
        return network_kwargs(spec)

    @classmethod
    def from_spec(cls, spec: dict[str, Any], n: int, *, key: jax.Array) -> Any:
        """The block that ``spec`` (the output of :meth:`spec`) describes, for ``n`` variables;
        ``key`` draws weights that the model file then overwrites."""
        return cls(n, **cls.spec_options(spec), key=key)


@register("poisson", "neural")
class SkewMLPPoisson(_AbstractSkewNetwork):
    r"""Learned :math:`L(x)` from exactly :math:`n(n-1)/2` network outputs.

    The outputs fill the strict upper triangle; the lower triangle is their negative and the
    diagonal is zero, so :math:`L^\top = -L` holds exactly for any weights. With a
    :class:`~metriplex.structure.scaling.Scaling`, the network works on standardised states and
    :math:`L = D\tilde L D^\top` (folded into the last layer).
    """

    uses_gradient: ClassVar[bool] = False

    @staticmethod
    def _check(n: int) -> None:
        check_variables(n, 2, "a learned Poisson bivector",
                        fix="With one variable the only antisymmetric L is 0: pass --poisson "
                        "zero (in Python, ZeroPoisson(1)).")

    def __call__(self, x: State, grad_entropy: State | None = None) -> Matrix:
        return self._network(x)


@register("poisson", "planar")
class PlanarPoisson(_AbstractSkewNetwork):
    r"""Learned :math:`L(x) = a(x)\,J` of two variables with :math:`a > 0` everywhere.

    In two variables every antisymmetric :math:`L` is :math:`a(x) J`,
    :math:`J = \begin{pmatrix}0&1\\-1&0\end{pmatrix}`, and satisfies the Jacobi identity.
    Wherever the state moves, :math:`a \ne 0` (:math:`\dot x = a J\nabla E`), so over
    connected data :math:`a` keeps one sign, and that sign is a gauge of a learned energy
    (:math:`(a, E) \to (-a, -E)`): :math:`a > 0` restricts nothing then. A network of free
    sign lets training put a zero of :math:`a` across the data, which :math:`a\nabla E` cannot
    fit without a singular :math:`E`; from most initialisations on a double well it does
    (docs/zoo.md). Here :math:`a = r\,\mathrm{softplus}(z(\tilde x))` with :math:`z` the
    network's output and :math:`r > 0` the scaling's congruence factor. With a given energy
    of the other orientation, use :class:`SkewMLPPoisson`.
    """

    uses_gradient: ClassVar[bool] = False

    @staticmethod
    def _check(n: int) -> None:
        if n != 2:
            raise MetriplexError(
                f"PlanarPoisson is L = a(x) J for two variables; got n={n}. For other sizes "
                "use SkewMLPPoisson (--poisson neural picks it)."
            )

    def __call__(self, x: State, grad_entropy: State | None = None) -> Matrix:
        # The head folds the positive congruence r into the entry (0, 1): z = entry / r.
        r = 1.0 if self.head.row_scale is None else self.head.row_scale[1]
        a = r * softplus(self._network(x)[0, 1] / r)
        return a * jnp.asarray([[0.0, 1.0], [-1.0, 0.0]], x.dtype)


@register("poisson", "canonical")
class CanonicalPoisson(AbstractPoisson):
    r"""Canonical :math:`L = \begin{pmatrix}0 & I & 0\\ -I & 0 & 0\\ 0&0&0\end{pmatrix}`.

    The first ``pairs`` components are positions, the next ``pairs`` their momenta; the
    remaining ``n - 2*pairs`` components (e.g. entropies) have zero rows and columns.
    """

    n: int = eqx.field(static=True)
    pairs: int = eqx.field(static=True)

    def __init__(self, n: int, pairs: int) -> None:
        if pairs < 1 or 2 * pairs > n:
            raise MetriplexError(
                f"canonical:K needs 1 <= K and 2K <= n (K positions then K momenta); got "
                f"K={pairs} with n={n} variables. Choose K <= {n // 2}."
            )
        self.n = n
        self.pairs = pairs

    def matrix(self) -> np.ndarray:
        """The canonical :math:`L` as a NumPy ``(n, n)`` array."""
        K = self.pairs
        J = np.zeros((self.n, self.n))
        J[:K, K : 2 * K] = np.eye(K)
        J[K : 2 * K, :K] = -np.eye(K)
        return J

    uses_gradient: ClassVar[bool] = False

    def __call__(self, x: State, grad_entropy: State | None = None) -> Matrix:
        return jnp.asarray(self.matrix(), x.dtype)

    def spec(self) -> dict[str, Any]:
        return {"kind": "canonical", "pairs": self.pairs}

    @classmethod
    def from_spec(cls, spec: dict[str, Any], n: int, *, key: jax.Array) -> "CanonicalPoisson":
        """The canonical bivector of ``n`` variables with the ``pairs`` saved in ``spec`` (``key``
        is not needed)."""
        return cls(n, spec["pairs"])


@register("poisson", "zero")
class ZeroPoisson(AbstractZeroMatrix, AbstractPoisson):
    """No reversible dynamics: :math:`L = 0`."""

    uses_gradient: ClassVar[bool] = False


class KnownPoisson(AbstractFunctionMatrix, AbstractPoisson):
    """A Poisson bivector given by a function ``fn(x) -> (n, n)`` (ground-truth systems)."""

    uses_gradient: ClassVar[bool] = False


# -- exactly degenerate variant ----------------------------------------------------------------


class AbstractProjectedPoisson(AbstractProjected, AbstractPoisson):
    r"""A learned :math:`A(x)` of the family ``network`` projected against :math:`\nabla S`:
    :math:`L = Q A Q^\top` with :math:`L\nabla S = 0` (:class:`ProjectedSkewMLPPoisson` says
    how)."""

    def __call__(self, x: State, grad_entropy: State) -> Matrix:
        A = self.base(x)
        g_hat, u_hat = self._projector(grad_entropy, x.dtype)
        # L = K - K^T with K = A/2 - b u^T. Not A - (W - W^T): the compiler may fuse one of the
        # two products of W - W^T into an FMA and break exact antisymmetry; each K_ij is one
        # deterministic expression, so K_ij - K_ji = -(K_ji - K_ij) exactly.
        K = 0.5 * A - jnp.outer(A @ g_hat, u_hat)
        return K - K.T


@register("poisson", "projected-neural")
class ProjectedSkewMLPPoisson(AbstractProjectedPoisson):
    r"""Learned :math:`L` with :math:`L\nabla S = 0` by construction: :math:`L = Q A Q^\top`.

    :math:`A(x)` is a :class:`SkewMLPPoisson` (same network, same normalisation congruence
    :math:`A = D\tilde A D^\top`) and :math:`Q` projects out the entropy gradient
    :math:`g = \nabla S` in physical coordinates:

    .. math:: Q = I - \frac{D^2 g\,g^\top}{|Dg|^2 + \varepsilon^2},\qquad
              L = Q A Q^\top = A - (b\,\hat u^\top - \hat u\,b^\top),\quad
              b = A\hat g,

    with :math:`\hat g, \hat u` from :func:`~metriplex.structure._projection.projector_vectors` (the term
    :math:`\hat g^\top A\hat g` vanishes by antisymmetry). Equivalently
    :math:`L = D\tilde P\tilde A\tilde P D` with :math:`\tilde P` the orthogonal projector
    against the standardised gradient :math:`Dg`, so the family does not depend on the units
    of ``x``. :math:`L` is exactly antisymmetric for any weights (it is assembled as
    :math:`K - K^\top`, :math:`K = \tfrac12 A - b\hat u^\top`).

    Exactness: :math:`L\nabla S = A\nabla S\,\varepsilon^2/(|D\nabla S|^2+\varepsilon^2)`,
    so :math:`|D^{-1}L\nabla S| \le \tfrac12\varepsilon\|\tilde A\|` everywhere and the relative
    leak :math:`\varepsilon^2/|D\nabla S|^2` is below rounding wherever
    :math:`|D\nabla S| > \sqrt{\text{machine eps}}\,`\ (1.5e-8 in float64, 3.5e-4 in float32,
    with the default :math:`\varepsilon` = machine epsilon). Where :math:`\nabla S \to 0`
    (``ZeroPotential`` entropy, a critical point) :math:`L \to A` smoothly: no NaN, and with
    no entropy gradient there is nothing to project. Derivatives of :math:`L` grow like
    :math:`1/|D\nabla S|` near a critical point of :math:`S` (any continuous exactly
    degenerate :math:`L` must vanish at a non-degenerate critical point) and are capped at
    :math:`\sim 1/\varepsilon`.

    Options: ``eps`` (:math:`\varepsilon`; ``None``, the default, is machine epsilon) and those
    of :class:`SkewMLPPoisson` (``width``, ``depth``, ``activation``, ``scaling``), which builds
    :math:`A`.

    ```python
    L = ProjectedSkewMLPPoisson(10, key=jr.key(0))
    L(x, grad_entropy) @ grad_entropy  # ~ 0
    ```
    """

    network: ClassVar[type] = SkewMLPPoisson

    uses_gradient: ClassVar[bool] = True
