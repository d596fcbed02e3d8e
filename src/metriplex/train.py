r"""Training: ``fit(model, data, ...) -> (model, history)``.

An Optax loop over random minibatches of data pairs, with validation on held-out
**trajectories** (never pairs of a training trajectory), early stopping that keeps the best
validation model, and a history of every loss term. Many optimiser steps run inside one
compiled ``lax.scan`` between validations, so Python overhead stays off the hot path.
"""

from __future__ import annotations

import dataclasses
import math
import time
from typing import TYPE_CHECKING

import equinox as eqx
import jax.numpy as jnp
import jax.random as jr
import numpy as np
import optax
from tqdm.auto import tqdm

from ._errors import MetriplexError, TrainingDiverged
from ._fit_options import Checkpoint, LBFGSFinish
from ._interrupt import CtrlC
from ._model import GenericModel, float_dtype, with_dtype
from ._train import (
    History,
    TrainState,
    adjustable_optimizer,
    annealing,
    cosine_schedule,
    default_optimizer,
    default_scale,
    is_adjustable,
    learning_rate_of,
    make_chunk,
    batch_sharding,
    check_arguments,
    make_lbfgs_chunk,
    split_validation,
    spread,
    with_learning_rate,
)
from ._pairs import PairRows, PairStore
from ._validate import Plateau, RolloutCheck, rollout_score, scheme_of
from .data import Pairs, Trajectories, state_scale
from .integrate import model_size
from .losses import CrankNicolsonResidual, Loss

if TYPE_CHECKING:
    import jax
    from jax.typing import DTypeLike
    from numpy.typing import ArrayLike

__all__ = ["Checkpoint", "History", "LBFGSFinish", "Plateau", "RolloutCheck",
           "adjustable_optimizer", "default_optimizer", "fit"]


