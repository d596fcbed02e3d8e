r"""Friction matrices :math:`M(x)`: symmetric positive semi-definite.

Every friction block is called as ``friction(x, grad_energy)``, so that exactly degenerate
variants (:math:`M\nabla E = 0` by construction) can use the energy gradient.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, ClassVar, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._types import Matrix, State
from ._mlp import ACTIVATION, DEPTH, WIDTH
from ._mlp import FoldedHead, Hidden, check_states, check_variables, data_statistics
from ._mlp import folded_network, network_spec, standardise
from ._abstract import AbstractFriction
from ._fixed import AbstractFunctionMatrix, AbstractZeroMatrix
from ._registry import network_kwargs, register
from ._projection import AbstractProjected, check_eps, eps_squared
from .potential import FeatureMap
from .scaling import Scaling, scaling_spec, standardise_state

if TYPE_CHECKING:
    from numpy.typing import ArrayLike


@register("friction", "neural")
class CholeskyFriction(AbstractFriction):
    r"""Learned :math:`M(x) = B(x)B(x)^\top` with :math:`B` lower-triangular.

    :math:`B` has :math:`n(n+1)/2` network outputs; :math:`M` is symmetric and positive
    semi-definite for any weights. With a scaling, :math:`M = D\tilde B\tilde B^\top D^\top`.

    The network sees the standardised state, or, with ``features``, the standardised features
    of the state (statistics from ``data``). Invariant features (such as the pendulum's squared
    lengths) suit a friction whose entries are invariant functions of the state, e.g. heat
    conduction that depends only on the temperatures; the matrix itself is still indexed by the
    state's components.
    """

    hidden: Hidden
    head: FoldedHead
    n: int = eqx.field(static=True)
    scaling: Scaling | None = eqx.field(static=True)
    features: FeatureMap | None
    input_stats: tuple[tuple[float, ...], tuple[float, ...]] | None = eqx.field(static=True)

    def __init__(
        self, n: int, *,
        width: int = WIDTH, depth: int = DEPTH, activation: str = ACTIVATION,
        scaling: Scaling | None = None,
        features: FeatureMap | None = None,
        data: ArrayLike | None = None,
        input_stats: Sequence[Sequence[float]] | None = None,
        key: jax.Array,
    ) -> None:
        check_variables(n, 1, "a friction matrix")
        self.n = n
        self.scaling = scaling
        self.features = features
        if features is not None:
            features.check(n)
            if data is not None and input_stats is None:
                z = jax.vmap(features)(jnp.asarray(check_states(data, n)))
                input_stats = data_statistics(np.asarray(z), features.size)
        self.input_stats = (
            None if input_stats is None
            else tuple(tuple(float(v) for v in part) for part in input_stats)
        )
        in_size = n if features is None else features.size
        # Small initial B: training starts close to reversible dynamics.
        self.hidden, self.head = folded_network(
            in_size, n, "lower", width=width, depth=depth, activation=activation,
            scaling=scaling, init_scale=0.1, key=key,
        )

    def _inputs(self, x: State):
        if self.features is not None:
            stats = self.input_stats
            z = self.features(x)
            return z if stats is None else standardise(z, stats[0], stats[1])
        return standardise_state(x, self.scaling)

    def factor(self, x: State) -> Matrix:
        r"""The lower-triangular factor :math:`B(x)` of :math:`M = BB^\top`, shape ``(n, n)``."""
        return self.head(self.hidden(self._inputs(x)))

    uses_gradient: ClassVar[bool] = False

    def __call__(self, x: State, grad_energy: State | None = None) -> Matrix:
        B = self.factor(x)
        return B @ B.T

    def spec(self) -> dict[str, Any]:
        return network_spec(
            "neural", self.hidden,
            scaling=scaling_spec(self.scaling),
            features=None if self.features is None else self.features.to_json(),
            input_stats=None if self.input_stats is None else [list(v) for v in
                                                               self.input_stats],
        )

    @staticmethod
    def spec_options(spec: dict[str, Any]) -> dict[str, Any]:
        """The constructor's options saved in ``spec``."""
        feats = spec.get("features")
        return {
            **network_kwargs(spec),
            "features": None if feats is None else FeatureMap(**feats),
            "input_stats": spec.get("input_stats"),
        }

    @classmethod
    def from_spec(cls, spec: dict[str, Any], n: int, *, key: jax.Array) -> "CholeskyFriction":
        """The block that ``spec`` (the output of :meth:`spec`) describes, for ``n`` variables;
        ``key`` draws weights that the model file then overwrites."""
        return cls(n, **cls.spec_options(spec), key=key)


