"""How much of a model's predicted motion changes when the data's time step is refined
(:func:`step_sensitivity`, reported by :func:`metriplex.evaluate` with ``step_check=True``)."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from ._model import GenericModel, float_dtype
from ._precision import in_full_precision
from ._solve.rollout import RETRY_SUBSTEPS
from .data import Trajectories, state_scale
from .integrate import AbstractScheme, CrankNicolson, Rollout, solve

_TINY = 1e-300


#: Defaults of :func:`step_sensitivity`: the step is refined this many times, over the first
#: ``SENSITIVITY_STEPS`` intervals of at most ``SENSITIVITY_TRAJECTORIES`` trajectories.
SENSITIVITY_REFINE = 4
SENSITIVITY_STEPS = 200
SENSITIVITY_TRAJECTORIES = 10


@in_full_precision
def step_sensitivity(model: GenericModel, data: Trajectories, *,
                     scheme: AbstractScheme | None = None, refine: int = SENSITIVITY_REFINE,
                     steps: int = SENSITIVITY_STEPS,
                     trajectories: int = SENSITIVITY_TRAJECTORIES,
                     rollout: tuple[Rollout, np.ndarray, np.ndarray] | None = None,
                     ) -> tuple[float | None, str]:
    r"""How much of the model's predicted motion changes when the time step is refined.

    From the first state of up to ``trajectories`` trajectories (evenly spread), the model is
    rolled out over the first ``steps`` intervals of the data's own grid, once on that grid and
    once with every interval split into ``refine`` equal steps. Returns
    ``(value, note)``, with

    .. math:: \text{value} = \frac{\|D^{-1}(x^{\Delta t} - x^{\Delta t/r})\|}
              {\|D^{-1}(x^{\Delta t/r} - x_0)\|}

    over all compared states (``D``: the data's standard deviations), or ``None`` and why
    when no trajectory completed both rollouts.

    A model of the system's vector field, integrated by a convergent scheme, gives nearly the
    same motion with either step (second order: a change of about :math:`(1 - 1/r^2)` of the
    scheme's own error). A value near 1 or above says the prediction is a property of the
    scheme at the data's step: the field was learned so that *this* scheme at *this* step
    reproduces the data (a "modified" field, e.g. with stiff modes that the scheme damps or
    flips), or the data's step does not resolve the dynamics. Either way the field is not a
    trustworthy model of :math:`\dot x` between samples.

    ``rollout``: what :func:`metriplex.diagnostics.rollout_data` returned for this model, data
    and scheme; its states on the data's grid are reused, so only the refined rollout is
    computed. The refined rollout runs as ``refine`` rollouts of that shape, one after
    another, so it reuses their compiled program where the data's grid is all compared.
    """
    scheme = CrankNicolson() if scheme is None else scheme
    ts, xs, lengths = data.padded()
    pick = _spread(len(lengths), trajectories)
    w = int(min(steps + 1, np.min(lengths[pick])))
    if w < 2:
        return None, "no trajectory has two states"
    grid = ts[pick, :w]
    frac = np.arange(refine) / refine
    fine = (grid[:, :-1, None] + np.diff(grid, axis=1)[:, :, None] * frac).reshape(len(pick), -1)
    fine = np.concatenate([fine, grid[:, -1:]], axis=1)
    dtype = float_dtype(model)
    x0 = jnp.asarray(xs[pick, 0], dtype)
    if rollout is None:
        out = solve(model, x0, grid, scheme=scheme, retry=RETRY_SUBSTEPS)
        on_grid, failed = np.asarray(out.xs, np.float64), np.asarray(out.failed_step)
    else:
        on_grid = np.asarray(rollout[0].xs, np.float64)[pick, :w]
        failed = np.asarray(rollout[0].failed_step)[pick]
        failed = np.where(failed >= w, -1, failed)
    refined, refined_failed = _refined_rollout(model, scheme, x0, fine, w)
    ok = (failed < 0) & (refined_failed < 0)
    if not ok.any():
        return None, (f"every rollout failed, with the data's step or one {refine}x smaller "
                      f"({len(pick)} trajectories)")
    d = state_scale(data.x)[None, None, :]
    pc = on_grid[ok] / d
    pf = refined[ok][:, ::refine] / d
    start = np.asarray(xs[pick, 0], np.float64)[ok][:, None, :] / d
    num = float(np.sqrt(np.sum((pc - pf) ** 2)))
    den = float(np.sqrt(np.sum((pf - start) ** 2)))
    if not np.isfinite(num) or den <= _TINY:
        return None, "the refined rollouts do not move from their first states"
    return num / den, (f"{int(ok.sum())} trajectories, {w - 1} steps, step refined {refine}x")


def _spread(count: int, most: int) -> np.ndarray:
    """The indices of up to ``most`` of ``count`` trajectories, evenly spread over them."""
    return np.unique(np.linspace(0, count - 1, min(most, count)).astype(int))


def _refined_rollout(model, scheme, x0, fine, w):
    """The rollout on the refined grid ``fine`` (``(B, refine (w - 1) + 1)``), as ``refine``
    rollouts of ``w`` states each, every one from the last state of the one before: the shape
    of the rollout on the data's grid, whose compiled program it reuses (for data of at most
    ``SENSITIVITY_TRAJECTORIES`` trajectories of equal length, at most ``SENSITIVITY_STEPS``
    steps, the evaluation's own). Retried as the evaluation's rollouts are, so a model they
    complete is compared here too. Returns the states (float64, NaN from a failure on) and
    the index of the first failed state per trajectory (-1: none)."""
    x, failed, parts = x0, np.full(x0.shape[0], -1), [np.asarray(x0, np.float64)[:, None]]
    for k in range(0, fine.shape[1] - 1, w - 1):
        # a failed trajectory takes zero steps (a constant grid), as in one rollout
        grid = np.where((failed >= 0)[:, None], fine[:, k:k + 1], fine[:, k:k + w])
        out = solve(model, x, grid, scheme=scheme, retry=RETRY_SUBSTEPS)
        piece = np.asarray(out.failed_step)
        failed = np.where((failed < 0) & (piece >= 0), k + piece, failed)
        parts.append(np.asarray(out.xs, np.float64)[:, 1:])
        # a failed trajectory stays at a finite state; its states are not compared
        x = jnp.where(jnp.asarray(failed < 0)[:, None], out.xs[:, -1], x)
    xs = np.concatenate(parts, axis=1)
    last = np.where(failed < 0, xs.shape[1], failed)
    xs[np.arange(xs.shape[1])[None, :] >= last[:, None]] = np.nan
    return xs, failed


#: Defaults of :func:`initial_state_sensitivity`: the twins start this far apart (in standard
#: deviations of the data), and a separation of ``TWIN_APART`` is where the prediction is no
#: longer that of the given initial state (100-fold growth).
TWIN_OFFSET = 1e-3
TWIN_APART = 0.1


@in_full_precision
def initial_state_sensitivity(model: GenericModel, data: Trajectories, *,
                              scheme: AbstractScheme | None = None,
                              rollout: tuple[Rollout, np.ndarray, np.ndarray] | None = None,
                              trajectories: int = SENSITIVITY_TRAJECTORIES,
                              offset: float = TWIN_OFFSET, apart: float = TWIN_APART,
                              ) -> tuple[dict, dict[str, str]]:
    r"""How fast the model's own rollouts from nearby states separate: the horizon over which
    its predictions are those of their initial state.

    From the first state of up to ``trajectories`` trajectories (evenly spread) and from that
    state moved by ``offset`` standard deviations of the data (one fixed direction), the model
    is rolled out over each whole trajectory; the twins' separation is measured in standard
    deviations. Returns ``(report, null_reasons)``: ``twin_growth``, the median over the
    trajectories of the largest separation over the first; and ``predictability_time``, the
    median time from the first state at which the separation reaches ``apart`` (a
    ``apart / offset``-fold growth; a trajectory whose twins never get there counts as
    never), ``None`` where most never do. Chaotic motion separates twins exponentially, a
    regular one whose period depends on its amplitude linearly; beyond that time any model's
    error, the true one's included, is mostly that growth, so a whole-trajectory error there
    measures the motion's sensitivity as much as the model.

    ``rollout``: what :func:`metriplex.diagnostics.rollout_data` returned for this model, data
    and scheme (the first of each twin; rolled out here when ``None``)."""
    scheme = CrankNicolson() if scheme is None else scheme
    keys = ("twin_growth", "predictability_time")
    ts, xs, lengths = data.padded()
    pick = _spread(len(lengths), trajectories)
    dtype = float_dtype(model)
    if rollout is None:
        base = np.asarray(solve(model, jnp.asarray(xs[pick, 0], dtype), ts[pick], scheme=scheme,
                                retry=RETRY_SUBSTEPS).xs, np.float64)
    else:
        base = np.asarray(rollout[0].xs, np.float64)[pick]
    d = state_scale(data.x)
    u = np.random.default_rng(0).standard_normal(len(d))
    x0 = jnp.asarray(xs[pick, 0], dtype)
    twin0 = jnp.asarray(xs[pick, 0] + offset * d * u / np.linalg.norm(u), dtype)
    twin = np.asarray(solve(model, twin0, ts[pick], scheme=scheme, retry=RETRY_SUBSTEPS).xs,
                      np.float64)
    start = np.linalg.norm((np.asarray(twin0, np.float64) - np.asarray(x0, np.float64)) / d,
                           axis=-1)
    sep = np.linalg.norm((twin - base) / d, axis=-1)  # (trajectories, T); NaN after a failure
    valid = np.arange(ts.shape[1])[None, :] < lengths[pick][:, None]
    ok = (start > 0) & np.all(np.isfinite(sep) | ~valid, axis=1)
    if not ok.any():
        why = "no trajectory completed both twins' rollouts, or the offset is below rounding"
        return dict.fromkeys(keys), dict.fromkeys(keys, why)
    growth = np.where(valid, sep, 0.0)[ok].max(axis=1) / start[ok]
    reached = valid & (sep >= apart)
    when = np.array([ts[k, np.argmax(r)] - ts[k, 0] if r.any() else np.inf
                     for k, r in zip(pick[ok], reached[ok])])
    median = float(np.median(when))
    report = {"twin_growth": float(np.median(growth)),
              "predictability_time": median if np.isfinite(median) else None}
    reasons = {} if np.isfinite(median) else {"predictability_time": (
        f"rollouts from states {offset:g} standard deviations apart stay within {apart:g} of "
        f"each other in most of {int(ok.sum())} trajectories")}
    return report, reasons
