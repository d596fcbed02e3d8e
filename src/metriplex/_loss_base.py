"""The machinery every loss term shares: the :class:`Batch` of pairs a term reads (with its
:class:`Window` of rollout targets, when a term asks for one), the :class:`Context` of model
terms shared by all terms, :class:`AbstractLossTerm` and the weighted sum :class:`Loss`.
The terms themselves are in :mod:`metriplex.losses`, which re-exports these names."""

from __future__ import annotations

import abc
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.random as jr

from ._errors import MetriplexError
from ._model import GenericModel, Terms


class Window(NamedTuple):
    """Stretches of ``K`` consecutive steps of the training trajectories, for
    :class:`RolloutWindow`: from ``x0`` ``(W, n)``, the data ``targets`` ``(W, K, n)`` after
    steps ``dt`` ``(W, K)``; ``mask`` ``(W, K)`` is ``False`` past a trajectory's end."""

    x0: jax.Array
    targets: jax.Array
    dt: jax.Array
    mask: jax.Array


class Runs(NamedTuple):
    """How a batch drawn as runs of consecutive samples shares its states: the distinct
    ``states`` ``(S, n)`` and, for every pair, the rows ``first`` and ``second`` ``(B,)`` of
    its two states in them (the second state of one pair is the first of the next)."""

    states: jax.Array
    first: jax.Array
    second: jax.Array


class Batch(NamedTuple):
    """Data pairs as the loss reads them: states ``x0`` and ``x1`` ``(B, n)`` a step ``dt``
    ``(B,)`` apart, the per-component ``scale`` ``(n,)`` in which every term is measured, and
    the :class:`Window` of a training batch when a term reads one.

    Training batches drawn as runs of consecutive samples (``fit(consecutive=K)``) also carry
    their :class:`Runs`, so the loss evaluates each state once, and a ``weight`` ``(B,)``: 0
    where a run crosses from one trajectory into the next, so that "pair" is no pair of the
    data (its states are data states; its difference is not a step). Terms that read pair
    differences weigh them out; see :attr:`AbstractLossTerm.reads_runs`."""

    x0: jax.Array  # (B, n)
    x1: jax.Array  # (B, n)
    dt: jax.Array  # (B,)
    scale: jax.Array  # (n,) per-component data scale
    window: Window | None = None  # training batches of a loss with a RolloutWindow term
    weight: jax.Array | None = None  # (B,) 1 for a pair of the data, 0 across trajectories
    runs: Runs | None = None  # shared states of a batch drawn as runs


class Context(NamedTuple):
    """The model's :class:`~metriplex.Terms` at both states of every pair (and at their
    midpoints when a term asks for them), evaluated once and shared by every loss term."""

    terms0: Terms  # batched over B
    terms1: Terms
    mid: Terms | None = None  # at the midpoints (x0 + x1)/2, when a term asks for them


class AbstractLossTerm(eqx.Module):
    """One named term of the loss; returns the batch mean of a squared norm. Each final term
    states its ``name`` (the key of its figure in the training history)."""

    name: eqx.AbstractClassVar[str]

    @property
    def needs_midpoints(self) -> bool:
        """Whether this term reads ``ctx.mid`` (then :class:`Loss` evaluates it once)."""
        return False

    @property
    def window_shape(self) -> tuple[int, int] | None:
        """``(windows, steps)`` of the :class:`Window` this term reads from ``batch.window``,
        or ``None``. A term that reads windows is left out where a batch has none (the
        evaluation subsets of pairs)."""
        return None

    @property
    def reads_runs(self) -> bool:
        """Whether this term may be given batches drawn as runs of consecutive samples: it
        reads only the states, or it weighs each pair by ``batch.weight`` (0 where a run
        crosses into the next trajectory). ``False`` by default, so a term of your own gets
        independent pairs unless it says otherwise."""
        return False

    @abc.abstractmethod
    def __call__(self, model: GenericModel, batch: Batch, ctx: Context,
                 key: jax.Array) -> jax.Array:
        """The term's value on ``batch``, a scalar: ``ctx`` holds the shared evaluation of the
        model on the batch, ``key`` draws any random probes."""

    def as_loss(self) -> "Loss":
        """This term alone as a :class:`Loss` of weight 1."""
        return Loss((self,), (1.0,))

    def __add__(self, other):
        return self.as_loss() + other

    def __radd__(self, other):
        return self.as_loss().__radd__(other)

    def __mul__(self, w):
        return self.as_loss() * w

    __rmul__ = __mul__


