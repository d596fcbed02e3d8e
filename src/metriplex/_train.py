r"""The training step and the training state: what :func:`~metriplex.fit` runs between two
evaluations, and everything a checkpoint must hold to continue it.

- :func:`make_chunk`: ``length`` optimiser steps on random minibatches, compiled as one loop
  (no host round-trip per step; one program for every ``length``);
- :class:`TrainState`: parameters, optimiser state, best and restart parameters, PRNG key and
  the loop's counters, saved and restored as one object (:meth:`TrainState.save`).
"""

from __future__ import annotations

from numbers import Real

import dataclasses
import functools
import math
import os
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np
import optax

from . import _checkpoint
from ._errors import MetriplexError
from ._fit_options import Checkpoint, LBFGSFinish
from ._validate import Average
from .data import Pairs, Trajectories, state_scale, time_scale
from .losses import Batch, Loss

if TYPE_CHECKING:
    from numpy.typing import ArrayLike


@dataclasses.dataclass
class History:
    """Loss terms per evaluation: ``step``, ``train[name]``, ``valid[name]``, wall ``time``.
    ``best_valid`` is the kept model's validation loss, or its training loss where nothing
    was held out (``valid`` is then empty)."""

    step: list[int] = dataclasses.field(default_factory=list)
    train: dict[str, list[float]] = dataclasses.field(default_factory=dict)
    valid: dict[str, list[float]] = dataclasses.field(default_factory=dict)
    time: list[float] = dataclasses.field(default_factory=list)
    learning_rate: list[float] = dataclasses.field(default_factory=list)
    rollout: list[float] = dataclasses.field(default_factory=list)
    rollout_failures: list[int] = dataclasses.field(default_factory=list)
    best_step: int = 0
    best_valid: float = math.inf
    best_rollout: float = math.inf
    best_rollout_failures: int = -1
    stopped: str = ""
    converged: bool = False
    lbfgs_steps: int = 0

    def __repr__(self) -> str:
        # A summary: the lists hold one entry per evaluation (thousands in a long run).
        last = self.step[-1] if self.step else 0
        return (f"History({len(self.step)} evaluations to step {last}, "
                f"best_step={self.best_step}, "
                f"best_valid={self.best_valid:.4g}, best_rollout={self.best_rollout:.4g}, "
                f"stopped={self.stopped!r}, terms={sorted(self.train)})")

    def to_json(self) -> dict[str, Any]:
        """The history as a JSON-able dict (``history.json`` of a run folder)."""
        return dataclasses.asdict(self)

    def generalisation_gap(self) -> float | None:
        """The validation loss over the training loss at the kept step (``best_step``): how
        much worse the model fits held-out trajectories than those it was trained on. The
        training loss is the mean over the steps before that evaluation. ``None`` without
        validation trajectories, or where either loss is not a positive number."""
        if self.best_step not in self.step or not self.valid.get("total"):
            return None
        i = self.step.index(self.best_step)
        train, valid = self.train["total"][i], self.valid["total"][i]
        if not (math.isfinite(train) and math.isfinite(valid) and train > 0.0):
            return None
        return valid / train

    @classmethod
    def from_json(cls, obj: dict[str, Any]) -> "History":
        """The history that :meth:`to_json` wrote; unknown keys are ignored."""
        known = {f.name for f in dataclasses.fields(cls)}
        return cls(**{k: v for k, v in obj.items() if k in known})


