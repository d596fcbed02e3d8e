r"""Diagnostics that answer "how good is this model, and is it GENERIC?".

One set of functions judges ground-truth systems and learned models alike:

- rollout errors (relative L2 per trajectory, per variable, over time) against observed data,
  rolled out from each trajectory's first state on its own time grid, beside the error of
  predicting no motion at all, :math:`x(t) = x(0)`, which a model must beat to predict anything
  (``constant_prediction_error_mean``; ``constant_prediction_error_standardised_mean`` in
  standard deviations, beside ``rollout_error_standardised_mean``);
- the energy's relative drift along the model's own rollout (to the larger of :math:`|E(x_0)|`
  and E's spread over the data, as its offset is arbitrary), and beyond noise along the data,
  which GENERIC data keep constant (``energy_change_along_data_over_spread``), all null where
  E is constant to rounding over the data (``energy_rounding_over_data_spread``); entropy steps;
- degeneracy residuals :math:`|L\nabla S|`, :math:`|M\nabla E|` relative to the size of their
  factors, the Jacobi residual relative to the size of its terms, the PSD margin of ``M``,
  in standardised coordinates (each variable in its standard deviation over the data), as the
  verdict reads them;
- the sign of the entropy production :math:`\dot S = \nabla S\cdot\dot x` at the states along
  the model's rollouts;
- the step sensitivity: how much of the predicted motion changes when the data's time step is
  refined (:func:`step_sensitivity`), which tells a model of the system's vector field from one
  that is right only with its scheme at the data's step; and how soon the model's rollouts
  from nearby states part (:func:`initial_state_sensitivity`: chaos, or a period that
  depends on the amplitude), beyond which an error measures that as much as the model;
- what the data can determine of the learned E, S and temperatures at all, from which blocks
  are given and which learned (``identified``, :func:`identified`: e.g. with L = 0 the energy
  only up to a function of itself).

No quantity that could not be computed is reported as a number: it is ``None`` (``null`` in
JSON), and ``null_reasons`` says why (for instance "no rollout ran two steps").
"""

from __future__ import annotations

import contextlib
from numbers import Real
from concurrent.futures import ThreadPoolExecutor
from typing import Any, Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._errors import MetriplexError
from ._precision import in_full_precision
from ._model import GenericModel, float_dtype
from ._energy_along import energy_figures
from ._entropy_rise import ENTROPY_ROUNDING_UNITS as ENTROPY_ROUNDING_UNITS
from ._entropy_rise import entropy_rise, entropy_rise_ratio
from ._entropy_rise import entropy_step_rounding as entropy_step_rounding
from ._entropy_production import (  # noqa: F401 (re-exported)
    entropy_production_negative_fraction as entropy_production_negative_fraction,
)
from ._standardised import standardised_errors
# The residuals at given states (no rollout; every rollout is here), public from here.
from ._structure_check import identified, structure_residuals
from .data import Trajectories, check_width, state_scale
from ._solve.rollout import RETRY_SUBSTEPS
from .integrate import AbstractScheme, CrankNicolson, Rollout, model_size, solve
from ._progress import progress_bar
from ._threads import cpu_threads, in_this_threads_config
from ._sensitivity import SENSITIVITY_REFINE as SENSITIVITY_REFINE
from ._sensitivity import SENSITIVITY_STEPS as SENSITIVITY_STEPS
from ._sensitivity import SENSITIVITY_TRAJECTORIES as SENSITIVITY_TRAJECTORIES
from ._sensitivity import initial_state_sensitivity as initial_state_sensitivity
from ._sensitivity import step_sensitivity as step_sensitivity

_TINY = 1e-300

#: Data of up to this many states (trajectories x samples) are rolled out in one compiled call;
#: larger data in :data:`ROLLOUT_BATCHES` equal batches of trajectories (compiled once), each a
#: step of the progress bar.
ROLLOUT_BATCH_STATES = 50_000
ROLLOUT_BATCHES = 10


