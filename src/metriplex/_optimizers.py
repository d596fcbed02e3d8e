"""The optimisers of :func:`~metriplex.fit`: :func:`adjustable_optimizer` (Adam whose rate the
training loop changes between chunks: plateau cuts, the final :func:`annealing`; read and set
with :func:`learning_rate_of` and :func:`with_learning_rate`) and :func:`default_optimizer` (Adam
on the fixed :func:`cosine_schedule`).

Both are memoised: ``fit`` calls with the same settings get the same optimiser object, so the
chunk compiled for one (``_train.make_chunk(..., jit=True)``) serves the next. The compiled
chunks of a process's fits stay cached while it runs (one per loss, optimiser, model
structure and shapes); ``jax.clear_caches()`` frees them.
"""

from __future__ import annotations

import functools
import math

import jax.numpy as jnp
import optax


def adjustable_optimizer(learning_rate: float, warmup: int = 100,
                         weight_decay: float = 0.0) -> optax.GradientTransformation:
    """Adam (gradients clipped to norm 10) with a linear warm-up from 10% over ``warmup`` steps,
    whose learning rate the training loop can change between chunks
    (:func:`with_learning_rate`); ``weight_decay`` > 0 makes it AdamW (decoupled decay of every
    weight). Any real scalars (Python, NumPy or 0-d JAX values) are accepted."""
    return _adjustable(float(learning_rate), int(warmup), float(weight_decay))


@functools.lru_cache(maxsize=64)
def _adjustable(learning_rate: float, warmup: int, weight_decay: float):
    return optax.chain(
        optax.clip_by_global_norm(10.0),
        optax.scale_by_adam(),
        optax.add_decayed_weights(weight_decay) if weight_decay else optax.identity(),
        optax.scale_by_schedule(
            optax.linear_schedule(0.1, 1.0, max(warmup, 1))
        ),
        optax.inject_hyperparams(optax.scale)(step_size=-learning_rate),
    )


def cosine_schedule(learning_rate: float, steps: int) -> optax.Schedule:
    """A short linear warm-up, then cosine decay to 1% of the peak rate over ``steps``."""
    return optax.warmup_cosine_decay_schedule(
        init_value=learning_rate * 0.1,
        peak_value=learning_rate,
        warmup_steps=min(100, max(steps // 20, 1)),
        decay_steps=max(steps, 2),
        end_value=learning_rate * 1e-2,
    )


def default_optimizer(learning_rate: float, steps: int) -> optax.GradientTransformation:
    """Adam on the :func:`cosine_schedule` (the optimiser of ``fit(..., stopping=None)``: a
    fixed number of steps)."""
    return _default(float(learning_rate), int(steps))


@functools.lru_cache(maxsize=64)
def _default(learning_rate: float, steps: int):
    return optax.chain(optax.clip_by_global_norm(10.0),
                       optax.adam(cosine_schedule(learning_rate, steps)))


def annealing(step: int, start: int, end: int) -> float:
    """The factor on the learning rate at ``step`` of a cosine annealing to 1% between
    ``start`` and ``end`` (1 before ``start``)."""
    frac = min(max((step - start) / max(end - start, 1), 0.0), 1.0)
    return 0.01 + 0.99 * 0.5 * (1.0 + math.cos(math.pi * frac))


def _rate_state(opt_state):
    """The injected-hyperparameter state of :func:`adjustable_optimizer`, or ``None``."""
    last = opt_state[-1] if isinstance(opt_state, tuple) and opt_state else None
    # inject_hyperparams' state is InjectStatefulHyperparamsState in current Optax and
    # InjectHyperparamsState in older ones.
    states = (optax.InjectHyperparamsState, optax.InjectStatefulHyperparamsState)
    if isinstance(last, states) and "step_size" in last.hyperparams:
        return last
    return None


def is_adjustable(opt_state: optax.OptState) -> bool:
    """Whether ``opt_state`` belongs to an :func:`adjustable_optimizer`."""
    return _rate_state(opt_state) is not None


def learning_rate_of(opt_state: optax.OptState, default: float) -> float:
    """The current rate of an :func:`adjustable_optimizer`'s state, else ``default``."""
    last = _rate_state(opt_state)
    return default if last is None else -float(last.hyperparams["step_size"])


def with_learning_rate(opt_state: optax.OptState, learning_rate: float) -> optax.OptState:
    """``opt_state`` of :func:`adjustable_optimizer` with another learning rate."""
    last = _rate_state(opt_state)
    old = last.hyperparams["step_size"]
    hyper = {**last.hyperparams, "step_size": jnp.asarray(-learning_rate, old.dtype)}
    return (*opt_state[:-1], last._replace(hyperparams=hyper))