@register("friction", "zero")
class ZeroFriction(AbstractZeroMatrix, AbstractFriction):
    """No dissipation: :math:`M = 0`."""

    uses_gradient: ClassVar[bool] = False


class KnownFriction(AbstractFunctionMatrix, AbstractFriction):
    """A friction matrix given by a function ``fn(x) -> (n, n)`` (ground-truth systems)."""

    uses_gradient: ClassVar[bool] = False


# -- exactly degenerate variant ----------------------------------------------------------------


@register("friction", "projected-neural")
class ProjectedCholeskyFriction(AbstractProjected, AbstractFriction):
    r"""Learned :math:`M` with :math:`M\nabla E = 0` by construction: :math:`M = F F^\top`,
    :math:`F = Q B`.

    :math:`B(x)` is the factor of a :class:`CholeskyFriction` (same network, same
    normalisation, :math:`B = D\tilde B`) and :math:`Q` projects out the energy gradient
    :math:`g = \nabla E` in physical coordinates,

    .. math:: Q = I - \frac{D^2 g\,g^\top}{|Dg|^2 + \varepsilon^2},\qquad
              F = B - \hat u\,(B^\top\hat g)^\top,

    (:math:`\hat g = g/\sqrt s`, :math:`\hat u = D^2 g/\sqrt s`, :math:`s = |Dg|^2 +
    \varepsilon^2`), i.e. :math:`M = D\tilde P\tilde B\tilde B^\top\tilde P D` with
    :math:`\tilde P` the orthogonal projector against the standardised gradient :math:`Dg`.
    :math:`M` is symmetric positive semi-definite for any weights (a Gram matrix).

    Exactness: :math:`M\nabla E = F B^\top\nabla E\,\varepsilon^2/s`, below rounding wherever
    :math:`|D\nabla E| > \sqrt{\text{machine eps}}` with the default :math:`\varepsilon` (machine
    epsilon of the dtype); where :math:`\nabla E \to 0`, :math:`M \to BB^\top` smoothly (no NaN).
    Then :math:`dE/dt = \nabla E^\top L\nabla E + (M\nabla E)^\top\nabla S = 0` to rounding.

    Options: ``eps`` (:math:`\varepsilon`; ``None``, the default, is machine epsilon) and those
    of :class:`CholeskyFriction` (``width``, ``depth``, ``activation``, ``scaling``,
    ``features``, ``data``, ``input_stats``), which builds :math:`B`.
    """

    network: ClassVar[type] = CholeskyFriction

    def factor(self, x: State, grad_energy: State) -> Matrix:
        r"""The factor :math:`F = \tilde P B` of :math:`M = FF^\top`: the network's :math:`B(x)`
        projected against :math:`\nabla E` (``grad_energy``), shape ``(n, n)``."""
        B = self.base.factor(x)
        g_hat, u_hat = self._projector(grad_energy, x.dtype)
        return B - jnp.outer(u_hat, g_hat @ B)

    uses_gradient: ClassVar[bool] = True

    def __call__(self, x: State, grad_energy: State) -> Matrix:
        F = self.factor(x, grad_energy)
        return F @ F.T


