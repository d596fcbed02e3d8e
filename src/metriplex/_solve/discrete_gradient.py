"""The discrete-gradient step: the learned energy conserved and the entropy non-decreasing
at every step, for any model."""

from __future__ import annotations

from typing import ClassVar

import jax
import jax.numpy as jnp
import numpy as np

from .._model import GenericModel, Terms
from .._types import Scalar, State
from ._implicit import AbstractImplicitScheme


def _sum(a):
    return jnp.sum(a, axis=-1)


def discrete_gradient(grad_mid: State, value0: Scalar, value1: Scalar, x0: State,
                      x1: State) -> State:
    r"""Gonzalez's midpoint discrete gradient of a scalar :math:`F` between ``x0`` and ``x1``.

    .. math::
        \bar\nabla F = \nabla F(\bar x)
        + \frac{F(x_1) - F(x_0) - \nabla F(\bar x)\cdot\Delta}{|\Delta|^2 + \delta^2}\,\Delta,
        \qquad \Delta = x_1 - x_0,\ \bar x = \tfrac12(x_0 + x_1),

    with ``grad_mid`` :math:`=\nabla F(\bar x)`. With :math:`\delta = 0` this is exactly
    Gonzalez's (1996) discrete gradient, :math:`\bar\nabla F\cdot\Delta = F(x_1) - F(x_0)`.

    **The limit** :math:`\Delta\to0`. The numerator is :math:`O(|\Delta|^3)` in exact arithmetic
    but carries the rounding error of :math:`F(x_1) - F(x_0)`, about
    :math:`\varepsilon|F|`; divided by :math:`|\Delta|^2` alone it would blow up (0/0 at
    :math:`\Delta = 0`, noise :math:`\varepsilon|F|/|\Delta|` for tiny steps). The smooth,
    never-zero denominator uses :math:`\delta^2 = \varepsilon\,\tfrac12(|x_0|^2+|x_1|^2) +
    \sqrt{\text{tiny}}` (machine epsilon and smallest normal number of the dtype):

    - it is smooth in :math:`(x_0, x_1)` (Newton and training see an honest Jacobian) and
      equals :math:`\nabla F(x_0)` at :math:`\Delta = 0`, with no ``NaN`` in value or
      derivatives (:math:`\delta^4` never underflows);
    - rounding noise enters with a Lipschitz constant of at most about
      :math:`|F|/|x|^2`, the size of a genuine Hessian, so a near-stationary state is not
      kicked by noise;
    - the identity :math:`\bar\nabla F\cdot\Delta = F(x_1)-F(x_0)` is violated by
      :math:`\frac{\delta^2}{|\Delta|^2+\delta^2}\cdot\text{numerator} \le
      \tfrac1{24}|D^3F|\,|\Delta|\,\delta^2`, i.e. :math:`\varepsilon\,|\Delta|/|x|` relative to
      the third-order scale of :math:`F`: below the rounding error of :math:`F` itself.
    """
    d = x1 - x0
    eps = jnp.finfo(d.dtype).eps
    floor = np.sqrt(np.finfo(jnp.dtype(d.dtype)).tiny)
    delta2 = eps * 0.5 * (_sum(x0 * x0) + _sum(x1 * x1)) + floor
    defect = (value1 - value0) - _sum(grad_mid * d)
    return grad_mid + (defect / (_sum(d * d) + delta2)) * d


def project_out(g: State, v: State) -> State:
    r""":math:`v - g\,\frac{g\cdot v}{|g|^2 + \tau}`: ``v`` with its component along ``g``
    removed (the projector :math:`I - gg^\top/|g|^2`, symmetric and idempotent).

    :math:`\tau = \sqrt{\text{tiny}}` only guards :math:`g = 0`, where the projector becomes the
    identity instead of ``NaN``; for any :math:`|g|^2 \gg \tau` (about 1e-154 in float64,
    1e-19 in float32) it is the exact projector to rounding.
    """
    tau = np.sqrt(np.finfo(jnp.dtype(v.dtype)).tiny)
    return v - g * (_sum(g * v) / (_sum(g * g) + tau))


