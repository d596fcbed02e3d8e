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
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np
import optax
from tqdm.auto import tqdm

from . import _checkpoint
from ._errors import MetriplexError, TrainingDiverged
from ._model import GenericModel, float_dtype, with_dtype
from .data import Pairs, Trajectories, state_scale
from .integrate import model_size
from .losses import Batch, CrankNicolsonResidual, Loss


@dataclasses.dataclass
class History:
    """Loss terms per evaluation: ``step``, ``train[name]``, ``valid[name]``, wall ``time``."""

    step: list[int] = dataclasses.field(default_factory=list)
    train: dict[str, list[float]] = dataclasses.field(default_factory=dict)
    valid: dict[str, list[float]] = dataclasses.field(default_factory=dict)
    time: list[float] = dataclasses.field(default_factory=list)
    learning_rate: list[float] = dataclasses.field(default_factory=list)
    best_step: int = 0
    best_valid: float = math.inf
    stopped: str = ""

    def to_json(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_json(cls, obj: dict[str, Any]) -> "History":
        return cls(**obj)


def _as_pairs(data) -> tuple[Pairs, Trajectories | None]:
    if isinstance(data, Trajectories):
        return data.pairs(), data
    if isinstance(data, Pairs):
        return data, None
    if isinstance(data, tuple) and len(data) == 3:
        return Pairs(*(np.asarray(a) for a in data)), None
    raise MetriplexError(
        f"fit needs Trajectories, Pairs or a tuple (x0, x1, dt); got {type(data).__name__}."
    )


def _check_pairs(p: Pairs, n: int | None, what: str) -> None:
    if p.x0.ndim != 2 or p.x0.shape != p.x1.shape or p.dt.shape != p.x0.shape[:1]:
        raise MetriplexError(
            f"{what} pairs need x0, x1 of shape (N, n) and dt of shape (N,); got "
            f"{p.x0.shape}, {p.x1.shape}, {p.dt.shape}."
        )
    if len(p) == 0:
        raise MetriplexError(f"{what} data hold no pairs; each trajectory needs >= 2 samples.")
    if n is not None and p.x0.shape[1] != n:
        raise MetriplexError(
            f"the data have {p.x0.shape[1]} state variables but the model expects {n}; build the "
            f"model for {p.x0.shape[1]} variables or select matching columns."
        )
    if np.any(~np.isfinite(p.dt)) or np.any(p.dt <= 0):
        raise MetriplexError(
            f"every dt must be finite and > 0; {what} data have dt = "
            f"{p.dt[(~np.isfinite(p.dt)) | (p.dt <= 0)][:3]}. Sort samples by time and drop "
            "duplicates."
        )
    for a in (p.x0, p.x1):
        if not np.all(np.isfinite(a)):
            raise MetriplexError(f"{what} data contain NaN or inf; clean them before training.")


def _batch(pairs: Pairs, idx, scale, dtype) -> Batch:
    return Batch(
        jnp.asarray(pairs.x0[idx], dtype),
        jnp.asarray(pairs.x1[idx], dtype),
        jnp.asarray(pairs.dt[idx], dtype),
        jnp.asarray(scale, dtype),
    )


def _batch_sharding(enabled: bool, batch_size: int):
    """A function that shards a batch's sample axis over all local devices, or ``None``."""
    if not enabled:
        return None
    from jax.sharding import Mesh, NamedSharding, PartitionSpec as P

    devices = jax.devices()
    if batch_size % len(devices):
        raise MetriplexError(
            f"data-parallel training splits each batch over {len(devices)} devices, so the batch "
            f"size must be a multiple of {len(devices)}; got {batch_size}. Choose "
            f"--batch-size {batch_size - batch_size % len(devices) or len(devices)}."
        )
    mesh = Mesh(np.array(devices), ("data",))
    rows = NamedSharding(mesh, P("data"))
    whole = NamedSharding(mesh, P())

    def shard(batch: Batch) -> Batch:
        c = jax.lax.with_sharding_constraint
        return Batch(c(batch.x0, rows), c(batch.x1, rows), c(batch.dt, rows), c(batch.scale, whole))

    return shard


def default_optimizer(learning_rate: float, steps: int) -> optax.GradientTransformation:
    """Adam with a short linear warm-up and cosine decay to 1% of the peak rate."""
    schedule = optax.warmup_cosine_decay_schedule(
        init_value=learning_rate * 0.1,
        peak_value=learning_rate,
        warmup_steps=min(100, max(steps // 20, 1)),
        decay_steps=max(steps, 2),
        end_value=learning_rate * 1e-2,
    )
    return optax.chain(optax.clip_by_global_norm(10.0), optax.adam(schedule))


def train_chunk(loss: Loss, optimizer, static, batch_size: int, shard=None):
    """The compiled unit of :func:`fit`: ``chunk(params, opt_state, key, length, full_train)``
    runs ``length`` optimiser steps in one ``lax.scan``, each on ``batch_size`` random pairs of
    ``full_train`` (a :class:`Batch` of all training pairs), and returns ``(params, opt_state,
    mean loss, mean loss terms)``.

    The training pairs are an argument, not a closed-over constant, so the data set is not
    embedded in the compiled program and the chunk can be timed on its own
    (``benchmarks/run.py``).

    Exposed (privately) so that ``benchmarks/run.py`` times exactly the step that ``fit`` runs.
    """
    def loss_fn(p, batch, k):
        return loss(eqx.combine(p, static), batch, key=k)

    def chunk(params, opt_state, key, length, full_train):
        n_train = full_train.x0.shape[0]

        def one(carry, k):
            params, opt_state = carry
            kb, kl = jr.split(k)
            idx = jr.randint(kb, (batch_size,), 0, n_train)
            batch = Batch(full_train.x0[idx], full_train.x1[idx], full_train.dt[idx], full_train.scale)
            if shard is not None:
                batch = shard(batch)
            (value, parts), grads = jax.value_and_grad(loss_fn, has_aux=True)(params, batch, kl)
            # Optax mixes int step counts with floats; keep it working under strict promotion.
            with jax.numpy_dtype_promotion("standard"):
                updates, opt_state = optimizer.update(grads, opt_state, params)
            params = eqx.apply_updates(params, updates)
            return (params, opt_state), (value, parts)

        (params, opt_state), (values, parts) = jax.lax.scan(
            one, (params, opt_state), jr.split(key, length)
        )
        return params, opt_state, jnp.mean(values), jax.tree_util.tree_map(jnp.mean, parts)

    return chunk


def fit(
    model: GenericModel,
    data,
    *,
    loss: Loss | None = None,
    optimizer: optax.GradientTransformation | None = None,
    learning_rate: float = 1e-3,
    steps: int = 5000,
    batch_size: int = 256,
    validation: float | Trajectories | None = 0.2,
    eval_every: int = 100,
    patience: int | None = None,
    scale=None,
    dtype=None,
    progress: bool = True,
    seed_split: int = 0,
    checkpoint: str | None = None,
    checkpoint_every: int = 10,
    resume: bool = False,
    data_parallel: bool = False,
    key,
) -> tuple[GenericModel, History]:
    r"""Learn ``model`` from trajectory data; return the best model and the training history.

    Parameters
    ----------
    data:
        :class:`~metriplex.Trajectories` (pairs of consecutive samples, each with its own dt),
        or ready :class:`~metriplex.data.Pairs`.
    loss:
        Default: :func:`~metriplex.CrankNicolsonResidual`.
    validation:
        Fraction of trajectories held out (default 0.2; split **by trajectory**), explicit
        validation ``Trajectories``, or ``None``/``0`` for none. The returned model is the one
        with the lowest validation loss (or training loss without validation).
    patience:
        Stop after this many evaluations without improvement (``None``: never stop early).
    scale:
        Per-component data scale used to weigh loss terms (default: standard deviation of the
        training states, 1 for constant columns).
    dtype:
        ``jnp.float32`` or ``jnp.float64`` (needs ``jax_enable_x64``); default: the model's.
    checkpoint:
        Path of a checkpoint file, written atomically every ``checkpoint_every`` evaluations,
        on Ctrl-C and at the end: parameters, optimiser state, step, PRNG key, best model and
        history. With ``resume=True`` training continues from it and reaches the same result as
        an uninterrupted run with the same arguments.
    data_parallel:
        Split every minibatch over all local devices (``jax.devices()``) with JAX sharding:
        parameters are replicated, the batch axis is sharded, and XLA inserts the gradient
        all-reduce. The result equals single-device training to rounding. ``batch_size`` must be
        a multiple of the device count. Across hosts, call ``jax.distributed.initialize()``
        first (see docs/performance.md).

    ```python
    model, history = fit(model, data, steps=2000, key=jr.key(0))
    ```
    """
    if steps < 0 or batch_size < 1 or eval_every < 1:
        raise MetriplexError(
            f"need steps >= 0, batch_size >= 1 and eval_every >= 1; got steps={steps}, "
            f"batch_size={batch_size}, eval_every={eval_every}."
        )
    loss = CrankNicolsonResidual().as_loss() if loss is None else loss.as_loss()
    n = getattr(model, "n", None) or model_size(model)
    valid_pairs = None
    if isinstance(data, Trajectories) and isinstance(validation, (int, float)) and validation:
        train_data, valid_data = data.split(float(validation), seed=seed_split)
        train_pairs = train_data.pairs()
        valid_pairs = None if valid_data is None else valid_data.pairs()
    else:
        train_pairs, _ = _as_pairs(data)
        if isinstance(validation, Trajectories):
            valid_pairs = validation.pairs()
    _check_pairs(train_pairs, n, "training")
    if valid_pairs is not None:
        _check_pairs(valid_pairs, n, "validation")
    if dtype is None:
        dtype = float_dtype(model, default=jnp.float32)
    if scale is None:
        scale = state_scale(train_pairs.x0)
    scale = np.asarray(scale, dtype=np.float64)
    model = with_dtype(model, dtype)

    optimizer = default_optimizer(learning_rate, steps) if optimizer is None else optimizer
    params, static = eqx.partition(model, eqx.is_inexact_array)
    opt_state = optimizer.init(params)
    n_train = len(train_pairs)
    bsz = min(batch_size, n_train)
    shard = _batch_sharding(data_parallel, bsz)
    full_train = _batch(train_pairs, np.arange(n_train), scale, dtype)

    def loss_fn(p, batch, k):
        return loss(eqx.combine(p, static), batch, key=k)

    run_chunk = eqx.filter_jit(train_chunk(loss, optimizer, static, bsz, shard))

    eval_size = 4096

    @eqx.filter_jit
    def evaluate(params, batch, key):
        return loss_fn(params, batch, key)

    def eval_pairs(params, pairs: Pairs, key) -> tuple[float, dict[str, float]]:
        m = len(pairs)
        if m <= eval_size:
            idx = np.arange(m)
        else:  # a fixed, evenly spread subset: one compiled shape, a stable signal
            idx = np.linspace(0, m - 1, eval_size).astype(int)
        total, parts = evaluate(params, _batch(pairs, idx, scale, dtype), key)
        return float(total), {k: float(v) for k, v in parts.items()}

    history = History()
    best_params = params
    best_value = math.inf
    since_best = 0
    done = 0
    key, eval_key = jr.split(key)
    train_value, train_parts = math.nan, {}
    if resume:
        if checkpoint is None:
            raise MetriplexError("resume=True needs the `checkpoint` path to resume from.")
        state = _checkpoint.load(checkpoint, (params, opt_state, best_params, jr.key_data(key)))
        (params, opt_state, best_params, key_data), meta = state
        key = jr.wrap_key_data(key_data)
        history = History.from_json(meta["history"])
        done, best_value, since_best = meta["done"], meta["best_value"], meta["since_best"]
        train_value, train_parts = meta["train_value"], meta["train_parts"]
        if history.stopped.startswith("interrupted"):
            history.stopped = ""
        if done > steps:
            raise MetriplexError(
                f"the checkpoint is at step {done}, beyond the requested {steps} steps; ask for "
                "at least as many steps as the interrupted run."
            )

    def save_checkpoint():
        if checkpoint is None:
            return
        meta = dict(
            done=done, best_value=best_value, since_best=since_best, history=history.to_json(),
            train_value=train_value, train_parts=train_parts,
        )
        _checkpoint.save(checkpoint, (params, opt_state, best_params, jr.key_data(key)), meta)

    start = time.perf_counter() - (history.time[-1] if history.time else 0.0)
    evaluations = 0
    skip_evaluation = resume
    bar = tqdm(total=steps, initial=done, disable=not progress, desc="fit", unit="step", leave=False)

    def run_next_chunk():
        nonlocal key, params, opt_state, train_value, train_parts, done
        length = min(eval_every, steps - done)
        key, sub = jr.split(key)
        params, opt_state, value, parts = run_chunk(params, opt_state, sub, length, full_train)
        train_value = float(value)
        train_parts = {k: float(v) for k, v in parts.items()}
        done += length
        bar.update(length)

    try:
        while True:
            if skip_evaluation:
                # Resumed: the restored history already holds the evaluation at `done`.
                skip_evaluation = False
                if done >= steps or history.stopped.startswith("early stop"):
                    break
                run_next_chunk()
                continue
            if done > 0 or steps == 0:
                tr_total, tr_parts = train_value, train_parts
            else:
                tr_total, tr_parts = eval_pairs(params, train_pairs, eval_key)
            if valid_pairs is not None:
                va_total, va_parts = eval_pairs(params, valid_pairs, eval_key)
            else:
                va_total, va_parts = tr_total, {}
            history.step.append(done)
            history.time.append(time.perf_counter() - start)
            for name, v in tr_parts.items():
                history.train.setdefault(name, []).append(v)
            history.train.setdefault("total", []).append(tr_total)
            for name, v in va_parts.items():
                history.valid.setdefault(name, []).append(v)
            if va_parts:
                history.valid.setdefault("total", []).append(va_total)
            if not math.isfinite(tr_total) or not math.isfinite(va_total):
                bad = [k for k, v in {**tr_parts, **va_parts}.items() if not math.isfinite(v)]
                history.stopped = f"diverged at step {done} (non-finite: {', '.join(bad)})"
                raise TrainingDiverged(
                    f"training diverged at step {done}: the loss term(s) {bad or ['total']} "
                    f"became non-finite. The best model so far (step {history.best_step}) is "
                    "kept; lower the learning rate or the loss weights.",
                    model=eqx.combine(best_params, static),
                    history=history,
                )
            if va_total < best_value:
                best_value, best_params, since_best = va_total, params, 0
                history.best_step, history.best_valid = done, va_total
            else:
                since_best += 1
            bar.set_postfix(loss=f"{tr_total:.3e}", valid=f"{va_total:.3e}")
            evaluations += 1
            if evaluations % max(checkpoint_every, 1) == 0:
                save_checkpoint()
            if done >= steps:
                history.stopped = history.stopped or "completed"
                break
            if patience is not None and since_best > patience:
                history.stopped = f"early stop at step {done} (no improvement in {patience} evaluations)"
                break
            run_next_chunk()
    except KeyboardInterrupt:
        history.stopped = f"interrupted at step {done}"
    finally:
        bar.close()
    save_checkpoint()
    return eqx.combine(best_params, static), history
