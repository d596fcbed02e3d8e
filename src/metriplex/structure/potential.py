r"""Scalar potentials: the energy :math:`E(x)` and the entropy :math:`S(x)`.

Every potential maps a state ``x`` of shape ``(n,)`` to a scalar; its gradient is taken by
autodiff in :class:`metriplex.GenericModel`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Callable, Iterable, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._errors import MetriplexError
from .._types import Array, Float, Scalar, State
from ._mlp import (ACTIVATION, DEPTH, WIDTH, Hidden, check_states, data_statistics,
                   network_spec, standardise)
from ._abstract import AbstractPotential
from .confinement import Confinement
from ._registry import register

if TYPE_CHECKING:
    from numpy.typing import ArrayLike


class FeatureMap(eqx.Module):
    r"""Fixed input features: squared distances :math:`|x_a - x_b|^2` and raw components.

    ``squared_norms`` is a tuple of ``(a, b)`` index tuples (``b`` may be empty, giving
    :math:`|x_a|^2`); ``passthrough`` lists components passed unchanged. The paper's pendulum
    featurisation is ``squared_norms=(((0,1),()), ((2,3),(0,1)), ((4,5),()), ((6,7),()))``,
    ``passthrough=(8, 9)``: rotation-invariant by construction.
    """

    squared_norms: tuple[tuple[tuple[int, ...], tuple[int, ...]], ...] = eqx.field(static=True)
    passthrough: tuple[int, ...] = eqx.field(static=True)

    def __init__(self, squared_norms: Iterable[Sequence[Iterable[int]]] = (),
                 passthrough: Iterable[int] = ()) -> None:
        self.squared_norms = tuple(
            (tuple(int(i) for i in a), tuple(int(i) for i in b)) for a, b in squared_norms
        )
        self.passthrough = tuple(int(i) for i in passthrough)
        for a, b in self.squared_norms:
            if b and len(a) != len(b):
                raise MetriplexError(
                    f"a squared distance |x_a - x_b|^2 needs index groups of equal length; got "
                    f"a={a}, b={b}."
                )

    @property
    def size(self) -> int:
        """The number of features: one per squared distance and one per passed component."""
        return len(self.squared_norms) + len(self.passthrough)

    def check(self, n: int) -> None:
        """Raise :class:`~metriplex.MetriplexError` unless every index is a component of a state of
        ``n`` variables."""
        used = [i for a, b in self.squared_norms for i in (*a, *b)] + list(self.passthrough)
        bad = [i for i in used if not 0 <= i < n]
        if bad:
            raise MetriplexError(
                f"feature indices must lie in [0, {n - 1}] for a state of {n} variables; got "
                f"{bad}."
            )

    def __call__(self, x: State) -> Float[Array, " features"]:
        """The features of the state ``x``: the squared distances, then the passed components; shape
        ``(size,)``."""
        parts = []
        for a, b in self.squared_norms:
            d = x[jnp.array(a)] - (x[jnp.array(b)] if b else 0.0)
            parts.append(jnp.sum(d**2)[None])
        if self.passthrough:
            parts.append(x[jnp.array(self.passthrough)])
        return jnp.concatenate(parts)

    def to_json(self) -> dict[str, Any]:
        """The constructor's arguments as JSON lists: ``FeatureMap(**to_json())`` rebuilds it."""
        return {
            "squared_norms": [[list(a), list(b)] for a, b in self.squared_norms],
            "passthrough": list(self.passthrough),
        }