def make_chunk(loss: Loss, optimizer: optax.GradientTransformation, static: Any, batch_size: int,
               shard: Callable[[Batch], Batch] | None = None, noise: jax.Array | None = None,
               consecutive: int = 1, *, jit: bool = False,
               ) -> Callable[..., tuple[Any, optax.OptState, jax.Array, dict[str, jax.Array]]]:
    """The unit of training: ``chunk(params, opt_state, key, length, full_train)`` runs
    ``length`` optimiser steps in one loop, each on ``batch_size`` random pairs of
    ``full_train`` (a :class:`~metriplex._pairs.PairStore` of all training pairs), and returns
    ``(params, opt_state, mean loss, mean loss terms)``. Step ``i`` draws from
    ``jr.fold_in(key, i)``.

    ``jit=True`` returns the chunk compiled by one ``eqx.filter_jit`` that every call of
    ``make_chunk`` shares, so chunks of the same loss, optimiser, model structure and shapes
    compile once (the trials of several starts, the stage that trains the chosen one).
    ``length`` may be traced (an array, as ``fit`` passes it): one program then serves every
    length (the evaluations' spacing, a shorter last chunk, the trials' steps).

    The training pairs are an argument, not a closed-over constant, so the data set is not
    embedded in the compiled program and the chunk can be timed on its own
    (``benchmarks/run.py`` times exactly this step).

    ``noise`` (per-variable standard deviations, or ``None``) perturbs both states of every
    pair by one Gaussian draw: the pair's difference, the target, is kept, and the field is
    asked to produce it near the data as well as on it.

    ``consecutive`` > 1 draws each batch as ``batch_size // consecutive`` runs of that many
    consecutive pairs (:meth:`~metriplex._pairs.PairStore.take_runs`; the caller checks that
    the data and the loss allow it), so that the model is evaluated at ``consecutive + 1``
    states per run instead of two per pair.
    """
    return functools.partial(_chunk_compiled if jit else _chunk, loss=loss, optimizer=optimizer,
                             static=static, batch_size=batch_size, shard=shard, noise=noise,
                             consecutive=consecutive)


