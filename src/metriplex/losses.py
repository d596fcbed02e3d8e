r"""Training losses on data pairs :math:`(x_n, x_{n+1}, \Delta t_n)`.

Loss terms are small objects that compose with ``+`` and scalar ``*``, as in the seed paper's
:math:`\mathcal L = w_t\mathcal L_{traj} + w_S\mathcal L_{L\nabla S} + w_E\mathcal L_{M\nabla E}
+ w_J\mathcal L_{Jac}`:

```python
loss = CrankNicolsonResidual() + 10.0 * DegeneracyPenalty() + 1.0 * JacobiPenalty(ExactJacobi())
```

Options are objects, as elsewhere in the library: the Jacobi penalty takes an estimator
(:class:`ExactJacobi`, :class:`StochasticJacobi`), and a degeneracy penalty a flag
``at_midpoints``; the command line's spellings (``--jacobi``, ``--degeneracy-at``) are parsed
in :mod:`metriplex.app`.

Each term is a mean over the batch of a squared norm. Every term is measured in standardised
state units: the trainer passes the per-component data scale ``d``, residuals are divided by
``d`` componentwise and the Jacobi tensor by :math:`d_i d_j d_l`, so variables of very different
magnitudes weigh alike. One evaluation of :math:`E, S, \nabla E, \nabla S, L, M` at both states
of a pair is shared by all terms.
"""

from __future__ import annotations

import abc
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np

from ._errors import MetriplexError, count_of, expect_instance
from ._loss_base import AbstractLossTerm, Batch, Context, Loss, Window
from ._model import GenericModel, Terms
from ._types import Matrix, Scalar, State
from .integrate import AbstractScheme, CrankNicolson, DiscreteGradient, ImplicitMidpoint

# The terms, their sum and what a term of your own subclasses and receives (AbstractLossTerm,
# Batch, Context, Window: the extension API, defined in _loss_base).
__all__ = ["AbstractJacobiEstimator", "AbstractLossTerm", "Batch", "Context",
           "CrankNicolsonResidual", "DegeneracyPenalty", "DiscreteGradientResidual",
           "ExactJacobi", "FrictionDegeneracy", "JacobiPenalty", "Loss", "MidpointResidual",
           "NegativeTemperature", "PoissonDegeneracy", "SchemeResidual", "StochasticJacobi",
           "Window", "stochastic_jacobi"]


def _sq(v, scale, weight=None, metric=None):
    u = v / scale[None, :]
    per = jnp.sum(u**2, axis=-1) if metric is None else jnp.sum(u * (u @ metric.astype(u.dtype)),
                                                                axis=-1)
    if weight is None:
        return jnp.mean(per)
    # where, not a product: a weighed-out "pair" across trajectories may be anything
    return jnp.sum(jnp.where(weight > 0, weight * per, 0.0)) / jnp.maximum(jnp.sum(weight), 1)


def _metric(w):
    """A residual metric as a float array, checked: square, symmetric, positive definite."""
    if w is None or isinstance(w, jax.core.Tracer):  # built under a transform: unchecked
        return w
    a = np.asarray(w, dtype=np.float64)
    if a.ndim != 2 or a.shape[0] != a.shape[1] or not np.all(np.isfinite(a)) \
            or not np.allclose(a, a.T, rtol=1e-10, atol=0.0) or np.linalg.eigvalsh(a).min() <= 0:
        raise MetriplexError(
            f"SchemeResidual's metric must be a finite, symmetric, positive definite (n, n) "
            f"matrix; got shape {a.shape}. Use metriplex.Units.residual_metric(data), or leave "
            f"it out for the plain residual.")
    return jnp.asarray(a)