@register("potential", "neural")
class MLPPotential(AbstractPotential):
    r"""A learned potential: an MLP with C^\infty activations, :math:`\mathbb R^n\to\mathbb R`.

    Inputs (after the optional ``features``) are standardised with statistics of ``data`` when
    given, so that states of very different magnitudes (e.g. temperatures ~300 and entropies
    ~1e-2) are learned equally well. ``output_scale`` :math:`\sigma` multiplies the network:
    :math:`E = \sigma\tilde E`, so that a network of order one has the potential's natural size
    (e.g. when it pairs with a given Poisson bivector; see :class:`metriplex.Units`).
    ``linear`` adds a fixed linear term :math:`a^\top z` in the standardised inputs, zero
    until it is set and not trained (the gradient stops at it, so a zero term changes no step
    of a training; only ``--weight-decay``, off by default, shrinks a set one): a slope that
    the network alone would have to grow from order one (a temperature :math:`\partial
    E/\partial s` far larger than the gradients that drive the motion), which training sets
    from the data (README, *Friction that carries the motion*). ``confinement`` (a
    :class:`~metriplex.structure.Confinement`) adds a wall that is zero on a box a little
    wider than the training data and quartic outside it, so that the level sets of the
    potential are bounded: :math:`E = \sigma(\tilde E + W)`.

    ```python
    E = MLPPotential(10, width=64, depth=2, key=jr.key(0))
    E(jnp.zeros(10))  # a scalar
    ```
    """

    hidden: Hidden
    out: eqx.nn.Linear
    n: int = eqx.field(static=True)
    features: FeatureMap | None
    shift: tuple[float, ...] | None = eqx.field(static=True)
    scale: tuple[float, ...] | None = eqx.field(static=True)
    output_scale: float = eqx.field(static=True)
    quadratic: jax.Array | None
    confinement: Confinement | None
    linear: jax.Array | None

    def __init__(
        self, n: int, *,
        width: int = WIDTH, depth: int = DEPTH, activation: str = ACTIVATION,
        features: FeatureMap | None = None,
        data: ArrayLike | None = None,
        shift: Sequence[float] | None = None,
        scale: Sequence[float] | None = None,
        output_scale: float = 1.0,
        quadratic: bool = False,
        confinement: Confinement | None = None,
        linear: bool = False,
        key: jax.Array,
    ) -> None:
        import jax.random as jr

        if not (np.isfinite(output_scale) and output_scale > 0):
            raise MetriplexError(
                f"MLPPotential output_scale must be finite and > 0; got {output_scale}."
            )
        self.output_scale = float(output_scale)
        self.n = n
        self.features = features
        if features is not None:
            features.check(n)
        in_size = n if features is None else features.size
        if data is not None:
            z = check_states(data, n)  # the states' width, before any feature reads them
            if features is not None:
                import jax

                z = np.asarray(jax.vmap(features)(jnp.asarray(z)))
            shift, scale = data_statistics(z, in_size)
        self.shift = None if shift is None else tuple(float(v) for v in shift)
        self.scale = None if scale is None else tuple(float(v) for v in scale)
        hkey, okey, qkey = jr.split(key, 3)
        self.hidden = Hidden(in_size, width, depth, activation, key=hkey)
        self.out = eqx.nn.Linear(width, "scalar", key=okey)
        # A learned quadratic form beside the network: the second-order Taylor term, which
        # extrapolates linearly in the forces where the network alone would be arbitrary.
        self.quadratic = (jr.normal(qkey, (in_size, in_size)) / np.sqrt(in_size)
                          if quadratic else None)
        self.confinement = confinement
        self.linear = jnp.zeros(in_size) if linear else None

    def __call__(self, x: State) -> Scalar:
        z = x if self.features is None else self.features(x)
        z = standardise(z, self.shift, self.scale)
        y = self.out(self.hidden(z))
        if self.linear is not None:
            y = y + z @ jax.lax.stop_gradient(self.linear.astype(z.dtype))
        if self.quadratic is not None:
            W = self.quadratic.astype(z.dtype)
            y = y + 0.25 * (z @ (W + W.T) @ z)
        if self.confinement is not None:
            y = y + self.confinement(x)
        return y if self.output_scale == 1.0 else self.output_scale * y

    def spec(self) -> dict[str, Any]:
        return network_spec(
            "neural", self.hidden,
            features=None if self.features is None else self.features.to_json(),
            shift=self.shift,
            scale=self.scale,
            output_scale=self.output_scale,
            quadratic=self.quadratic is not None,
            confinement=None if self.confinement is None else self.confinement.to_json(),
            **({"linear": True} if self.linear is not None else {}),
        )

    @classmethod
    def from_spec(cls, spec: dict[str, Any], n: int, *, key: jax.Array) -> "MLPPotential":
        """The block that ``spec`` (the output of :meth:`spec`) describes, for ``n`` variables;
        ``key`` draws weights that the model file then overwrites."""
        feats = spec.get("features")
        wall = spec.get("confinement")
        return cls(
            n,
            width=spec["width"],
            depth=spec["depth"],
            activation=spec.get("activation", ACTIVATION),
            features=None if feats is None else FeatureMap(**feats),
            shift=spec.get("shift"),
            scale=spec.get("scale"),
            output_scale=spec.get("output_scale", 1.0),
            quadratic=spec.get("quadratic", False),
            confinement=None if wall is None else Confinement.from_json(wall),
            linear=spec.get("linear", False),
            key=key,
        )


@register("potential", "sum")
class SumOf(AbstractPotential):
    r"""A known linear potential :math:`S(x) = \sum_{i\in I} x_i` (e.g. total entropy)."""

    indices: tuple[int, ...] = eqx.field(static=True)

    def __init__(self, indices: Iterable[int]) -> None:
        self.indices = tuple(int(i) for i in indices)
        if not self.indices:
            raise MetriplexError("SumOf needs at least one index; got an empty list.")

    def __call__(self, x: State) -> Scalar:
        return jnp.sum(x[jnp.array(self.indices)])

    def spec(self) -> dict[str, Any]:
        return {"kind": "sum", "indices": list(self.indices)}

    @classmethod
    def from_spec(cls, spec: dict[str, Any], n: int, *, key: jax.Array) -> "SumOf":
        """The ``SumOf`` of the indices saved in ``spec`` (``n`` and ``key`` are not needed)."""
        return cls(spec["indices"])


@register("potential", "zero")
class ZeroPotential(AbstractPotential):
    """The zero potential (e.g. no entropy for a conservative system)."""

    def __call__(self, x: State) -> Scalar:
        return jnp.zeros((), x.dtype)

    def spec(self) -> dict[str, Any]:
        return {"kind": "zero"}

    @classmethod
    def from_spec(cls, spec: dict[str, Any], n: int, *, key: jax.Array) -> "ZeroPotential":
        """The zero potential (``spec``, ``n`` and ``key`` are not needed)."""
        return cls()


class Known(AbstractPotential):
    """A potential given by a user function ``fn(x) -> scalar`` written with ``jax.numpy``.

    Used for ground-truth systems. It cannot be written to a model file (files never hold code).
    """

    fn: Callable = eqx.field(static=True)

    def __call__(self, x: State) -> Scalar:
        return self.fn(x)