@register("friction", "exchange")
class ExchangeFriction(AbstractFriction):
    r"""Learned pairwise exchange: :math:`M\nabla E = 0` and :math:`M \succeq 0` by construction,

    .. math:: M(x) = f\,D\Big[\sum_{i<j} w_{ij}(x)\,\zeta_{ij}\zeta_{ij}^\top\Big]D,\qquad
              \zeta_{ij} = \frac{h_j e_i - h_i e_j}{\sqrt{|h|^2 + \varepsilon^2}},\quad
              h = D\nabla E,

    with :math:`w_{ij} = a_{ij}(x)^2 \ge 0` from a network of :math:`n(n-1)/2` outputs (``f`` and
    ``D`` those of the scaling). Each term moves one conserved quantity between the variables
    :math:`i` and :math:`j` at the rate that keeps :math:`E` fixed: heat conducted between two
    cells, momentum damped into a bath. Since :math:`\zeta_{ij}\cdot h = 0`, :math:`M\nabla E`
    vanishes to rounding at every state; :math:`M \to 0` smoothly where :math:`\nabla E \to 0`.

    Entries: :math:`\tilde M_{ii} = \sum_j w_{ij}h_j^2/s`, :math:`\tilde M_{ij} = -w_{ij}h_ih_j/s`
    (:math:`s = |h|^2 + \varepsilon^2`), assembled in :math:`O(n^2)`.
    """

    hidden: Hidden
    head: eqx.nn.Linear
    n: int = eqx.field(static=True)
    scaling: Scaling | None = eqx.field(static=True)
    eps: float | None = eqx.field(static=True)

    def __init__(self, n: int, *, width: int = WIDTH, depth: int = DEPTH,
                 activation: str = ACTIVATION, scaling: Scaling | None = None,
                 eps: float | None = None, key: jax.Array) -> None:
        check_variables(n, 2, "an exchange friction", "It moves E between pairs of variables; "
                        "with one variable use CholeskyFriction (--friction neural).")
        check_eps(eps)
        self.n = n
        self.scaling = scaling
        self.eps = None if eps is None else float(eps)
        hkey, okey = jax.random.split(key)
        self.hidden = Hidden(n, width, depth, activation, key=hkey)
        head = eqx.nn.Linear(width, n * (n - 1) // 2, key=okey)
        # Small initial rates, as CholeskyFriction's 0.1-scaled factor.
        self.head = eqx.tree_at(lambda l: (l.weight, l.bias), head,
                                (0.1 * head.weight, 0.1 * head.bias))

    def rates(self, x: State) -> Matrix:
        r"""The symmetric, zero-diagonal matrix of the exchange rates :math:`w_{ij}(x) \ge 0`."""
        a = self.head(self.hidden(standardise_state(x, self.scaling)))
        i, j = np.triu_indices(self.n, 1)
        W = jnp.zeros((self.n, self.n), a.dtype).at[i, j].set(a * a)
        return W + W.T

    uses_gradient: ClassVar[bool] = True

    def __call__(self, x: State, grad_energy: State) -> Matrix:
        W = self.rates(x)
        d = (jnp.ones(self.n, x.dtype) if self.scaling is None
             else jnp.asarray(self.scaling.scale, x.dtype))
        h = d * grad_energy
        e2 = eps_squared(self.eps, x.dtype)
        s = jnp.sum(h * h) + jnp.asarray(e2, x.dtype)
        Mt = (jnp.diag(W @ (h * h)) - W * jnp.outer(h, h)) / s
        f = 1.0 if self.scaling is None else self.scaling.factor
        return f * (d[:, None] * Mt * d[None, :])

    def spec(self) -> dict[str, Any]:
        return network_spec("exchange", self.hidden, scaling=scaling_spec(self.scaling),
                            eps=self.eps)

    @classmethod
    def from_spec(cls, spec: dict[str, Any], n: int, *, key: jax.Array) -> "ExchangeFriction":
        """The block that ``spec`` (the output of :meth:`spec`) describes, for ``n`` variables;
        ``key`` draws weights that the model file then overwrites."""
        return cls(n, **network_kwargs(spec), eps=spec.get("eps"), key=key)