class SchemeResidual(AbstractLossTerm):
    r"""The defect of each pair under a time-stepping scheme, e.g. Crank–Nicolson:

    .. math:: r_n = \frac{x_{n+1}-x_n}{\Delta t_n} - \tfrac12\big(f(x_n) + f(x_{n+1})\big).

    It needs no derivative of the data, only the pairs and their own ``dt``. Each residual
    is measured in the data's rate units (``scale``) as :math:`|r|^2`, or as
    :math:`r^\top W r` with a ``metric`` :math:`W` ``(n, n)``, symmetric positive definite
    (:meth:`metriplex.Units.residual_metric`: weight on combinations of variables that the
    data keep nearly still).
    """

    scheme: AbstractScheme
    metric: Matrix | None = eqx.field(default=None, converter=_metric)
    name: ClassVar[str] = "residual"

    @property
    def reads_runs(self) -> bool:
        return True  # weighs each pair by batch.weight

    @property
    def needs_midpoints(self) -> bool:
        # The discrete-gradient residual evaluates the model at the midpoints anyway; taking
        # those terms from the shared context lets midpoint penalties reuse them.
        return isinstance(self.scheme, DiscreteGradient)

    def __call__(self, model: GenericModel, batch: Batch, ctx: Context,
                 key: jax.Array) -> jax.Array:
        args = (model, batch.x0, batch.x1, batch.dt, ctx.terms0, ctx.terms1)
        if self.needs_midpoints:
            r = jax.vmap(self.scheme.residual, in_axes=(None, 0, 0, 0, 0, 0, 0))(*args, ctx.mid)
        else:
            r = jax.vmap(self.scheme.residual, in_axes=(None, 0, 0, 0, 0, 0))(*args)
        return _sq(r, batch.scale, batch.weight, self.metric)


class _AbstractDegeneracy(AbstractLossTerm):
    at_midpoints: bool = eqx.field(static=True, default=False)

    def __check_init__(self):
        expect_instance(
            self.at_midpoints, bool, what=f"{type(self).__name__}'s at_midpoints",
            expected="True (once per pair, at the midpoints (x0 + x1)/2) or False (at both "
            "states of each pair, the default)",
            fix="Write at_midpoints=True for the former where='midpoints', and leave it out "
            "for 'states'.",
        )

    @property
    def needs_midpoints(self) -> bool:
        return self.at_midpoints

    @property
    def reads_runs(self) -> bool:
        # At the states: every state of a run is a data state. At the midpoints of pairs,
        # a midpoint across two trajectories is none.
        return not self.at_midpoints

    @staticmethod
    def _defect(t: Terms) -> jax.Array: ...

    def __call__(self, model: GenericModel, batch: Batch, ctx: Context,
                 key: jax.Array) -> jax.Array:
        if self.at_midpoints:
            return _sq(self._defect(ctx.mid), batch.scale)
        return 0.5 * (_sq(self._defect(ctx.terms0), batch.scale)
                      + _sq(self._defect(ctx.terms1), batch.scale))


def CrankNicolsonResidual() -> SchemeResidual:
    """The seed paper's trajectory loss: the Crank–Nicolson residual of each pair."""
    return SchemeResidual(CrankNicolson())


def MidpointResidual() -> SchemeResidual:
    """The implicit-midpoint residual of each pair."""
    return SchemeResidual(ImplicitMidpoint())


def DiscreteGradientResidual() -> SchemeResidual:
    """The discrete-gradient GENERIC residual of each pair: train with the scheme that conserves
    the learned energy exactly and never decreases the learned entropy in rollouts."""
    return SchemeResidual(DiscreteGradient())


class PoissonDegeneracy(_AbstractDegeneracy):
    r""":math:`|L\nabla S|^2` at both states of each pair (the seed paper's weight :math:`w_S`).

    ``at_midpoints=True`` evaluates it once per pair at :math:`\bar x = (x_0 + x_1)/2`
    instead, where the discrete-gradient and midpoint schemes evaluate the structure: with the
    discrete-gradient residual the whole loss then needs the full structure only at the
    midpoints (energies and entropies at the states), about half the cost of the step
    (``docs/performance.md``).
    """

    name: ClassVar[str] = "degeneracy_L"

    @staticmethod
    def _defect(t):
        return jnp.einsum("bij,bj->bi", t.poisson, t.grad_entropy)


class FrictionDegeneracy(_AbstractDegeneracy):
    r""":math:`|M\nabla E|^2` at both states of each pair (the seed paper's weight :math:`w_E`),
    or, with ``at_midpoints=True``, at their midpoints (see :class:`PoissonDegeneracy`)."""

    name: ClassVar[str] = "degeneracy_M"

    @staticmethod
    def _defect(t):
        return jnp.einsum("bij,bj->bi", t.friction, t.grad_energy)