def fit(
    model: GenericModel,
    data: Trajectories | Pairs | tuple[ArrayLike, ArrayLike, ArrayLike],
    *,
    loss: Loss | None = None,
    optimizer: optax.GradientTransformation | None = None,
    learning_rate: float = 1e-2,
    weight_decay: float = 0.0,
    steps: int = 30_000,
    batch_size: int = 256,
    validation: float | Trajectories | None = 0.2,
    eval_every: int = 100,
    stopping: Plateau | None = Plateau(),
    rollout_check: RolloutCheck | None = RolloutCheck(),
    patience: int | None = None,
    max_seconds: float | None = None,
    scale: ArrayLike | None = None,
    dtype: DTypeLike | None = None,
    progress: bool = True,
    seed_split: int = 0,
    checkpoint: Checkpoint | None = None,
    data_parallel: bool = False,
    finish: LBFGSFinish | None = None,
    input_noise: float = 0.0,
    key: jax.Array,
) -> tuple[GenericModel, History]:
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

    ``steps``: the most optimiser steps (default 30 000).

    ``validation``: fraction of trajectories held out (default 0.2; split **by trajectory**),
    explicit validation ``Trajectories``, or ``None``/``0`` for none. The returned model is the
    one with the best validation score (or training loss without validation).

    ``stopping``: a :class:`Plateau` (default), or ``None`` for exactly ``steps`` steps of a
    cosine schedule (``default_optimizer``), optionally ended by ``patience``.

    ``rollout_check``: a :class:`RolloutCheck` (default) to score evaluations by held-out
    rollouts, or ``None`` to score them by the validation loss only.

    ``patience``: evaluations without improvement before a plateau (overrides
    ``stopping.patience``); with ``stopping=None``, before training stops.

    ``max_seconds``: stop after this much training time (a budget, like ``steps``).

    ``scale``: per-component rate scale in which residuals are measured (default
    :math:`d_i/\tau`: the standard deviation of the training states, 1 for constant columns,
    over the data's time scale :func:`~metriplex.data.time_scale`; so the loss does not depend
    on the units of time or of the state).

    ``dtype``: ``jnp.float32`` or ``jnp.float64`` (needs ``jax_enable_x64``); default: the
    model's.

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
    pair, as a fraction of each variable's standard deviation (default 0: none).

    ```python
    model, history = fit(model, data, key=jr.key(0))
    ```
    """
    check_arguments(steps=steps, batch_size=batch_size, eval_every=eval_every,
                    learning_rate=learning_rate, patience=patience, input_noise=input_noise,
                    checkpoint=checkpoint, finish=finish)
    lbfgs_steps = 0 if finish is None else finish.steps
    if stopping is not None and patience is not None:
        stopping = dataclasses.replace(stopping, patience=patience)
    loss = CrankNicolsonResidual().as_loss() if loss is None else loss.as_loss()
    n = getattr(model, "n", None) or model_size(model)
    dtype = float_dtype(model, default=jnp.float32) if dtype is None else dtype
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
    if input_noise > 0:
        noise = jnp.asarray(input_noise * state_scale(train_rows.x), dtype)
    run_chunk = eqx.filter_jit(make_chunk(loss, optimizer, static, bsz, shard, noise))

    @eqx.filter_jit
    def evaluate(params, batch, key):
        return loss(eqx.combine(params, static), batch, key=key)

    # Evaluations see fixed spread subsets of the pairs.
    # The training subset carries windows like the training batches (its figures are the
    # first of the training history); the validation subset judges the pair loss.
    train_eval = train_rows.batch(spread(n_train, 4096), scale, dtype, loss.window_shape)
    valid_eval = None if valid_rows is None else valid_rows.batch(
        spread(valid_rows.count, 4096), scale, dtype)

    def eval_pairs(params, batch, key) -> tuple[float, dict[str, float]]:
        total, parts = evaluate(params, batch, key)
        return float(total), {k: float(v) for k, v in parts.items()}

    windows = None
    if rollout_check is not None and valid_data is not None:
        windows = rollout_check.prepare(valid_data, dtype)
        scheme = scheme_of(loss)
        state_units = state_scale(train_rows.x, valid_data.x)
    del train_rows, valid_rows, train_data

    key, eval_key = jr.split(key)
    state = TrainState.start(params, opt_state, key, learning_rate)
    resume = checkpoint is not None and checkpoint.resume
    if resume:
        state = state.load(checkpoint.path)
        if state.history.stopped.startswith("interrupted"):
            state.history.stopped = ""
        if state.done > steps:
            raise MetriplexError(
                f"the checkpoint is at step {state.done}, beyond the requested {steps} steps; "
                "ask for at least as many steps as the interrupted run."
            )
    history = state.history

    def save_checkpoint():
        if checkpoint is not None:
            state.save(checkpoint.path)

    # The last fifth of the step budget anneals the rate (cosine to 1%), so a run that the
    # budget ends before it converges still finishes on a small learning rate.
    anneal_from = int(0.8 * steps)

    def run_next_chunk():
        length = min(eval_every, steps - state.done)
        if adjustable and state.done >= anneal_from:
            state.opt_state = with_learning_rate(
                state.opt_state, state.lr * annealing(state.done, anneal_from, steps))
        state.key, sub = jr.split(state.key)
        state.params, state.opt_state, value, parts = run_chunk(
            state.params, state.opt_state, sub, length, full_train)
        state.train_value = float(value)
        state.train_parts = {k: float(v) for k, v in parts.items()}
        state.done += length
        bar.update(length)

    def record_evaluation() -> tuple[float, int]:
        """Evaluate the current parameters, append to the history, keep the best model;
        return the score and the rollout failures (-1 without rollouts)."""
        if state.done > 0:
            tr_total, tr_parts = state.train_value, state.train_parts
        else:
            tr_total, tr_parts = eval_pairs(state.params, train_eval, eval_key)
        if valid_eval is not None:
            va_total, va_parts = eval_pairs(state.params, valid_eval, eval_key)
        else:
            va_total, va_parts = tr_total, {}
        history.step.append(state.done)
        history.time.append(time.perf_counter() - start)
        history.learning_rate.append(learning_rate_of(state.opt_state, state.lr)
                                     if rate_at is None else float(rate_at(state.done)))
        for name, v in tr_parts.items():
            history.train.setdefault(name, []).append(v)
        history.train.setdefault("total", []).append(tr_total)
        for name, v in va_parts.items():
            history.valid.setdefault(name, []).append(v)
        if va_parts:
            history.valid.setdefault("total", []).append(va_total)
        if not math.isfinite(tr_total) or not math.isfinite(va_total):
            bad = [k for k, v in {**tr_parts, **va_parts}.items() if not math.isfinite(v)]
            history.stopped = f"diverged at step {state.done} (non-finite: {', '.join(bad)})"
            raise TrainingDiverged(
                f"training diverged at step {state.done}: the loss term(s) {bad or ['total']} "
                f"became non-finite. The best model so far (step {history.best_step}) is "
                "kept; lower the learning rate or the loss weights.",
                model=eqx.combine(state.best_params, static),
                history=history,
            )
        # The plateau schedule follows the (smooth) validation loss; the model kept is the one
        # with the best score: held-out rollouts when checked, else that loss.
        if va_total < state.plateau_best * (1.0 - (stopping.min_delta if stopping else 0.0)):
            state.since_best = 0
        else:
            state.since_best += 1
        if va_total < state.plateau_best:
            state.plateau_best, state.restart_params = va_total, state.params
        score, failures = va_total, -1
        if windows is not None:
            score, failures = rollout_score(
                eqx.combine(state.params, static), scheme, windows, state_units)
            history.rollout.append(score)
            history.rollout_failures.append(failures)
        if score < state.best_value:
            state.best_value, state.best_params = score, state.params
            history.best_step, history.best_valid = state.done, va_total
            if windows is not None:
                history.best_rollout, history.best_rollout_failures = score, failures
        postfix = dict(loss=f"{tr_total:.3e}", valid=f"{va_total:.3e}")
        if windows is not None:
            postfix["rollout"] = f"{score:.3g}" + (f" ({failures} failed)" if failures else "")
        bar.set_postfix(**postfix)
        return score, failures

    def should_stop() -> bool:
        """Apply the budgets and the plateau schedule after an evaluation."""
        if state.done >= steps:
            history.stopped = history.stopped or f"step budget reached ({steps} steps)"
            return True
        if max_seconds is not None and history.time[-1] >= max_seconds:
            history.stopped = f"time budget reached ({max_seconds:g} s) at step {state.done}"
            return True
        if stopping is None:
            if patience is not None and state.since_best > patience:
                history.stopped = (f"early stop at step {state.done} (no improvement in "
                                   f"{patience} evaluations)")
                history.converged = True
                return True
        elif state.since_best >= stopping.patience:
            if state.cuts >= stopping.cuts or not adjustable:
                history.stopped = (f"converged at step {state.done} (no improvement in "
                                   f"{stopping.patience} evaluations after {state.cuts} "
                                   "learning-rate cuts)")
                history.converged = True
                return True
            state.cuts += 1
            state.lr *= stopping.factor
            state.params, state.since_best = state.restart_params, 0
            state.opt_state = with_learning_rate(state.opt_state, state.lr)
        return False

    def lbfgs_finish():
        """L-BFGS from the best model on a fixed batch; evaluations keep the best model."""
        nonlocal bar
        solver, chunk = make_lbfgs_chunk(loss, static)
        chunk = eqx.filter_jit(chunk)
        pairs = full_train.take(jnp.asarray(spread(n_train, finish.pairs)), loss.window_shape)
        state.params = state.best_params
        opt_state = solver.init(state.params)
        bar = tqdm(total=lbfgs_steps, disable=not progress, desc="L-BFGS", unit="it",
                   leave=False)
        done = 0
        try:
            while done < lbfgs_steps:
                length = min(eval_every, lbfgs_steps - done)
                params, opt_state, value = chunk(state.params, opt_state, length, pairs,
                                                 eval_key)
                if not math.isfinite(float(value)):
                    history.stopped += f"; L-BFGS stopped at iteration {done} (non-finite loss)"
                    break
                state.params = params
                done += length
                state.done += length
                bar.update(length)
                state.train_value, state.train_parts = eval_pairs(state.params, train_eval,
                                                                  eval_key)
                record_evaluation()
                ctrl_c.check()
                if max_seconds is not None and history.time[-1] >= max_seconds:
                    break
        except KeyboardInterrupt:
            history.stopped += f"; L-BFGS interrupted at iteration {done}"
        finally:
            bar.close()
            history.lbfgs_steps = done

    start = time.perf_counter() - (history.time[-1] if history.time else 0.0)
    evaluations = 0
    bar = tqdm(total=steps, initial=state.done, disable=not progress, desc="fit", unit="step",
               leave=False)
    with CtrlC() as ctrl_c:
        try:
            finished = resume and (
                state.done >= steps or history.stopped.startswith(("early stop", "converged")))
            if resume and not finished:
                run_next_chunk()  # the restored history already holds the evaluation at its step
            while not finished:
                ctrl_c.check()
                record_evaluation()
                evaluations += 1
                if checkpoint is not None and evaluations % checkpoint.every == 0:
                    save_checkpoint()
                ctrl_c.check()
                if should_stop():
                    break
                run_next_chunk()
        except KeyboardInterrupt:
            history.stopped = f"interrupted at step {state.done}"
        finally:
            bar.close()
        if (lbfgs_steps and not history.stopped.startswith("interrupted")
                and history.lbfgs_steps == 0):
            lbfgs_finish()
    save_checkpoint()
    return eqx.combine(state.best_params, static), history