def discrete_generic_field(model: GenericModel, x0: State, x1: State, energy0: Scalar,
                           energy1: Scalar, entropy0: Scalar, entropy1: Scalar,
                           mid: Terms | None = None) -> State:
    r"""The discrete-gradient GENERIC average :math:`\bar L\bar\nabla E + \bar M\bar\nabla S`.

    With :math:`\bar\nabla E,\ \bar\nabla S` the discrete gradients of
    :func:`discrete_gradient` and :math:`P = I - \hat s\hat s^\top`, :math:`Q = I - \hat e\hat
    e^\top` the projectors orthogonal to them (:func:`project_out`),

    .. math:: \bar L = P\,L(\bar x)\,P, \qquad \bar M = Q\,M(\bar x)\,Q .

    :math:`\bar L` is antisymmetric with :math:`\bar L\bar\nabla S = 0`; :math:`\bar M` is
    symmetric positive semi-definite (when :math:`M` is) with :math:`\bar M\bar\nabla E = 0`:
    the GENERIC degeneracy holds discretely, whatever the model. The blocks are called as
    ``poisson(x̄, ∇̄S)`` and ``friction(x̄, ∇̄E)``, so exactly degenerate parametrisations see
    the discrete gradients.

    ``mid``: the model's :class:`~metriplex.Terms` at the midpoint, if already computed (the
    training loss shares them); their gradients are used, and their ``L`` and ``M`` for blocks
    that do not depend on the gradient argument (``uses_gradient``).
    """
    xm = 0.5 * (x0 + x1)
    gE_mid = jax.grad(model.energy)(xm) if mid is None else mid.grad_energy
    gS_mid = jax.grad(model.entropy)(xm) if mid is None else mid.grad_entropy
    gE = discrete_gradient(gE_mid, energy0, energy1, x0, x1)
    gS = discrete_gradient(gS_mid, entropy0, entropy1, x0, x1)
    reuse = mid is not None
    L = mid.poisson if reuse and not model.poisson.uses_gradient else model.poisson(xm, gS)
    M = mid.friction if reuse and not model.friction.uses_gradient else model.friction(xm, gE)
    reversible = project_out(gS, L @ project_out(gS, gE))
    irreversible = project_out(gE, M @ project_out(gE, gS))
    return reversible + irreversible


class DiscreteGradient(AbstractImplicitScheme):
    r"""Structure-preserving discrete-gradient GENERIC step (Gonzalez 1996; Öttinger 2018;
    Romero 2009):

    .. math:: \frac{x_1 - x_0}{\Delta t} = \bar L\,\bar\nabla E + \bar M\,\bar\nabla S

    (see :func:`discrete_generic_field`). Because :math:`\bar\nabla E\cdot\Delta = E(x_1) -
    E(x_0)`, antisymmetry of :math:`\bar L` and :math:`\bar M\bar\nabla E = 0` give
    :math:`E(x_1) = E(x_0)` to solver tolerance, and :math:`S(x_1) - S(x_0) = \Delta t\,
    \bar\nabla S^\top\bar M\,\bar\nabla S \ge 0`, at every step, for **any** model — a
    learned one included — and any energy, not only quadratic ones. Second order.

    ```python
    xs = mx.simulate(model, x0, ts, scheme=mx.DiscreteGradient())
    loss = mx.SchemeResidual(mx.DiscreteGradient())  # train for this rollout
    ```
    """

    name: ClassVar[str] = "discrete-gradient"
    summary: ClassVar[str] = "keeps any learned E exactly and dS >= 0"

    def start(self, model: GenericModel, x0: State) -> tuple[Scalar, Scalar]:
        """What the step needs of its first state: :math:`E(x_0)` and :math:`S(x_0)`, computed once
        per step."""
        return model.energy(x0), model.entropy(x0)

    def average(self, model: GenericModel, x0: State, x1: State,
                start: tuple[Scalar, Scalar], dt: Scalar | float) -> State:
        """The discrete GENERIC field between ``x0`` and ``x1`` (:func:`discrete_generic_field`),
        with ``start`` the energy and entropy at ``x0``."""
        energy0, entropy0 = start
        return discrete_generic_field(
            model, x0, x1, energy0, model.energy(x1), entropy0, model.entropy(x1)
        )

    def residual(self, model: GenericModel, x0: State, x1: State, dt: Scalar, terms0: Terms,
                 terms1: Terms, mid: Terms | None = None) -> State:
        r"""The defect of the data pair ``x0 -> x1`` over a step ``dt`` under this scheme,
        :math:`(x_1 - x_0)/\Delta t` minus the scheme's field, shape ``(n,)``; ``terms0`` and
        ``terms1`` are :class:`~metriplex.Terms` at the two states, shared by every loss term (zero
        on data that the scheme made). ``mid``: the terms at the midpoint, where a loss has them
        already."""
        field = discrete_generic_field(
            model, x0, x1, terms0.energy, terms1.energy, terms0.entropy, terms1.entropy, mid
        )
        return (x1 - x0) / dt - field