def DegeneracyPenalty(at_midpoints: bool = False) -> Loss:
    r"""Both degeneracy penalties, :math:`|L\nabla S|^2 + |M\nabla E|^2`, at both states of
    each pair or, with ``at_midpoints=True``, at their midpoints."""
    return (PoissonDegeneracy(at_midpoints=at_midpoints)
            + FrictionDegeneracy(at_midpoints=at_midpoints))


class NegativeTemperature(AbstractLossTerm):
    r"""A hinge on negative temperatures where :math:`S = \sum_{i\in I} x_i` (the :math:`x_i`
    entropies): :math:`\sum_{i\in I}\operatorname{relu}(-d_iT_i)^2 / |D\nabla E|^2`, batch
    means, :math:`T_i = \partial E/\partial x_i`, at both states of each pair.

    A physical energy rises with every entropy; where a learned one falls, entropy production
    feeds the motion. The term is a ratio of the energy's own gradients in standardised
    coordinates, so it depends on no unit and the scale of E cannot lower it.
    """

    indices: tuple[int, ...] = eqx.field(static=True)
    name: ClassVar[str] = "temperature"

    @property
    def reads_runs(self) -> bool:
        return True  # reads the states only

    def __check_init__(self):
        if not self.indices or not all(isinstance(i, int) and i >= 0 for i in self.indices):
            raise MetriplexError(
                f"NegativeTemperature needs the indices of the entropy variables (non-negative "
                f"integers, e.g. (8, 9)); got {self.indices!r}.")

    def __call__(self, model: GenericModel, batch: Batch, ctx: Context,
                 key: jax.Array) -> jax.Array:
        idx = jnp.asarray(self.indices)

        def one(t: Terms) -> jax.Array:
            g = t.grad_energy * batch.scale[None, :]
            # The ratio is the same for g times any constant: taken at g's own size, its square
            # and that square's square in the derivative neither under- nor overflow (float32,
            # an energy of 5e-8 in the data's units: a new-user check in ms and 1e-3 m).
            g = g / jax.lax.stop_gradient(jnp.sqrt(jnp.mean(g**2)) + jnp.finfo(g.dtype).tiny)
            cold = jnp.mean(jnp.sum(jax.nn.relu(-g[:, idx]) ** 2, axis=-1))
            size = jnp.mean(jnp.sum(g**2, axis=-1))
            return cold / (size + jnp.finfo(size.dtype).tiny)

        return 0.5 * (one(ctx.terms0) + one(ctx.terms1))


def stochastic_jacobi(model: GenericModel, x: State, u: State, v: State, w: State) -> Scalar:
    r"""The Jacobi trilinear form :math:`J(u, v, w) = \sum J^{ijl}u_iv_jw_l` from three
    directional derivatives of :math:`L`:

    .. math:: J(u,v,w) = u^\top (D_{Lw}L)\,v + w^\top (D_{Lv}L)\,u + v^\top (D_{Lu}L)\,w.

    Cost: three forward-mode products, :math:`O(n^2)` per probe instead of the full
    :math:`n^3` tensor.
    """
    L = model.poisson_matrix(x)
    dirs = jnp.stack([L @ w, L @ v, L @ u])
    dL = jax.vmap(lambda a: jax.jvp(model.poisson_matrix, (x,), (a,))[1])(dirs)
    return u @ dL[0] @ v + w @ dL[1] @ u + v @ dL[2] @ w


class AbstractJacobiEstimator(eqx.Module):
    r"""How :class:`JacobiPenalty` estimates :math:`\sum_{ijl}(J^{ijl})^2`: :class:`ExactJacobi`
    or :class:`StochasticJacobi`. Concrete estimators are final."""

    @abc.abstractmethod
    def mean_squared_residual(self, model: GenericModel, x: jax.Array, inv_scale: jax.Array,
                              key: jax.Array) -> jax.Array:
        r"""The batch mean of :math:`\sum_{ijl}(J^{ijl})^2` at the states ``x`` ``(B, n)``, in
        standardised units: :math:`J^{ijl}` times ``inv_scale`` ``(n,)`` in each of its three
        indices. ``key`` draws any random probes."""