def _chunk(params, opt_state, key, length, full_train, *, loss, optimizer, static, batch_size,
           shard, noise, consecutive):
    """:func:`make_chunk`'s chunk."""
    n_train = full_train.first.shape[0]

    def loss_fn(p, batch, k):
        return loss(eqx.combine(p, static), batch, key=k)

    def draw(k):
        """The batch of the step whose key is ``k``, and the key of its loss."""
        kb, kl = jr.split(k)
        if consecutive > 1:
            start = jr.randint(kb, (max(1, batch_size // consecutive),), 0,
                               full_train.x.shape[0] - 1)
            batch = full_train.take_runs(start.astype(full_train.first.dtype), consecutive)
        else:
            idx = jr.randint(kb, (batch_size,), 0, n_train)
            batch = full_train.take(idx, loss.window_shape)
        if noise is not None:
            kn = jr.fold_in(kl, 1)
            eps = jr.normal(kn, batch.x0.shape, batch.x0.dtype) * noise[None, :]
            batch = batch._replace(x0=batch.x0 + eps, x1=batch.x1 + eps)
        if shard is not None:
            batch = shard(batch)
        return batch, kl

    def one(params, opt_state, k):
        batch, kl = draw(k)
        (value, parts), grads = jax.value_and_grad(loss_fn, has_aux=True)(params, batch, kl)
        # Optax mixes int step counts with floats; keep it working under strict promotion.
        with jax.numpy_dtype_promotion("standard"):
            updates, opt_state = optimizer.update(grads, opt_state, params)
        params = eqx.apply_updates(params, updates)
        return params, opt_state, (value, parts)

    def body(i, carry):
        params, opt_state, sums = carry
        params, opt_state, terms = one(params, opt_state, jr.fold_in(key, i))
        return params, opt_state, jax.tree_util.tree_map(jnp.add, sums, terms)

    # The running sums start at zeros shaped as the loss and its terms (traced without the
    # gradient and the update).
    shapes = jax.eval_shape(lambda: loss_fn(params, *draw(key)))
    zeros = jax.tree_util.tree_map(lambda s: jnp.zeros(s.shape, s.dtype), shapes)
    params, opt_state, (total, parts) = jax.lax.fori_loop(
        0, length, body, (params, opt_state, zeros))
    count = jnp.asarray(length, total.dtype)
    return params, opt_state, total / count, jax.tree_util.tree_map(lambda v: v / count, parts)


_chunk_compiled = eqx.filter_jit(_chunk)


def make_lbfgs_chunk(loss: Loss, static: Any) -> tuple[
        optax.GradientTransformationExtraArgs,
        Callable[..., tuple[Any, optax.OptState, jax.Array]]]:
    """The compiled unit of the L-BFGS finish: ``chunk(params, opt_state, length, pairs, key)``
    runs ``length`` iterations of :func:`optax.lbfgs` (zoom line search) on the loss of the
    fixed ``pairs`` (a deterministic objective: one batch, one key), and returns
    ``(params, opt_state, last loss)``.

    After Adam has found the basin, a quasi-Newton method on a fixed batch reaches a much
    smaller pair residual in few iterations; :func:`~metriplex.fit` keeps its result only where
    the validation score improves.
    """
    base = optax.lbfgs()
    # Its initial state holds weakly typed scalars (the line search's info) that every
    # iteration returns strongly typed: typed once here, the chunk compiles once, not twice.
    solver = base._replace(init=lambda params: jax.tree_util.tree_map(
        lambda a: a.astype(a.dtype) if eqx.is_array(a) else a, base.init(params)))

    def chunk(params, opt_state, length, pairs, key):
        def value(p):
            return loss(eqx.combine(p, static), pairs, key=key)[0]

        value_and_grad = optax.value_and_grad_from_state(value)

        def one(carry, _):
            params, opt_state = carry
            with jax.numpy_dtype_promotion("standard"):
                v, g = value_and_grad(params, state=opt_state)
                updates, opt_state = solver.update(g, opt_state, params, value=v, grad=g,
                                                   value_fn=value)
            params = eqx.apply_updates(params, updates)
            return (params, opt_state), v

        (params, opt_state), values = jax.lax.scan(one, (params, opt_state), None,
                                                   length=length)
        return params, opt_state, values[-1]

    return solver, chunk


@dataclasses.dataclass
class TrainState:
    """Everything the training loop carries from one evaluation to the next.

    Arrays: the current ``params`` and ``opt_state``, their running average
    ``average_params`` (:class:`~metriplex.train.Average`; the parameters that evaluations
    judge, else equal to ``params``), the ``best_params`` (best validation score, the model
    returned), the ``restart_params`` (best validation loss, where a plateau cut restarts from)
    and the PRNG ``key``. Counters: optimiser steps ``done``, the best score
    and loss so far, evaluations ``since_best`` improvement, learning-rate ``cuts`` and the
    current base rate ``lr``, the last chunk's mean training loss, and the ``history``.
    """

    params: Any
    opt_state: Any
    average_params: Any
    best_params: Any
    restart_params: Any
    key: Any
    lr: float
    done: int = 0
    best_value: float = math.inf
    plateau_best: float = math.inf
    since_best: int = 0
    cuts: int = 0
    train_value: float = math.nan
    train_parts: dict[str, float] = dataclasses.field(default_factory=dict)
    history: History = dataclasses.field(default_factory=History)

    @classmethod
    def start(cls, params: Any, opt_state: optax.OptState, key: jax.Array,
              lr: float) -> "TrainState":
        return cls(params=params, opt_state=opt_state, average_params=params,
                   best_params=params, restart_params=params, key=key, lr=float(lr))

    def _arrays(self):
        return (self.params, self.opt_state, self.average_params, self.best_params,
                self.restart_params, jr.key_data(self.key))

    def save(self, path: str | os.PathLike) -> None:
        """Write the state to ``path`` atomically (JSON header + Equinox leaves)."""
        meta = dict(
            done=self.done, best_value=self.best_value, since_best=self.since_best,
            history=self.history.to_json(), train_value=self.train_value,
            train_parts=self.train_parts, cuts=self.cuts, lr=self.lr,
            plateau_best=self.plateau_best,
        )
        _checkpoint.save(path, self._arrays(), meta)

    def load(self, path: str | os.PathLike) -> "TrainState":
        """The state saved at ``path``, read with this state's array structure."""
        (params, opt_state, average, best, restart, key_data), meta = _checkpoint.load(
            path, self._arrays())
        return TrainState(
            params=params, opt_state=opt_state, average_params=average, best_params=best,
            restart_params=restart,
            key=jr.wrap_key_data(key_data), lr=meta["lr"], done=meta["done"],
            best_value=meta["best_value"], plateau_best=meta["plateau_best"],
            since_best=meta["since_best"], cuts=meta["cuts"], train_value=meta["train_value"],
            train_parts=meta["train_parts"], history=History.from_json(meta["history"]),
        )


def check_arguments(*, steps: int, batch_size: int, eval_every: int, learning_rate: float,
                    patience: int | None, input_noise: Any, checkpoint: Any,
                    finish: Any, average: Any = None, consecutive: int = 1) -> None:
    """Refuse :func:`~metriplex.fit` arguments out of range, naming the value received."""
    if isinstance(consecutive, bool) or not isinstance(consecutive, int) or consecutive < 1:
        raise MetriplexError(
            f"consecutive must be an integer >= 1 (pairs per run in a batch; 1 for "
            f"independent pairs); got {consecutive!r}.")
    if steps < 0 or batch_size < 1 or eval_every < 1:
        raise MetriplexError(
            f"need steps >= 0, batch_size >= 1 and eval_every >= 1; got steps={steps}, "
            f"batch_size={batch_size}, eval_every={eval_every}."
        )
    if not learning_rate > 0:
        raise MetriplexError(f"the learning rate must be > 0; got {learning_rate}.")
    if patience is not None and patience < 1:
        raise MetriplexError(f"patience must be >= 1 evaluations; got {patience}.")
    for name, value, cls, example in (
            ("checkpoint", checkpoint, Checkpoint, 'Checkpoint("run/checkpoint.ckpt")'),
            ("finish", finish, LBFGSFinish, "LBFGSFinish(steps=1000)"),
            ("average", average, Average, "Average(steps=500)")):
        if value is not None and not isinstance(value, cls):
            raise MetriplexError(
                f"fit's {name}= must be None or {cls.__name__}(...); got {type(value).__name__} "
                f"{value!r}. Example: {name}={example}."
            )
    if not np.all((0 <= np.asarray(input_noise)) & (np.asarray(input_noise) < 1)):
        raise MetriplexError(
            f"input_noise must be in [0, 1) (a fraction of each variable's standard "
            f"deviation, one for all or one per variable); got {input_noise}."
        )
    if checkpoint is not None and Path(checkpoint.path).is_dir():
        raise MetriplexError(
            f"Checkpoint's path must name a file; {str(checkpoint.path)!r} is a folder. "
            f"Example: Checkpoint({str(Path(checkpoint.path) / 'checkpoint.ckpt')!r}).")


def training_dtype(dtype: Any) -> np.dtype:
    """``fit``'s ``dtype=``, checked: float32, or float64 where JAX has x64 enabled."""
    try:
        checked = np.dtype(dtype)
    except TypeError:
        checked = None
    if checked not in (np.dtype(np.float32), np.dtype(np.float64)):
        raise MetriplexError(
            f"fit's dtype= must be float32 or float64 (jnp.float32, jnp.float64); got "
            f"{repr(dtype) if checked is None else checked.name}.")
    if checked == np.float64 and not jax.config.jax_enable_x64:
        raise MetriplexError(
            "fit's dtype=float64 needs JAX's x64 mode, which is off: call "
            "`jax.config.update('jax_enable_x64', True)` before creating any array, or train "
            "in float32.")
    return checked


def split_validation(data: Trajectories | Pairs | tuple[ArrayLike, ArrayLike, ArrayLike],
                     validation: float | Trajectories | None, seed: int,
                     ) -> tuple[Trajectories | Pairs | tuple, Trajectories | None]:
    """``(training data, validation trajectories or None)`` as :func:`~metriplex.fit`'s
    ``validation`` asks: a fraction of the trajectories of ``data`` (split by trajectory, with
    ``seed``), explicit ``Trajectories``, or ``None``/``0`` for none. Pairs hold no
    trajectories, so a fraction holds none of them out."""
    if validation is None or isinstance(validation, Trajectories):
        return data, validation
    if isinstance(validation, bool) or not isinstance(validation, Real):
        raise MetriplexError(
            f"validation must be a fraction of the trajectories to hold out (such as 0.2), "
            f"validation Trajectories, or None; got {type(validation).__name__} "
            f"{validation!r:.40}."
        )
    if isinstance(data, Trajectories) and validation:
        return data.split(float(validation), seed=seed)
    return data, None


def default_scale(x: np.ndarray, data: Trajectories | Pairs | tuple) -> np.ndarray:
    r""":func:`~metriplex.fit`'s default rate scale :math:`d_i/\tau`: the standard deviation of
    the training states ``x`` over the time scale of the training ``data``."""
    d = state_scale(x)
    return d / time_scale(data if isinstance(data, Trajectories)
                          else Pairs(*(np.asarray(a) for a in data)), d)


def spread(m: int, k: int) -> np.ndarray:
    """Indices of all ``m`` items when ``m <= k``, else of ``k`` evenly spread ones (a fixed
    subset: one compiled shape, the same items at every evaluation)."""
    return np.arange(m) if m <= k else np.linspace(0, m - 1, k).astype(int)


def batch_sharding(enabled: bool, batch_size: int) -> Callable[[Batch], Batch] | None:
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
        # Windows, where the loss reads any, stay as the step gathered them.
        return batch._replace(x0=c(batch.x0, rows), x1=c(batch.x1, rows), dt=c(batch.dt, rows),
                              scale=c(batch.scale, whole))

    return shard
