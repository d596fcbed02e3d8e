"""Figures. Every function takes ``ax=None`` (or a figure size), returns the figure and never
calls ``plt.show()``. :func:`save_figure` writes PNG and PDF with the raw numbers beside them
(NPZ), so users can restyle any figure.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Sequence

import matplotlib

matplotlib.use("Agg", force=False)
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ._layout import SAVE_DPI as SAVE_DPI, save_figure as save_figure  # noqa: E402
from ._layout import legend as _legend  # noqa: E402
from ._layout import time_limits as _time_limits  # noqa: E402
from ._energy_plot import LEAST_SPAN as LEAST_SPAN  # noqa: E402
from ._energy_plot import energy_entropy as energy_entropy  # noqa: E402

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure
    from numpy.typing import ArrayLike

    from .._train import History


def _axes(ax, figsize=(6, 4)):
    if ax is None:
        fig, ax = plt.subplots(figsize=figsize, constrained_layout=True)
    return ax.figure, ax


#: Relative errors above this are drawn at it: beyond, a rollout has left the data altogether,
#: and a blow-up (1e13 before the step that fails) would squash every other line.
ERROR_CEILING = 1e3
#: The lowest decade drawn below the largest value (1e-12: float64 rounding of a
#: relative error), so an exact zero or a denormal does not stretch the axis to 1e-315.
LOG_SPAN = 1e-12
#: Variables labelled by name in a legend; the others are drawn thin and grey, as one entry.
MAX_LABELS = 8


def _positive(a, ceiling=None):
    """``a`` as float64 with non-finite and non-positive values as NaN (not drawn) and values
    above ``ceiling`` drawn at it."""
    a = np.array(a, dtype=np.float64)
    a[~(np.isfinite(a) & (a > 0))] = np.nan
    if ceiling is not None:
        a = np.minimum(a, ceiling)
    return a


def _log_limits(ax, *arrays, empty: str = "") -> None:
    """Fit a log axis to the finite positive values of ``arrays`` (errors from the second state:
    the first is rounding), at most ``LOG_SPAN`` below the largest; if none, say ``empty``."""
    vals = [np.ravel(a)[np.isfinite(np.ravel(a))] for a in arrays if np.size(a)]
    vals = np.concatenate(vals) if vals else np.zeros(0)
    if len(vals) == 0:
        if empty:
            ax.text(0.5, 0.5, empty, transform=ax.transAxes, ha="center", va="center",
                    fontsize=9, color="0.3", wrap=True)
        return
    hi = float(np.max(vals))
    lo = max(float(np.min(vals)), hi * LOG_SPAN)
    if lo == hi:
        lo, hi = lo / 10, hi * 10
    ax.set_ylim(lo / 2, hi * 2)


def _top_k(values: dict, k: int) -> list:
    """The names of the ``k`` largest series by their largest finite value."""
    def size(v):
        v = np.asarray(v, dtype=np.float64)
        v = v[np.isfinite(v)]
        return float(np.max(v)) if len(v) else -np.inf
    return sorted(values, key=lambda n: size(values[n]), reverse=True)[:k]


def _per_variable_lines(ax, ts, per_variable: dict, max_labels: int, ceiling=None):
    """One thin line per variable; the ``max_labels`` largest are named, the rest grey. A
    variable's colour is that of its place among the variables, the same in every figure."""
    named = _top_k(per_variable, max_labels)
    rest = [n for n in per_variable if n not in named]
    for i, name in enumerate(per_variable):
        if name in named:  # C7 is grey, the colour of the unnamed ones: skipped
            ax.semilogy(ts, _positive(per_variable[name], ceiling), lw=0.8, alpha=0.8,
                        color=f"C{(0, 1, 2, 3, 4, 5, 6, 8, 9)[i % 9]}", label=name)
    for j, name in enumerate(rest):
        ax.semilogy(ts, _positive(per_variable[name], ceiling), lw=0.5, color="0.7",
                    label=f"other {len(rest)} variables" if j == 0 else None, zorder=0)
    return len(named) + (1 if rest else 0)


