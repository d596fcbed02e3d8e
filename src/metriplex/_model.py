r"""The GENERIC model :math:`\dot x = L(x)\nabla E(x) + M(x)\nabla S(x)`."""

from __future__ import annotations

import abc
from typing import TYPE_CHECKING, Any, NamedTuple, TypeVar

import equinox as eqx
import jax
import jax.numpy as jnp

from ._errors import MetriplexError
from ._types import Array, Float, Matrix, Scalar, State
from .structure import _registry
from .structure.friction import AbstractFriction
from .structure.poisson import AbstractPoisson
from .structure.potential import AbstractPotential, MLPPotential, SumOf

if TYPE_CHECKING:
    import numpy as np
    from jax.typing import DTypeLike

_M = TypeVar("_M")


class Terms(NamedTuple):
    """Everything GENERIC evaluates at one state, computed once and shared by all losses."""

    energy: Scalar
    entropy: Scalar
    grad_energy: State
    grad_entropy: State
    poisson: Matrix
    friction: Matrix

    @property
    def reversible(self) -> State:
        r"""The reversible part of the field, :math:`L\nabla E`."""
        return self.poisson @ self.grad_energy

    @property
    def irreversible(self) -> State:
        r"""The irreversible part of the field, :math:`M\nabla S`."""
        return self.friction @ self.grad_entropy

    @property
    def vector_field(self) -> State:
        r"""The GENERIC field :math:`L\nabla E + M\nabla S`."""
        return self.reversible + self.irreversible


class AbstractModel(eqx.Module):
    """What :func:`~metriplex.fit`, the schemes and the diagnostics use of a model: its
    :class:`Terms` at a state, its vector field and bracket, and how many variables it has.
    :class:`GenericModel` is the GENERIC one; the verdict's black-box reference is another."""

    @abc.abstractmethod
    def terms(self, x: State) -> Terms:
        """Everything the losses evaluate at the state ``x``."""

    @abc.abstractmethod
    def vector_field(self, x: State) -> State:
        """The time derivative at the state ``x``."""

    @abc.abstractmethod
    def poisson_matrix(self, x: State) -> Matrix:
        """The bivector :math:`L(x)` whose Jacobi identity the diagnostics check."""

    @abc.abstractmethod
    def size(self) -> int | None:
        """The number of state variables, ``None`` where the model cannot tell (a model of
        known functions only)."""


_EXAMPLES = {"energy": "MLPPotential or Known", "entropy": "MLPPotential, SumOf or Known",
             "poisson": "CanonicalPoisson or SkewMLPPoisson",
             "friction": "CholeskyFriction or ZeroFriction"}