class ExactJacobi(AbstractJacobiEstimator):
    r"""The full tensor :math:`J^{ijl}`, from the forward-mode Jacobian of :math:`L` (cost
    :math:`\propto n^3` per sample plus ``n`` tangents of the network). ``--jacobi exact``."""

    def mean_squared_residual(self, model: GenericModel, x: jax.Array, inv_scale: jax.Array,
                              key: jax.Array) -> jax.Array:
        J = jax.vmap(model.jacobi_tensor)(x)
        inv = inv_scale
        w3 = inv[:, None, None] * inv[None, :, None] * inv[None, None, :]
        J = J * w3[None]
        return jnp.mean(jnp.sum(J**2, axis=(1, 2, 3)))


class StochasticJacobi(AbstractJacobiEstimator):
    r"""Hutchinson-style: :math:`J(u,v,w)^2` with independent standard normal probes, averaged
    over ``probes`` draws per sample (:func:`stochastic_jacobi`). Since
    :math:`E[u_iu_{i'}] = \delta_{ii'}` for each probe, :math:`E[J(u,v,w)^2] = \sum (J^{ijl})^2`:
    an **unbiased** estimate of the exact penalty whose cost grows like :math:`n^2`.
    ``--jacobi stochastic --jacobi-probes K``.
    """

    probes: int = eqx.field(static=True, default=1, converter=count_of(
        "StochasticJacobi's probes (random probe triples per sample)", least=1))

    def mean_squared_residual(self, model: GenericModel, x: jax.Array, inv_scale: jax.Array,
                              key: jax.Array) -> jax.Array:
        B, n = x.shape
        probes = jr.normal(key, (3, B, self.probes, n), x.dtype) * inv_scale[None, None, None, :]
        vals = jax.vmap(
            jax.vmap(lambda xi, u, v, w: stochastic_jacobi(model, xi, u, v, w),
                     in_axes=(None, 0, 0, 0)),
        )(x, probes[0], probes[1], probes[2])
        return jnp.mean(vals**2)


class JacobiPenalty(AbstractLossTerm):
    r"""The Jacobi-identity penalty :math:`\sum_{ijl}(J^{ijl})^2` at the first state of each pair.

    ``estimator``: an :class:`AbstractJacobiEstimator`, :class:`ExactJacobi` (default; the full
    tensor, cost :math:`\propto n^3`) or :class:`StochasticJacobi` (``probes`` random triples
    per sample, unbiased, cost :math:`\propto n^2`):

    ```python
    JacobiPenalty(StochasticJacobi(probes=2), samples=256)
    ```

    ``samples``: evaluate the penalty on only ``samples`` pairs of each batch, every k-th one
    (``None``: all). Training batches are uniform random draws, so these are a random subset
    and the term stays an unbiased estimate of the same mean, with more variance, at
    ``samples / batch`` of the cost. The Jacobi term is a regulariser on the structure, not
    the data fit, so it can do with fewer samples than the residual.
    """

    estimator: AbstractJacobiEstimator = ExactJacobi()
    samples: int | None = eqx.field(static=True, default=None)
    name: ClassVar[str] = "jacobi"

    @property
    def reads_runs(self) -> bool:
        return True  # reads the first states only

    def __check_init__(self):
        expect_instance(
            self.estimator, AbstractJacobiEstimator, what="JacobiPenalty's estimator",
            expected="a Jacobi estimator object, ExactJacobi() (the default) or "
            "StochasticJacobi(probes=K) (in metriplex)",
            fix="Write JacobiPenalty(ExactJacobi()) for the former 'exact' and "
            "JacobiPenalty(StochasticJacobi(probes=K)) for 'stochastic' with probes=K.",
        )
        if self.samples is not None and self.samples < 1:
            raise MetriplexError(
                f"JacobiPenalty samples must be >= 1 (or None for the whole batch); got "
                f"{self.samples}."
            )

    def __call__(self, model: GenericModel, batch: Batch, ctx: Context,
                 key: jax.Array) -> jax.Array:
        x = batch.x0
        if self.samples is not None and self.samples < x.shape[0]:
            # Every k-th pair: a random subset of a random training batch, and still spread
            # over all trajectories in the evenly spaced validation batch.
            x = x[:: x.shape[0] // self.samples][: self.samples]
        return self.estimator.mean_squared_residual(model, x, 1.0 / batch.scale, key)
