r"""Diagnostics that answer "how good is this model, and is it GENERIC?".

One set of functions judges ground-truth systems and learned models alike:

- rollout errors (relative L2 per trajectory, per variable, over time) against observed data,
  rolled out from each trajectory's first state on its own time grid;
- the energy's relative drift and the entropy change per step along the model's own rollout;
- degeneracy residuals :math:`|L\nabla S|`, :math:`|M\nabla E|` relative to the size of their
  factors, the Jacobi residual relative to the size of its terms, the PSD margin of ``M``.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from ._model import GenericModel, float_dtype
from .data import Trajectories
from .integrate import AbstractScheme, CrankNicolson, solve

_TINY = 1e-300


def rollout_data(model: GenericModel, data: Trajectories, *, scheme: AbstractScheme | None = None):
    """Roll ``model`` out from each trajectory's first state on its own grid (ragged-safe).

    Returns ``(rollout, observed_xs, lengths)`` on the padded grid of :meth:`Trajectories.padded`.
    """
    ts, xs, lengths = data.padded()
    dtype = float_dtype(model)
    out = solve(model, jnp.asarray(xs[:, 0], dtype), jnp.asarray(ts, dtype), scheme=scheme)
    return out, xs, lengths


def _potential_along(model, fn, xs):
    xs = jnp.asarray(xs, float_dtype(model))
    return np.asarray(jax.vmap(jax.vmap(fn))(xs), dtype=np.float64)


def structure_residuals(model: GenericModel, x: np.ndarray, *, max_states: int = 256) -> dict:
    """Degeneracy, Jacobi and PSD diagnostics at states ``x`` (subsampled to ``max_states``)."""
    x = np.asarray(x)
    if len(x) > max_states:
        x = x[np.linspace(0, len(x) - 1, max_states).astype(int)]
    xj = jnp.asarray(x, float_dtype(model))
    terms = jax.vmap(model.terms)(xj)
    f64 = lambda a: np.asarray(a, dtype=np.float64)  # noqa: E731
    L, M = f64(terms.poisson), f64(terms.friction)
    gE, gS = f64(terms.grad_energy), f64(terms.grad_entropy)
    LgS = np.einsum("bij,bj->bi", L, gS)
    MgE = np.einsum("bij,bj->bi", M, gE)
    nL = np.linalg.norm(L, axis=(1, 2))
    nM = np.linalg.norm(M, axis=(1, 2))
    nS = np.linalg.norm(gS, axis=1)
    nE = np.linalg.norm(gE, axis=1)
    rel_LS = np.linalg.norm(LgS, axis=1) / np.maximum(nL * nS, _TINY)
    rel_MS = np.linalg.norm(MgE, axis=1) / np.maximum(nM * nE, _TINY)
    J = f64(jax.vmap(model.jacobi_tensor)(xj[: min(len(x), 64)]))
    # Each of the three cyclic terms of J has the Frobenius norm of T = (dL) L; measure J
    # against their sum, so 1 means "no cancellation at all" and 0 an exact Poisson bracket.
    jac_abs = np.sqrt(np.sum(J**2, axis=(1, 2, 3)))
    jac_scale = f64(jax.vmap(lambda xi: _jacobi_scale(model, xi))(xj[: min(len(x), 64)]))
    eig = np.linalg.eigvalsh(0.5 * (M + np.swapaxes(M, 1, 2)))
    asym = np.linalg.norm(L + np.swapaxes(L, 1, 2), axis=(1, 2)) / np.maximum(nL, _TINY)
    return {
        "degeneracy_L_gradS": float(np.mean(np.linalg.norm(LgS, axis=1))),
        "degeneracy_M_gradE": float(np.mean(np.linalg.norm(MgE, axis=1))),
        "degeneracy_L_gradS_relative": float(np.mean(rel_LS)) if np.any(nL * nS > 0) else 0.0,
        "degeneracy_M_gradE_relative": float(np.mean(rel_MS)) if np.any(nM * nE > 0) else 0.0,
        "jacobi_residual": float(np.mean(jac_abs)),
        "jacobi_residual_relative": float(np.mean(jac_abs / np.maximum(jac_scale, _TINY)))
        if np.any(jac_scale > 0)
        else 0.0,
        "poisson_antisymmetry_relative": float(np.max(asym)),
        "friction_min_eigenvalue": float(np.min(eig)),
        "friction_max_eigenvalue": float(np.max(eig)),
    }


def _jacobi_scale(model: GenericModel, x):
    from ._model import _value_and_jacfwd

    L, dL = _value_and_jacfwd(model.poisson_matrix, x)
    n = x.shape[0]
    T = dL.reshape(n * n, n) @ L
    return 3.0 * jnp.sqrt(jnp.sum(T**2))


def evaluate(
    model: GenericModel,
    data: Trajectories,
    *,
    scheme: AbstractScheme | None = None,
    horizon: float | None = None,
) -> dict[str, Any]:
    """Metrics of ``model`` on ``data`` (see the module docstring); a JSON-able dict.

    ``horizon``: also report the rollout error up to ``t0 + horizon`` (``error_to_horizon``).

    ```python
    report = mx.evaluate(model, data)
    report["rollout_error_mean"]
    ```
    """
    scheme = CrankNicolson() if scheme is None else scheme
    out, xs, lengths = rollout_data(model, data, scheme=scheme)
    pred = np.asarray(out.xs, dtype=np.float64)
    ts = np.asarray(out.ts, dtype=np.float64)
    failed = np.asarray(out.failed_step)
    per_traj, per_traj_h = [], []
    per_var_num = np.zeros(data.n)
    per_var_den = np.zeros(data.n)
    for k, T in enumerate(lengths):
        p, o = pred[k, :T], xs[k, :T]
        if horizon is not None:
            # Only the states up to the horizon count: a rollout that stops later has a
            # finite error up to the horizon (its failure is in `rollout_failures`).
            m = ts[k, :T] <= ts[k, 0] + horizon + 1e-12
            per_traj_h.append(_relative_error(p[m], o[m]))
        if not np.all(np.isfinite(p)):
            per_traj.append(float("inf"))
            continue
        per_traj.append(_relative_error(p, o))
        per_var_num += np.sum((p - o) ** 2, axis=0)
        per_var_den += np.sum(o**2, axis=0)
    completed = any(np.isfinite(e) for e in per_traj)
    E = _potential_along(model, model.energy, np.nan_to_num(pred))
    S = _potential_along(model, model.entropy, np.nan_to_num(pred))
    drifts, drifts_gauge, dS_min, neg_frac = [], [], [], []
    E_data = _potential_along(model, model.energy, xs)
    spread = float(np.ptp(np.concatenate([E_data[k, :T] for k, T in enumerate(lengths)])))
    for k, T in enumerate(lengths):
        if failed[k] >= 0:
            T = int(failed[k])
        e, s = E[k, :T], S[k, :T]
        if T < 2:
            continue
        d = float(np.max(np.abs(e - e[0])))
        drifts.append(d / max(abs(float(e[0])), _TINY))
        drifts_gauge.append(d / max(spread, _TINY))
        ds = np.diff(s)
        dS_min.append(float(ds.min()))
        neg_frac.append(float(np.mean(ds < -1e-12 * max(1.0, float(np.abs(s).max())))))
    report: dict[str, Any] = {
        "trajectories": int(len(lengths)),
        "variables": list(data.names),
        "scheme": scheme.name,
        "rollout_error": per_traj,
        "rollout_error_mean": float(np.mean(per_traj)),
        # Over the completed rollouts only; null (never 0.0) when every rollout failed.
        "rollout_error_per_variable": {
            name: float(np.sqrt(a / max(b, _TINY))) if completed else None
            for name, a, b in zip(data.names, per_var_num, per_var_den)
        },
        "rollout_failures": int(np.sum(failed >= 0)),
        "rollout_error_mean_completed": (
            float(np.mean([e for e in per_traj if np.isfinite(e)])) if completed else None),
        "energy_relative_drift": float(np.max(drifts)) if drifts else 0.0,
        "energy_drift_over_data_spread": float(np.max(drifts_gauge)) if drifts_gauge else 0.0,
        "entropy_min_step": float(np.min(dS_min)) if dS_min else 0.0,
        "entropy_negative_step_fraction": float(np.mean(neg_frac)) if neg_frac else 0.0,
    }
    if horizon is not None:
        report["horizon"] = float(horizon)
        report["rollout_error_to_horizon"] = per_traj_h
        report["rollout_error_to_horizon_mean"] = float(np.mean(per_traj_h))
    report.update(structure_residuals(model, data.x))
    return report


def _relative_error(pred: np.ndarray, obs: np.ndarray) -> float:
    """``|pred - obs| / |obs|`` over a whole trajectory; inf if any predicted state is missing."""
    if not np.all(np.isfinite(pred)):
        return float("inf")
    return float(np.linalg.norm(pred - obs) / max(np.linalg.norm(obs), _TINY))


def error_over_time(pred: np.ndarray, obs: np.ndarray) -> np.ndarray:
    """Relative error ``|pred(t) - obs(t)| / rms|obs|`` at each time (one trajectory)."""
    scale = max(float(np.sqrt(np.mean(np.sum(obs**2, axis=-1)))), _TINY)
    return np.linalg.norm(pred - obs, axis=-1) / scale


def time_to_error(ts: np.ndarray, pred: np.ndarray, obs: np.ndarray, threshold: float = 0.1):
    """First time at which the relative error exceeds ``threshold`` (``inf`` if never)."""
    err = error_over_time(pred, obs)
    above = np.flatnonzero(~(err <= threshold))
    return float("inf") if len(above) == 0 else float(ts[above[0]] - ts[0])