class GenericModel(AbstractModel):
    r"""A GENERIC system built from four blocks, each learned or given.

    .. math:: \dot x = L(x)\,\nabla E(x) + M(x)\,\nabla S(x)

    Gradients are taken by autodiff. Ground-truth systems and learned models are both
    ``GenericModel``\ s, so one :func:`metriplex.simulate` and one set of diagnostics serve both.

    ```python
    model = GenericModel(
        energy=MLPPotential(10, key=k1),
        entropy=SumOf((8, 9)),
        poisson=CanonicalPoisson(10, pairs=4),
        friction=CholeskyFriction(10, key=k2),
    )
    model.vector_field(x)  # shape (10,)
    ```
    """

    energy: AbstractPotential
    entropy: AbstractPotential
    poisson: AbstractPoisson
    friction: AbstractFriction

    def __check_init__(self) -> None:
        for role, block, kind in (("energy", self.energy, AbstractPotential),
                                  ("entropy", self.entropy, AbstractPotential),
                                  ("poisson", self.poisson, AbstractPoisson),
                                  ("friction", self.friction, AbstractFriction)):
            if not isinstance(block, kind):
                raise MetriplexError(
                    f"GenericModel's {role} must be an {kind.__name__} block (such as "
                    f"{_EXAMPLES[role]}); got {type(block).__name__}."
                )
        sizes = {role: n for role, n in (
            ("poisson", self.poisson.n), ("friction", self.friction.n),
            ("energy", self.energy.n if isinstance(self.energy, MLPPotential) else None),
            ("entropy", self.entropy.n if isinstance(self.entropy, MLPPotential) else None),
        ) if n is not None}
        if len(set(sizes.values())) > 1:
            raise MetriplexError(
                f"GenericModel's blocks are made for different numbers of state variables: "
                f"{sizes}; build every block for the data's n."
            )
        n = next(iter(sizes.values()), None)
        for role, block in (("energy", self.energy), ("entropy", self.entropy)):
            if isinstance(block, SumOf) and n is not None and not all(
                    0 <= i < n for i in block.indices):
                raise MetriplexError(
                    f"GenericModel's {role} SumOf{block.indices} names variables outside "
                    f"[0, {n - 1}] of its {n} state variables."
                )

    def terms(self, x: State) -> Terms:
        """Everything GENERIC evaluates at the state ``x``, computed once: the potentials, their
        gradients by autodiff and the two matrices."""
        E, gE = jax.value_and_grad(self.energy)(x)
        S, gS = jax.value_and_grad(self.entropy)(x)
        return Terms(E, S, gE, gS, self.poisson(x, gS), self.friction(x, gE))

    def vector_field(self, x: State) -> State:
        r"""The time derivative :math:`\dot x = L\nabla E + M\nabla S` at the state ``x``."""
        return self.terms(x).vector_field

    def __call__(self, x: State) -> State:
        """The vector field at ``x`` (:meth:`vector_field`)."""
        return self.vector_field(x)

    def size(self) -> int | None:
        """The number of state variables, from the first block that states it (``None`` where
        none does, e.g. a model of known functions only)."""
        sizes = (self.poisson.n, self.friction.n,
                 self.energy.n if isinstance(self.energy, MLPPotential) else None)
        return next((n for n in sizes if n is not None), None)

    def poisson_matrix(self, x: State) -> Matrix:
        """The Poisson bivector :math:`L(x)`, its block called with the entropy's gradient."""
        return self.poisson(x, jax.grad(self.entropy)(x))

    def jacobi_tensor(self, x: State) -> Float[Array, "n n n"]:
        r"""The Jacobi residual :math:`J^{ijl} = L^{kl}\partial_k L^{ij} + L^{kj}\partial_k
        L^{li} + L^{ki}\partial_k L^{jl}` at ``x`` (zero for a Poisson bivector).

        Computed as one product :math:`T = (\partial L)\,L` (forward-mode Jacobian, ``n``
        tangents) and two index permutations of ``T``.
        """
        L, dL = _value_and_jacfwd(self.poisson_matrix, x)  # dL[i, j, k] = d_k L^{ij}
        n = x.shape[0]
        T = (dL.reshape(n * n, n) @ L).reshape(n, n, n)  # T[i,j,l] = d_k L^{ij} L^{kl}
        return T + jnp.transpose(T, (1, 2, 0)) + jnp.transpose(T, (2, 0, 1))

    def spec(self) -> dict[str, Any]:
        """A JSON-able description that :meth:`from_spec` turns back into this architecture."""
        return {
            "energy": self.energy.spec(),
            "entropy": self.entropy.spec(),
            "poisson": self.poisson.spec(),
            "friction": self.friction.spec(),
        }

    @classmethod
    def from_spec(cls, spec: dict[str, Any], n: int, *, key: jax.Array) -> "GenericModel":
        """The model that ``spec`` (the output of :meth:`spec`) describes, for ``n`` variables, each
        block rebuilt through the block registry; ``key`` draws weights that the model file then
        overwrites."""
        k1, k2, k3, k4 = jax.random.split(key, 4)
        return cls(
            energy=_registry.from_spec("potential", spec["energy"], n, key=k1),
            entropy=_registry.from_spec("potential", spec["entropy"], n, key=k2),
            poisson=_registry.from_spec("poisson", spec["poisson"], n, key=k3),
            friction=_registry.from_spec("friction", spec["friction"], n, key=k4),
        )


def weights(model: Any) -> list[jax.Array]:
    """The floating-point weights of ``model`` (or of a block): its trainable leaves; none for
    given functions, such as a ground-truth system's."""
    return jax.tree_util.tree_leaves(eqx.filter(model, eqx.is_inexact_array))


def float_dtype(model: Any, default: DTypeLike | None = None) -> np.dtype:
    """The dtype of the model's floating-point weights (``default``, or JAX's default float
    type, for a model without any, such as a ground-truth system)."""
    leaves = weights(model)
    if leaves:
        return leaves[0].dtype
    return jnp.zeros(()).dtype if default is None else jnp.dtype(default)


def with_dtype(model: _M, dtype: DTypeLike) -> _M:
    """``model`` with every floating-point weight cast to ``dtype``."""
    return jax.tree_util.tree_map(
        lambda a: a.astype(dtype) if eqx.is_inexact_array(a) else a, model
    )


def _value_and_jacfwd(fn, x):
    """``(fn(x), d fn / dx)`` with the Jacobian's input axis last, in forward mode."""
    basis = jnp.eye(x.shape[0], dtype=x.dtype)
    y, dy = jax.vmap(lambda v: jax.jvp(fn, (x,), (v,)), out_axes=(None, -1))(basis)
    return y, dy
