r"""A loss term on short rollouts: :class:`RolloutWindow`.

The pair residual asks the learned field to explain each step of the data on its own; a model
can do that well and still drift off the data over a few hundred steps, where its own errors
compound. :class:`RolloutWindow` rolls the model out for ``steps`` steps of the training
scheme from data states and compares the whole stretch with the data, so the errors that
compound are the ones trained away.
"""

from __future__ import annotations

from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp

from ._errors import count_of, expect_instance
from ._model import GenericModel
from .integrate import AbstractScheme, CrankNicolson
from ._loss_base import AbstractLossTerm, Batch, Context


def _frozen(model: GenericModel) -> GenericModel:
    return jax.tree_util.tree_map(
        lambda a: jax.lax.stop_gradient(a) if eqx.is_array(a) else a, model)


class RolloutWindow(AbstractLossTerm):
    r"""The error of ``steps``-step rollouts of the model from data states, against the data.

    From the first state of ``windows`` training pairs of each batch, the model is rolled out
    by ``scheme`` over the next ``steps`` steps of the same trajectory (fewer where the
    trajectory ends). The error after ``k`` steps is divided by :math:`k\,\Delta t`, so that it
    is measured like the pair residual (a model whose every step has residual :math:`r` scores
    about :math:`|r|^2`), in standardised state units, and averaged over all steps rolled.

    Each implicit step is solved without gradients and then differentiated as one update
    :math:`x + \Delta t\,\bar f(x, x_1)` at the solved :math:`x_1`
    (:meth:`~metriplex.integrate.AbstractScheme.differentiable_step`): the gradient of the
    step to first order in :math:`\Delta t`, at the cost of one more evaluation of the field.
    A rollout stops contributing where a step fails to converge or leaves the finite numbers.

    Training batches carry the windows; evaluation subsets of pairs do not, so the validation
    loss (which times the learning-rate schedule) is the pair loss, and the held-out rollouts
    judge the model kept.

    ```python
    loss = mx.CrankNicolsonResidual() + mx.RolloutWindow(mx.CrankNicolson(), steps=16)
    ```
    """

    scheme: AbstractScheme = CrankNicolson()
    steps: int = eqx.field(static=True, default=16,
                           converter=count_of("RolloutWindow's steps", least=1))
    windows: int = eqx.field(static=True, default=32,
                             converter=count_of("RolloutWindow's windows", least=1))
    name: ClassVar[str] = "window"

    def __check_init__(self):
        expect_instance(self.scheme, AbstractScheme, what="RolloutWindow's scheme",
                        expected="a scheme such as CrankNicolson() (metriplex.integrate)")

    @property
    def window_shape(self) -> tuple[int, int]:
        return self.windows, self.steps

    def __call__(self, model: GenericModel, batch: Batch, ctx: Context,
                 key: jax.Array) -> jax.Array:
        r"""The mean over the rolled steps of the squared, standardised rollout error, each
        divided by :math:`(k\,\Delta t)^2` after ``k`` steps; ``batch.window`` holds the
        windows (``ctx`` and ``key`` are not used)."""
        x0, targets, dts, mask = batch.window
        frozen = _frozen(model)
        scheme = self.scheme
        advance = jax.vmap(lambda x, dt, y: scheme.differentiable_step(model, x, dt, y))
        inv = 1.0 / batch.scale[None, :]

        def body(carry, inputs):
            x, alive, k = carry
            target, dt, m = inputs
            fixed = jax.lax.stop_gradient(x)
            solved, ok, _ = scheme.step_batch(frozen, fixed, dt, fixed)
            solved = jax.lax.stop_gradient(solved)
            ok = ok & jnp.all(jnp.isfinite(solved), axis=-1)
            # Failed rows continue from a finite state and are masked: no NaN reaches the
            # gradient through the unselected branch.
            solved = jnp.where(ok[:, None], solved, fixed)
            nxt = advance(x, dt, solved)
            alive = alive & ok & m & jnp.all(jnp.isfinite(nxt), axis=-1)
            nxt = jnp.where(alive[:, None], nxt, fixed)
            err = jnp.sum(((nxt - target) * inv) ** 2, axis=-1) / (k * dt) ** 2
            return (nxt, alive, k + 1), jnp.where(alive, err, 0.0)

        start = (x0, jnp.ones(x0.shape[:1], bool), jnp.ones((), x0.dtype))
        _, errors = jax.lax.scan(body, start, (jnp.swapaxes(targets, 0, 1), dts.T, mask.T))
        return jnp.sum(errors) / jnp.maximum(jnp.sum(mask), 1).astype(x0.dtype)
