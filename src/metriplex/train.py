r"""Training: ``fit(model, data, ...) -> (model, history)``.

An Optax loop over random minibatches of data pairs, with validation on held-out
**trajectories** (never pairs of a training trajectory), early stopping that keeps the best
validation model, and a history of every loss term. Many optimiser steps run inside one
compiled loop between validations, so Python overhead stays off the hot path.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Sequence

import equinox as eqx
import jax.numpy as jnp
import jax.random as jr
import numpy as np
import optax

from ._precision import in_full_precision
from ._errors import MetriplexError
from ._fit_loop import INTERRUPTED, Evaluation, FitLoop, ending
from ._fit_options import Checkpoint, LBFGSFinish
from ._model import AbstractModel, float_dtype, with_dtype
from ._optimizers import (
    adjustable_optimizer,
    cosine_schedule,
    default_optimizer,
    is_adjustable,
)
from ._train import (
    History,
    TrainState,
    default_scale,
    make_chunk,
    batch_sharding,
    check_arguments,
    split_validation,
    training_dtype,
    spread,
)
from ._pairs import PairRows, PairStore
from ._validate import Average, Plateau, RolloutCheck, scheme_of
from .data import Pairs, Trajectories, state_scale
from .integrate import model_size
from .losses import CrankNicolsonResidual, Loss

if TYPE_CHECKING:
    import jax
    from jax.typing import DTypeLike
    from numpy.typing import ArrayLike

__all__ = ["Average", "Checkpoint", "History", "LBFGSFinish", "Plateau", "RolloutCheck",
           "adjustable_optimizer", "default_optimizer", "fit"]


@in_full_precision
def fit(
    model: AbstractModel,
    data: Trajectories | Pairs | tuple[ArrayLike, ArrayLike, ArrayLike],
    *,
    loss: Loss | None = None,
    optimizer: optax.GradientTransformation | None = None,
    learning_rate: float = 1e-2,
    weight_decay: float = 0.0,
    steps: int = 100_000,
    batch_size: int = 256,
    validation: float | Trajectories | None = 0.2,
    eval_every: int = 100,
    stopping: Plateau | None = Plateau(),
    rollout_check: RolloutCheck | None = RolloutCheck(),
    average: Average | None = Average(),
    patience: int | None = None,
    max_seconds: float | None = None,
    scale: ArrayLike | None = None,
    dtype: DTypeLike | None = None,
    progress: bool = True,
    seed_split: int = 0,
    checkpoint: Checkpoint | None = None,
    data_parallel: bool = False,
    finish: LBFGSFinish | None = None,
    input_noise: float | Sequence[float] = 0.0,
    consecutive: int = 1,
    key: jax.Array,
) -> tuple[AbstractModel, History]:
    r"""Learn ``model`` from trajectory data; return the best model and the training history.

    By default training runs until the validation score stops improving: Adam with a short
    warm-up; after ``stopping.patience`` evaluations without improvement the learning rate is
    cut (``stopping.factor``) and training resumes from the best model; after
    ``stopping.cuts`` plateaus it stops (``history.converged``). ``steps`` (and
    ``max_seconds``) cap the run; over the last fifth of ``steps`` the rate is annealed (cosine
    to 1%). The validation score is the error of short rollouts of the held-out trajectories
    (``rollout_check``): the model kept is the one that rolls out best.

    ``data``: :class:`~metriplex.Trajectories` (pairs of consecutive samples, each with its own
    dt), or ready :class:`~metriplex.data.Pairs`.

    ``loss``: a :class:`~metriplex.Loss` (default :func:`~metriplex.CrankNicolsonResidual`).

    ``learning_rate``: peak Adam learning rate (default 1e-2; every loss is measured in the
    data's own units, so one rate serves data of any scale).

    ``weight_decay``: decoupled weight decay (AdamW) of the default optimiser (default 0).

    ``steps``: the most optimiser steps (default 100 000; a cap: training usually stops
    earlier, when the plateau schedule has converged).

    ``validation``: fraction of trajectories held out (default 0.2; split **by trajectory**:
    ``data.split(validation, seed=seed_split)``), explicit validation ``Trajectories``, or
    ``None``/``0`` for none. The returned model is the one with the best validation score (or
    training loss without validation). A fraction applies to ``Trajectories`` only: ``Pairs``
    and ``(x0, x1, dt)`` have no trajectories to hold out, so every pair trains and the model
    is chosen by its training loss (pass validation ``Trajectories`` to judge it).

    ``stopping``: a :class:`Plateau` (default), or ``None`` for exactly ``steps`` steps of a
    cosine schedule (``default_optimizer``), optionally ended by ``patience``.

    ``rollout_check``: a :class:`RolloutCheck` (default) to score evaluations by held-out
    rollouts, or ``None`` to score them by the validation loss only.

    ``average``: an :class:`Average` (default: over about 500 steps) to judge every evaluation
    by a running average of the parameters and keep that average, or ``None`` to judge the
    optimiser's parameters themselves.

    ``patience``: evaluations without improvement before a plateau (overrides
    ``stopping.patience``); with ``stopping=None``, before training stops.

    ``max_seconds``: stop after this much training time (a budget, like ``steps``).

    ``scale``: per-component rate scale in which residuals are measured (default
    :math:`d_i/\tau`: the standard deviation of the training states, 1 for constant columns,
    over the data's time scale :func:`~metriplex.data.time_scale`; so the loss does not depend
    on the units of time or of the state).

    ``dtype``: ``jnp.float32`` or ``jnp.float64`` (needs ``jax_enable_x64``); default: the
    model's. Float32 states round a variable far from zero (one near 1e4 to 1e-3): where that
    is a fair share of its change over a step, the residual fits the rounding as noise on the
    rates, and float64 trains better (``metriplex train`` chooses float64 there by itself).

    ``checkpoint``: a :class:`Checkpoint` (path, how often, whether to resume from it): the
    file is written atomically every ``checkpoint.every`` evaluations, on Ctrl-C and at the
    end; with ``resume=True`` training continues from it and reaches the same result as an
    uninterrupted run with the same arguments. ``None`` (default): no checkpoint.

    ``data_parallel``: split every minibatch over all local devices (``jax.devices()``) with JAX
    sharding: parameters are replicated, the batch axis is sharded, and XLA inserts the gradient
    all-reduce. The result equals single-device training to rounding. ``batch_size`` must be a
    multiple of the device count. Across hosts, call ``jax.distributed.initialize()`` first (see
    docs/performance.md).

    ``finish``: an :class:`LBFGSFinish` (an L-BFGS stage after Adam, whose model is kept only
    where the validation score improves), or ``None`` (default) for none.

    ``input_noise``: standard deviation of Gaussian noise added to both states of every training
    pair, as a fraction of each variable's standard deviation: one for all variables, or one
    per variable (default 0: none).

    ``consecutive``: draw each batch as ``batch_size // consecutive`` runs of that many
    consecutive pairs, so each state is evaluated once (default 1: independent pairs). Applies
    to trajectory data where every loss term reads such batches
    (:attr:`~metriplex.losses.AbstractLossTerm.reads_runs`), without ``input_noise`` and
    ``data_parallel``; elsewhere the pairs stay independent. Each step is cheaper, but a batch
    holds fewer independent samples (docs/zoo.md).

    ```python
    model, history = fit(model, data, key=jr.key(0))
    ```
    """
    check_arguments(steps=steps, batch_size=batch_size, eval_every=eval_every,
                    learning_rate=learning_rate, patience=patience, input_noise=input_noise,
                    consecutive=consecutive,
                    checkpoint=checkpoint, finish=finish, average=average)
    if stopping is not None and patience is not None:
        stopping = dataclasses.replace(stopping, patience=patience)
    loss = CrankNicolsonResidual().as_loss() if loss is None else loss.as_loss()
    n = model_size(model)
    dtype = float_dtype(model, default=jnp.float32) if dtype is None else training_dtype(dtype)
    train_data, valid_data = split_validation(data, validation, seed_split)
    # The pairs are rows of the states (no copy of them), checked once.
    train_rows = PairRows.of(train_data, n, "training")
    valid_rows = None if valid_data is None else PairRows.of(valid_data, n, "validation")
    scale = np.asarray(default_scale(train_rows.x, train_data) if scale is None else scale,
                       dtype=np.float64)
    model = with_dtype(model, dtype)

    rate_at = None  # the rate as a function of the step, where a fixed schedule sets it
    if optimizer is None and stopping is None:
        optimizer = default_optimizer(learning_rate, steps)
        rate_at = cosine_schedule(learning_rate, steps)
    elif optimizer is None:
        optimizer = adjustable_optimizer(learning_rate, weight_decay=weight_decay)
    params, static = eqx.partition(model, eqx.is_inexact_array)
    opt_state = optimizer.init(params)
    adjustable = stopping is not None and is_adjustable(opt_state)
    n_train = train_rows.count
    bsz = min(batch_size, n_train)
    shard = batch_sharding(data_parallel, bsz)
    full_train = PairStore.of(train_rows, scale, dtype)
    noise = None
    if np.any(np.asarray(input_noise) > 0):
        noise = jnp.asarray(np.asarray(input_noise) * state_scale(train_rows.x), dtype)
    runs = (consecutive if consecutive > 1 and train_rows.in_runs and loss.reads_runs
            and noise is None and shard is None else 1)
    run_chunk = make_chunk(loss, optimizer, static, bsz, shard, noise, runs, jit=True)

    # Evaluations see fixed spread subsets of the pairs. The training subset carries windows
    # like the training batches (its figures are the first of the training history); the
    # validation subset judges the pair loss.
    key, eval_key = jr.split(key)
    evaluation = Evaluation(
        loss, static, key=eval_key,
        train_pairs=train_rows.batch(spread(n_train, 4096), scale, dtype, loss.window_shape),
        valid_pairs=None if valid_rows is None else valid_rows.batch(
            spread(valid_rows.count, 4096), scale, dtype))
    if rollout_check is not None and valid_data is not None:
        evaluation.windows = rollout_check.prepare(valid_data, dtype)
        evaluation.scheme = scheme_of(loss)
        evaluation.state_units = state_scale(train_rows.x, valid_data.x)
    del train_rows, valid_rows, train_data

    state = TrainState.start(params, opt_state, key, learning_rate)
    resume = checkpoint is not None and checkpoint.resume
    if resume:
        state = state.load(checkpoint.path)
        if ending(state.history.stopped) == INTERRUPTED:
            state.history.stopped = ""
        if state.done > steps:
            raise MetriplexError(
                f"the checkpoint is at step {state.done}, beyond the requested {steps} steps; "
                "ask for at least as many steps as the interrupted run."
            )
    loop = FitLoop(state, static, run_chunk, full_train, evaluation, steps=steps,
                   eval_every=eval_every, stopping=stopping, adjustable=adjustable,
                   rate_at=rate_at, patience=patience, max_seconds=max_seconds,
                   average=average, checkpoint=checkpoint, finish=finish, progress=progress)
    return loop.run(resume=resume)