def loss_curves(history: History, ax: Axes | None = None) -> Figure:
    """Training and validation loss terms against the optimiser step (log scale); a term at
    exactly zero (an untouched hinge) is not drawn there, so it cannot stretch the axis."""
    fig, ax = _axes(ax)
    steps = np.asarray(history.step)
    for name, vals in history.train.items():  # the total wide and pale, under its terms
        ax.semilogy(steps, _positive(vals), label=f"train {name}", **(
            {"lw": 4, "alpha": 0.35, "zorder": 1} if name == "total" else {"lw": 1, "zorder": 2}))
    for vals in [history.valid["total"]] if "total" in history.valid else []:
        ax.semilogy(steps, _positive(vals), "k--", label="validation total", lw=2)
    _log_limits(ax, *[line.get_ydata() for line in ax.get_lines()])
    if history.best_step:
        ax.axvline(history.best_step, color="0.6", ls=":", label="best model")
    ax.set_xlabel("optimiser step")
    ax.set_ylabel("loss (standardised units)")
    ax.legend(fontsize=7, ncol=2)
    ax.set_title("loss curves")
    return fig


def trajectories(ts: np.ndarray, pred: np.ndarray, obs: np.ndarray, names: Sequence[str], *,
                 truth_label: str = "observed", model_label: str = "learned", max_vars: int = 12,
                 failed_at: float | None = None) -> Figure:
    """Each state variable against time: the model's rollout over the observed trajectory.

    Up to ``max_vars`` variables (the title says how many are shown); ``failed_at``: the time
    at which the rollout failed, marked on every panel (the rollout stops there)."""
    total = pred.shape[-1]
    n = min(total, max_vars)
    cols = 2 if n > 3 else 1
    rows = int(np.ceil(n / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(5 * cols, 1.8 * rows + 0.9), squeeze=False,
                             sharex=True, constrained_layout=True)
    pred = np.where(np.isfinite(pred), pred, np.nan)
    for i in range(n):
        ax = axes.flat[i]
        ax.plot(ts, obs[:, i], color="0.2", lw=1.6, label=truth_label)
        ax.plot(ts, pred[:, i], color="C3", lw=1.1, ls="--", label=model_label)
        if failed_at is not None:
            ax.axvline(failed_at, color="C3", lw=0.8, ls=":",
                       label="rollout failed" if i == 0 else None)
        ax.set_ylabel(names[i])
    for ax in axes.flat[n:]:
        ax.axis("off")
    axes.flat[0].legend(fontsize=8)
    for ax in axes[-1]:
        ax.set_xlabel("t")
    _time_limits(axes.flat[0], ts)
    title = [f"first {n} of {total} variables"] if n < total else []
    if failed_at is not None:
        title.append(f"the rollout failed at t = {failed_at:.4g}")
    if title:
        fig.suptitle("; ".join(title), fontsize=9)
    return fig


def positions(pred: np.ndarray, obs: np.ndarray, ax: Axes | None = None, *,
              upto: int | None = None, horizon_label: str = "") -> Figure:
    """Pendulum: paths of the two masses in the plane, learned against true.

    With ``upto``, the states ``[:upto]`` (e.g. up to the reported horizon) are drawn in full
    and the rest faintly, so the figure shows the part that the error bar is about.
    """
    fig, ax = _axes(ax, (5, 5))
    cut = len(obs) if upto is None else int(upto)
    for k, (i, c) in enumerate(((0, "C0"), (2, "C1"))):
        ax.plot(obs[:cut, i], obs[:cut, i + 1], color=c, lw=1.8, label=f"mass {k + 1} true")
        ax.plot(pred[:cut, i], pred[:cut, i + 1], color="k", lw=0.9, ls="--",
                label=f"mass {k + 1} learned")
        if cut < len(obs):
            ax.plot(obs[cut - 1:, i], obs[cut - 1:, i + 1], color=c, lw=1.0, alpha=0.25)
            ax.plot(pred[cut - 1:, i], pred[cut - 1:, i + 1], color="k", lw=0.6, ls="--",
                    alpha=0.25)
    ax.plot([0], [0], "ko", ms=4)
    ax.set_aspect("equal")
    ax.set_xlabel("x")
    ax.set_ylabel("y")
    ax.legend(fontsize=8)
    ax.set_title("positions of the two masses"
                 + (f"\n({horizon_label}; fainter: later)" if cut < len(obs) else ""))
    return fig


def error_over_time(ts: np.ndarray, err: np.ndarray, *, reference: np.ndarray | None = None,
                    per_variable: dict[str, np.ndarray] | None = None,
                    failed_at: float | None = None, ax: Axes | None = None,
                    max_labels: int = MAX_LABELS) -> Figure:
    """Relative rollout error against time (log scale), with a reference scheme's if given and
    each variable's error (divided by its data scale) as thin lines.

    Only finite positive values are drawn, errors above :data:`ERROR_CEILING` at it, and the
    axis spans at most :data:`LOG_SPAN` below the largest value. ``failed_at``: the time at
    which the rollout failed, marked with an ``x``. With many variables only the
    ``max_labels`` largest are named, and the legend goes outside the axes."""
    fig, ax = _axes(ax, (7.5, 4) if per_variable and len(per_variable) > max_labels else (6, 4))
    entries = 0
    if per_variable:
        entries += _per_variable_lines(ax, ts, per_variable, max_labels, ERROR_CEILING)
    e = _positive(err, ERROR_CEILING)
    ax.semilogy(ts, e, color="C3", lw=2, label="learned model")
    entries += 1
    drawn = [e] + [_positive(v, ERROR_CEILING) for v in (per_variable or {}).values()]
    if reference is not None:
        r = _positive(reference, ERROR_CEILING)
        ax.semilogy(ts, r, color="0.4", ls="--", label="ground truth, same scheme and dt")
        drawn.append(r)
        entries += 1
    _log_limits(ax, *(d[1:] for d in drawn), empty="no finite positive error to draw")
    _time_limits(ax, ts)
    title = "rollout error over time"
    if failed_at is not None:
        ok = e[np.isfinite(e)]
        ax.plot([failed_at], [ok[-1] if len(ok) else ERROR_CEILING], "x", color="C3", ms=9,
                mew=2, label="rollout failed")
        entries += 1
        title += f"\n(the rollout failed at t = {failed_at:.4g})"
    ax.set_xlabel("t")
    ax.set_ylabel("relative error")
    _legend(ax, entries > MAX_LABELS // 2 + 1)
    ax.set_title(title)
    return fig


def rollout_errors(ts: ArrayLike, errors: ArrayLike, *, failed_step: ArrayLike | None = None,
                   per_variable: dict[str, np.ndarray] | None = None,
                   trajectory: int | None = None, ids: Sequence[int] | None = None,
                   reference: ArrayLike | None = None, reference_label: str = "ground truth",
                   max_labels: int = MAX_LABELS,
                   ylabel: str = "relative error |x - x_data| / rms |x_data|") -> Figure:
    """Rollout errors of every trajectory, and per variable of one, against time (log scale).

    ``ts``, ``errors``: ``(K, T)`` arrays (padded; NaN where a rollout stopped or a trajectory
    ended); ``failed_step``: ``(K,)``, the step at which each rollout failed, or -1. Left: each
    trajectory's error (relative, or as ``ylabel`` says), a failed one marked with an ``x`` at
    its last state before the failure, and the title says how many failed; ``reference``: a
    ``(T,)`` error to compare trajectory ``trajectory``'s with (e.g. the true model's under the
    same scheme), dashed and named ``reference_label``. Right (with ``per_variable``, a dict of
    ``(T,)`` errors of trajectory ``trajectory``): each variable's error, the ``max_labels``
    largest named in a legend outside the axes. Only finite positive values are drawn, errors
    above :data:`ERROR_CEILING` at it."""
    ts = np.asarray(ts, dtype=np.float64)
    errors = np.asarray(errors, dtype=np.float64)
    K = errors.shape[0]
    failed = np.full(K, -1) if failed_step is None else np.asarray(failed_step)
    n_failed = int(np.sum(failed >= 0))
    wide = per_variable is not None
    fig, axes = plt.subplots(1, 2 if wide else 1, figsize=(12, 4.2) if wide else (6, 4),
                             constrained_layout=True, squeeze=False)
    ax = axes[0, 0]
    drawn = []
    for k in range(K):
        e = _positive(errors[k], ERROR_CEILING)
        drawn.append(e)
        color = "C3" if failed[k] >= 0 else "C0"
        ax.semilogy(ts[k], e, lw=1.4 if k == trajectory else 0.7,
                    alpha=1.0 if k == trajectory else 0.6, color=color,
                    label=f"trajectory {k if ids is None else ids[k]}"
                    + (", per variable at right" if wide else "") if k == trajectory else None)
        if failed[k] >= 0:
            last = np.flatnonzero(np.isfinite(e[: max(int(failed[k]), 1)]))
            y = e[last[-1]] if len(last) else ERROR_CEILING
            x = ts[k, min(int(failed[k]), ts.shape[1] - 1)]
            ax.plot([x], [y], "x", color="C3", ms=8, mew=2,
                    label="rollout failed here" if n_failed and k == int(np.argmax(failed >= 0))
                    else None)
    if reference is not None:
        k = trajectory if trajectory is not None else 0
        r = _positive(np.asarray(reference, dtype=np.float64), ERROR_CEILING)
        ax.semilogy(ts[k, :len(r)], r, color="0.2", ls="--", lw=1.2,
                    label=f"{reference_label}, trajectory {k if ids is None else ids[k]}")
        drawn.append(r)
    if n_failed < K:
        ax.plot([], [], color="C0", lw=0.7, label="completed rollouts")
    if n_failed:
        ax.plot([], [], color="C3", lw=0.7, label="failed rollouts (up to the failure)")
    _log_limits(ax, *(d[1:] for d in drawn), empty="no rollout got past its first state")
    _time_limits(ax, ts)
    ax.set_xlabel("t")
    ax.set_ylabel(ylabel)
    ax.set_title(f"rollout error over time, {K} trajectories"
                 + (f" ({n_failed} of {K} failed)" if n_failed else " (none failed)"))
    _legend(ax, False)
    if wide:
        ax2 = axes[0, 1]
        label = "" if ids is None or trajectory is None else f" {ids[trajectory]}"
        # Trajectory k's own length (the rows of `ts` are padded to the longest).
        length = len(next(iter(per_variable.values()))) if per_variable else ts.shape[1]
        tk = ts[trajectory if trajectory is not None else 0, :length]
        entries = _per_variable_lines(ax2, tk, per_variable, max_labels, ERROR_CEILING)
        _log_limits(ax2, *[_positive(v, ERROR_CEILING)[1:] for v in per_variable.values()],
                    empty="this rollout failed before its second state")
        _time_limits(ax2, tk)
        ax2.set_xlabel("t")
        ax2.set_ylabel("|x_i - x_data,i| / data scale of x_i")
        ax2.set_title(f"per variable, trajectory{label}"
                      + (f" (the {max_labels} largest named)" if len(per_variable) > max_labels
                         else ""))
        _legend(ax2, entries > 4)
    return fig


def gauge_fit(true_vals: ArrayLike, learned_vals: ArrayLike, *, label: str,
              ax: Axes | None = None) -> Figure:
    """Learned potential against the true one after the best affine fit (a scatter)."""
    fig, ax = _axes(ax, (4.5, 4.5))
    a, b = np.polyfit(true_vals, learned_vals, 1)
    ax.plot(true_vals, learned_vals, ".", ms=2, color="C0", alpha=0.5)
    lo, hi = float(np.min(true_vals)), float(np.max(true_vals))
    ax.plot([lo, hi], [a * lo + b, a * hi + b], "k--", lw=1,
            label=f"fit {a:.3g}·{label} {'+' if b >= 0 else '−'} {abs(b):.3g}")
    ax.set(xlabel=f"true {label}", ylabel=f"learned {label}")
    ax.legend(fontsize=8)
    ax.set_title(f"learned vs true {label}")
    return fig


def residual_over_time(ts: np.ndarray, residual: np.ndarray, names: Sequence[str],
                       ax: Axes | None = None, max_labels: int = MAX_LABELS) -> Figure:
    """The scheme residual of each observed pair against time, per variable (log scale); with
    many variables the ``max_labels`` largest are named, in a legend outside the axes."""
    many = len(names) > max_labels
    fig, ax = _axes(ax, (7.5, 4) if many else (6, 4))
    per_variable = {name: np.abs(residual[:, i]) for i, name in enumerate(names[: residual.shape[1]])}
    entries = _per_variable_lines(ax, ts, per_variable, max_labels)
    _log_limits(ax, *[_positive(v) for v in per_variable.values()],
                empty="no finite positive residual to draw")
    _time_limits(ax, ts)
    ax.set_xlabel("t")
    ax.set_ylabel("|residual of x_i| / typical rate of x_i\n(its data scale / the time scale)")
    _legend(ax, entries > 4, ncol=1 if entries > 4 else 2)
    ax.set_title("one-step residual on the observed pairs"
                 + (f" (the {max_labels} largest named)" if many else ""))
    return fig