@in_full_precision
def rollout_data(model: GenericModel, data: Trajectories, *, scheme: AbstractScheme | None = None,
                 progress: bool = False,
                 retry: int = RETRY_SUBSTEPS) -> tuple[Rollout, np.ndarray, np.ndarray]:
    """Roll ``model`` out from each trajectory's first state on its own grid (ragged-safe).
    A step whose solve fails is retaken as ``retry`` substeps before the trajectory is called
    failed (:func:`metriplex.solve`'s ``retry``; 0: never).

    Returns ``(rollout, observed_xs, lengths)`` on the padded grid of :meth:`Trajectories.padded`.
    Data of more than :data:`ROLLOUT_BATCH_STATES` states are rolled out in
    :data:`ROLLOUT_BATCHES` batches of trajectories (all of one shape, so compiled once, by the
    first; on the CPU the others then run as many side by side as there are cores), with a
    progress bar when ``progress``; the results are those of one call.
    """
    ts, xs, lengths = data.padded()
    dtype = float_dtype(model)
    K, T = ts.shape
    size = K if K * T <= ROLLOUT_BATCH_STATES else -(-K // max(1, ROLLOUT_BATCHES))
    if size >= K:
        out = solve(model, jnp.asarray(xs[:, 0], dtype), ts, scheme=scheme, retry=retry)
        return out._replace(ts=ts), xs, lengths  # the data's own times, in float64

    def batch(a):
        b = min(a + size, K)
        x0, grid = xs[a:b, 0], ts[a:b]
        if b - a < size:  # pad the last batch with trajectories that never move
            pad = size - (b - a)
            x0 = np.concatenate([x0, np.repeat(x0[-1:], pad, axis=0)])
            grid = np.concatenate([grid, np.full((pad, T), grid[-1, 0])])
        out = solve(model, jnp.asarray(x0, dtype), grid, scheme=scheme, retry=retry)
        return [np.asarray(v)[: b - a] for v in out._replace(ts=grid)]

    starts = range(0, K, size)
    with progress_bar(total=K, disable=not progress, desc="rollouts", unit="trajectory",
                      leave=False) as bar:
        parts = [batch(0)]  # compiles the program the other batches run
        bar.update(len(parts[0][1]))
        threads = cpu_threads()
        with (ThreadPoolExecutor(threads) if threads > 1 else contextlib.nullcontext()) as pool:
            for part in (pool.map(in_this_threads_config(batch), starts[1:]) if pool else
                         map(batch, starts[1:])):
                parts.append(part)
                bar.update(len(part[1]))
    return Rollout(*(np.concatenate(p) for p in zip(*parts))), xs, lengths


@in_full_precision
def potential_along(model: GenericModel, fn: Callable[[jax.Array], jax.Array],
                    xs: np.ndarray) -> np.ndarray:
    """A potential of ``model`` (``fn``: ``model.energy`` or ``model.entropy``) at every state of
    ``xs`` (shape ``(K, T, n)``, e.g. predicted trajectories), as ``(K, T)`` float64; computed
    in blocks of states, in the model's dtype."""
    xs = np.asarray(xs)
    flat = jnp.asarray(xs.reshape(-1, xs.shape[-1]), float_dtype(model))
    return np.asarray(_map_states(fn, flat), dtype=np.float64).reshape(xs.shape[:-1])


@in_full_precision
def energy_entropy_along(model: GenericModel,
                         xs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``model``'s energy and entropy at every state of ``xs`` (shape ``(..., n)``), each of
    shape ``xs.shape[:-1]``, float64: :func:`potential_along` for both in one pass (one
    program to compile, not two; the same values)."""
    xs = np.asarray(xs)
    flat = jnp.asarray(xs.reshape(-1, xs.shape[-1]), float_dtype(model))
    E, S = _map_energy_entropy(model, flat)
    return tuple(np.asarray(v, dtype=np.float64).reshape(xs.shape[:-1]) for v in (E, S))


@eqx.filter_jit
def _map_energy_entropy(model, xs):
    return jax.lax.map(lambda x: (model.energy(x), model.entropy(x)), xs, batch_size=4096)


@eqx.filter_jit
def _map_states(fn, xs):
    # In blocks of states: the networks' hidden layers for 1e5 states at once would hold
    # more memory than the data (vmap inside, a sequential map over the blocks).
    return jax.lax.map(fn, xs, batch_size=4096)


@in_full_precision
def evaluate(
    model: GenericModel,
    data: Trajectories,
    *,
    scheme: AbstractScheme | None = None,
    horizon: float | None = None,
    rollout: tuple[Rollout, np.ndarray, np.ndarray] | None = None,
    progress: bool = False,
    step_check: bool = True,
) -> dict[str, Any]:
    """Metrics of ``model`` on ``data`` (see the module docstring); a JSON-able dict.

    ``horizon`` (> 0): also report the rollout error up to ``t0 + horizon``
    (``rollout_error_to_horizon``, ``rollout_error_to_horizon_mean``; null where a trajectory
    has no step within it) and ``trajectories_ending_before_horizon`` (their error is that of
    their whole length).
    ``rollout``: what :func:`rollout_data` returned for this model, data and scheme, to reuse
    (otherwise the trajectories are rolled out here, with a progress bar when ``progress``).
    ``step_check``: also report ``step_sensitivity`` (:func:`step_sensitivity`; one more
    rollout of a few trajectories with a 4x smaller step), ``twin_growth`` and
    ``predictability_time`` (:func:`initial_state_sensitivity`; one more of nearby states).

    ```python
    report = mx.evaluate(model, data)
    report["rollout_error_mean"]
    ```
    """
    scheme = CrankNicolson() if scheme is None else scheme
    _check_inputs(model, data, scheme, horizon)
    if rollout is None:
        rollout = rollout_data(model, data, scheme=scheme, progress=progress)
    # What follows the rollouts takes seconds on large data (compiles, every predicted state
    # through E and S): one bar over its phases.
    bar = progress_bar(total=3 if step_check else 2, disable=not progress,
                       desc="diagnostics", unit="phase", leave=False)
    bar.set_postfix_str("energy and entropy along the rollouts")
    out, xs, lengths = rollout
    pred = np.asarray(out.xs, dtype=np.float64)
    ts = np.asarray(out.ts, dtype=np.float64)
    failed = np.asarray(out.failed_step)
    per_traj, per_traj_h, const, const_h = [], [], [], []
    per_var_num = np.zeros(data.n)
    per_var_den = np.zeros(data.n)
    for k, T in enumerate(lengths):
        p, o = pred[k, :T], xs[k, :T]
        const.append(_relative_error(np.broadcast_to(o[:1], o.shape), o))
        if horizon is not None:
            # Only the states up to the horizon count: a rollout that stops later has a
            # finite error up to the horizon (its failure is in `rollout_failures`).
            m = ts[k, :T] <= ts[k, 0] + horizon + 1e-12
            if np.count_nonzero(m) < 2:  # no step inside: nothing to judge, not a 0 error
                per_traj_h.append(float("nan"))
                const_h.append(float("nan"))
            else:
                per_traj_h.append(_relative_error(p[m], o[m]))
                const_h.append(_relative_error(np.broadcast_to(o[:1], o[m].shape), o[m]))
        if not np.all(np.isfinite(p)):
            per_traj.append(float("inf"))
            continue
        per_traj.append(_relative_error(p, o))
        per_var_num += np.sum((p - o) ** 2, axis=0)
        per_var_den += np.sum(o**2, axis=0)
    completed = any(np.isfinite(e) for e in per_traj)
    standardised = standardised_errors(pred, xs, lengths, data.x)
    still = standardised_errors(np.broadcast_to(xs[:, :1], xs.shape), xs, lengths, data.x)
    n_failed = int(np.sum(failed >= 0))
    E, S = energy_entropy_along(model, np.nan_to_num(pred))
    dS_min, neg_frac, along, rounding = [], [], [], []
    dtype = float_dtype(model)
    E_data, S_data = energy_entropy_along(model, xs)
    for k, T in enumerate(lengths):
        if failed[k] >= 0:
            T = min(int(failed[k]), int(T))
        along.append(pred[k, :T])
        if T < 2:
            continue
        s = S[k, :T]
        ds = np.diff(s)
        dS_min.append(float(ds.min()))
        rounding.append(entropy_step_rounding(s, dtype))
        neg_frac.append(float(np.mean(ds < -rounding[-1])))
    null_reasons: dict[str, str] = {}
    failures = f"{n_failed} of {len(lengths)} rollouts failed"

    def known(value, key, why):
        if value is None or not np.isfinite(value):
            null_reasons[key] = why
            return None if value is None else float(value)
        return float(value)

    no_steps = f"no rollout ran two steps ({failures})"
    report: dict[str, Any] = {
        "trajectories": int(len(lengths)),
        # How long the trajectories run (median): an error over a short one says less.
        "duration_median": float(np.median([ts[k, T - 1] - ts[k, 0]
                                            for k, T in enumerate(lengths)])),
        # The data's ids, in the order of every per-trajectory list below.
        "trajectory_ids": [int(i) for i in data.ids],
        "variables": list(data.names),
        "scheme": scheme.name,
        # A failed rollout's error is inf here and null in a JSON file.
        "rollout_error": per_traj,
        "rollout_error_mean": known(float(np.mean(per_traj)), "rollout_error_mean", failures),
        # Over the completed rollouts only; null (never 0.0) when every rollout failed.
        "rollout_error_per_variable": {
            name: float(np.sqrt(a / max(b, _TINY))) if completed else None
            for name, a, b in zip(data.names, per_var_num, per_var_den)
        },
        "rollout_failures": n_failed,
        # In standard deviations about the data's mean: an offset cannot shrink it.
        "rollout_error_standardised_mean": known(float(np.mean(standardised)),
                                                 "rollout_error_standardised_mean", failures),
        "rollout_error_standardised": [float(e) for e in standardised],  # per trajectory
        "rollout_error_mean_completed": known(
            float(np.mean([e for e in per_traj if np.isfinite(e)])) if completed else None,
            "rollout_error_mean_completed", f"no rollout completed ({failures})"),
        # The same error for the prediction x(t) = x(0) (no motion), over all trajectories: a
        # model whose rollouts do not beat it predicts nothing of these data.
        "constant_prediction_error_mean": float(np.mean(const)),
        "constant_prediction_error": [float(c) for c in const],  # per trajectory, as above
        "constant_prediction_error_standardised_mean": float(np.mean(still)),
        # Over the completed rollouts only, as rollout_error_mean_completed.
        "constant_prediction_error_mean_completed": known(
            float(np.mean([c for c, e in zip(const, per_traj) if np.isfinite(e)]))
            if completed else None,
            "constant_prediction_error_mean_completed", f"no rollout completed ({failures})"),
        **energy_figures(E, E_data, ts, lengths, failed, dtype, null_reasons, no_steps),
        "entropy_min_step": known(float(np.min(dS_min)) if dS_min else None,
                                  "entropy_min_step", no_steps),
        "entropy_negative_step_fraction": known(float(np.mean(neg_frac)) if neg_frac else None,
                                                "entropy_negative_step_fraction", no_steps),
        # The largest rounding of S along the rollouts (entropy_step_rounding): an entropy
        # step down by less is rounding, not a decrease (neither in the fraction above nor in
        # the bar "entropy never decreasing").
        "entropy_step_rounding": known(float(np.max(rounding)) if rounding else None,
                                       "entropy_step_rounding", no_steps),
        # How much more the entropy rises along the rollouts than along the data (mean over
        # the completed ones), in units of its spread over the data's states.
        "entropy_rise_over_data_spread": entropy_rise(S, S_data, lengths, failed,
                                                      null_reasons),
        # How many times the data's rise of it the rollouts make (1 where S tracks the data).
        "entropy_rise_over_data_rise": entropy_rise_ratio(S, S_data, lengths, failed,
                                                          null_reasons),
        # At the states of the rollouts up to any failure; null when none ran two steps.
        "entropy_production_negative_fraction": known(
            entropy_production_negative_fraction(model, np.concatenate(along),
                                                 state_scale(data.x)) if dS_min else None,
            "entropy_production_negative_fraction", no_steps),
    }
    if not completed:
        null_reasons["rollout_error_per_variable"] = f"no rollout completed ({failures})"
    if horizon is not None:
        report["horizon"] = float(horizon)
        report["rollout_error_to_horizon"] = per_traj_h
        # Data that end before the horizon give their whole length's error under its name.
        report["trajectories_ending_before_horizon"] = int(sum(
            ts[k, T - 1] - ts[k, 0] < horizon * (1 - 1e-9) for k, T in enumerate(lengths)))
        short = bool(np.any(np.isnan(per_traj_h)))
        report["rollout_error_to_horizon_mean"] = known(
            None if short else float(np.mean(per_traj_h)), "rollout_error_to_horizon_mean",
            "a trajectory has no step within the horizon" if short else
            "a rollout failed before the horizon")
        report["constant_prediction_error_to_horizon_mean"] = known(
            None if short else float(np.mean(const_h)),
            "constant_prediction_error_to_horizon_mean",
            "a trajectory has no step within the horizon")
    bar.update()
    if step_check:
        bar.set_postfix_str("step sensitivity")
        sensitivity, why = step_sensitivity(model, data, scheme=scheme, rollout=rollout)
        report["step_sensitivity"] = known(sensitivity, "step_sensitivity", why)
        twins, why_not = initial_state_sensitivity(model, data, scheme=scheme, rollout=rollout)
        report.update(twins)
        null_reasons.update(why_not)
        bar.update()
    bar.set_postfix_str("structure residuals")
    # In standardised coordinates, as the verdict reads them: one name, one number.
    structure = structure_residuals(model, data.x, scale=state_scale(data.x))
    bar.update()
    bar.close()
    null_reasons.update(structure.pop("null_reasons"))
    report.update(structure)
    report["null_reasons"] = null_reasons
    return report


def _check_inputs(model, data, scheme, horizon) -> None:
    """evaluate's arguments, each of its kind (a clear error, not an AttributeError deep in)."""
    from ._model import AbstractModel

    if not isinstance(model, AbstractModel):
        raise MetriplexError(
            f"evaluate takes a model (metriplex.load(RUN) gives one); got {type(model).__name__}"
            f" {model!r:.60}."
        )
    if not isinstance(data, Trajectories):
        raise MetriplexError(
            f"evaluate takes Trajectories (metriplex.read(PATH) gives them); got "
            f"{type(data).__name__} {data!r:.60}."
        )
    if not isinstance(scheme, AbstractScheme):
        raise MetriplexError(
            f"scheme must be a scheme object such as metriplex.CrankNicolson(); got {scheme!r}."
        )
    n = model_size(model)  # None for a model of known functions only
    if n is not None:
        check_width(data.n, n)
    if horizon is not None and (isinstance(horizon, bool) or not isinstance(horizon, Real)
                                or not np.isfinite(horizon) or horizon <= 0):
        raise MetriplexError(f"horizon must be a time > 0 (from each trajectory's start); got "
                             f"{horizon!r}.")


def _relative_error(pred: np.ndarray, obs: np.ndarray) -> float:
    """``|pred - obs| / |obs|`` over a whole trajectory; inf if any predicted state is missing."""
    if not np.all(np.isfinite(pred)):
        return float("inf")
    with np.errstate(over="ignore"):  # a rollout that blew up to 1e200: its error is inf
        return float(np.linalg.norm(pred - obs) / max(np.linalg.norm(obs), _TINY))


def error_over_time(pred: np.ndarray, obs: np.ndarray) -> np.ndarray:
    """Relative error ``|pred(t) - obs(t)| / rms|obs|`` at each time (one trajectory)."""
    scale = max(float(np.sqrt(np.mean(np.sum(obs**2, axis=-1)))), _TINY)
    with np.errstate(over="ignore", invalid="ignore"):  # blown-up states: inf; failed: NaN
        return np.linalg.norm(pred - obs, axis=-1) / scale


def time_to_error(ts: np.ndarray, pred: np.ndarray, obs: np.ndarray,
                  threshold: float = 0.1) -> float:
    """First time at which the relative error exceeds ``threshold`` (``inf`` if never)."""
    err = error_over_time(pred, obs)
    above = np.flatnonzero(~(err <= threshold))
    return float("inf") if len(above) == 0 else float(ts[above[0]] - ts[0])