class Loss(eqx.Module):
    """A weighted sum of loss terms. ``loss(model, batch, key=k)`` returns ``(total, parts)``."""

    terms: tuple[AbstractLossTerm, ...]
    weights: tuple[float, ...] = eqx.field(static=True)

    def as_loss(self) -> "Loss":
        """This loss itself (so a term or a loss can be passed wherever a loss is taken)."""
        return self

    def __add__(self, other):
        if isinstance(other, (int, float)) and other == 0:
            return self
        other = other.as_loss()
        return Loss(self.terms + other.terms, self.weights + other.weights)

    def __radd__(self, other):
        if isinstance(other, (int, float)) and other == 0:
            return self
        return NotImplemented

    def __mul__(self, w):
        if not isinstance(w, (int, float)):
            return NotImplemented
        if w < 0:
            raise MetriplexError(f"loss weights must be >= 0; got {w}.")
        return Loss(self.terms, tuple(float(w) * v for v in self.weights))

    __rmul__ = __mul__

    @property
    def names(self) -> tuple[str, ...]:
        """The names of the terms, in order (the keys of the parts :meth:`__call__` returns)."""
        return tuple(t.name for t in self.terms)

    @property
    def window_shape(self) -> tuple[int, int] | None:
        """``(windows, steps)`` that the training batches must carry (the largest asked for by
        any term), or ``None`` when no term reads windows."""
        shapes = [t.window_shape for t in self.terms if t.window_shape is not None]
        if not shapes:
            return None
        return max(w for w, _ in shapes), max(k for _, k in shapes)

    @property
    def reads_runs(self) -> bool:
        """Whether every term may be given batches drawn as runs of consecutive samples
        (:attr:`AbstractLossTerm.reads_runs`); :func:`~metriplex.fit` draws independent pairs
        otherwise."""
        return all(t.reads_runs for t in self.terms) and self.window_shape is None

    def __call__(self, model: GenericModel, batch: Batch, *,
                 key: jax.Array | None = None) -> tuple[jax.Array, dict[str, jax.Array]]:
        """The weighted total on ``batch`` and each term's unweighted value by name; terms that
        read windows are left out where the batch has none."""
        # Terms nobody reads (e.g. gradients at the states when only the discrete-gradient
        # residual and midpoint penalties are used) are removed by XLA under jit.
        if batch.runs is not None:
            # Each state once: a run of K pairs has K + 1 states, not 2K.
            each = jax.vmap(model.terms)(batch.runs.states)
            terms0 = jax.tree_util.tree_map(lambda a: a[batch.runs.first], each)
            terms1 = jax.tree_util.tree_map(lambda a: a[batch.runs.second], each)
        else:
            # One evaluation over both states of every pair: twice-as-tall matmuls and half
            # as many kernels as two separate vmaps (see docs/performance.md).
            B = batch.x0.shape[0]
            both = jax.vmap(model.terms)(jnp.concatenate([batch.x0, batch.x1]))
            terms0 = jax.tree_util.tree_map(lambda a: a[:B], both)
            terms1 = jax.tree_util.tree_map(lambda a: a[B:], both)
        mid = None
        if any(t.needs_midpoints for t in self.terms):
            mid = jax.vmap(model.terms)(0.5 * (batch.x0 + batch.x1))
        ctx = Context(terms0, terms1, mid)
        keys = jr.split(jr.key(0) if key is None else key, len(self.terms))
        parts: dict[str, jax.Array] = {}
        total = jnp.zeros((), batch.x0.dtype)
        for term, w, k in zip(self.terms, self.weights, keys):
            if term.window_shape is not None and batch.window is None:
                continue
            value = term(model, batch, ctx, k)
            parts[term.name] = parts.get(term.name, 0.0) + value
            total = total + w * value
        return total, parts
