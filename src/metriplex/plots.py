"""Figures. Every function takes ``ax=None`` (or a figure size), returns the figure and never
calls ``plt.show()``. :func:`save_figure` writes PNG and PDF with the raw numbers beside them
(NPZ), so users can restyle any figure.
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import matplotlib

matplotlib.use("Agg", force=False)
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402


def save_figure(fig, stem: str | Path, **raw) -> list[Path]:
    """Write ``stem.png``, ``stem.pdf`` and the raw data ``stem.npz``; return the paths."""
    from .io import atomic_write

    stem = Path(stem)
    stem.parent.mkdir(parents=True, exist_ok=True)
    paths = []
    for ext in ("png", "pdf"):
        p = stem.with_suffix(f".{ext}")
        with atomic_write(p, "wb") as f:
            fig.savefig(f, format=ext, dpi=150, bbox_inches="tight")
        paths.append(p)
    if raw:
        import io as _io

        buf = _io.BytesIO()
        np.savez(buf, **{k: np.asarray(v) for k, v in raw.items()})
        p = stem.with_suffix(".npz")
        with atomic_write(p, "wb") as f:
            f.write(buf.getvalue())
        paths.append(p)
    plt.close(fig)
    return paths


def _axes(ax, figsize=(6, 4)):
    if ax is None:
        fig, ax = plt.subplots(figsize=figsize, constrained_layout=True)
    return ax.figure, ax


def loss_curves(history, ax=None):
    """Training and validation loss terms against the optimiser step (log scale)."""
    fig, ax = _axes(ax)
    steps = np.asarray(history.step)
    for name, vals in history.train.items():
        ax.semilogy(steps, np.maximum(vals, 1e-300), label=f"train {name}",
                    lw=2 if name == "total" else 1)
    for name, vals in history.valid.items():
        if name == "total":
            ax.semilogy(steps, np.maximum(vals, 1e-300), "k--", label="validation total", lw=2)
    if history.best_step:
        ax.axvline(history.best_step, color="0.6", ls=":", label="best model")
    ax.set_xlabel("optimiser step")
    ax.set_ylabel("loss (standardised units)")
    ax.legend(fontsize=7, ncol=2)
    ax.set_title("loss curves")
    return fig


def trajectories(ts, pred, obs, names: Sequence[str], *, truth_label="observed",
                 model_label="learned", max_vars: int = 12):
    """Each state variable against time: the model's rollout over the observed trajectory."""
    n = min(pred.shape[-1], max_vars)
    cols = 2 if n > 3 else 1
    rows = int(np.ceil(n / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(5 * cols, 1.8 * rows + 0.6), squeeze=False,
                             sharex=True, constrained_layout=True)
    for i in range(n):
        ax = axes.flat[i]
        ax.plot(ts, obs[:, i], color="0.2", lw=1.6, label=truth_label)
        ax.plot(ts, pred[:, i], color="C3", lw=1.1, ls="--", label=model_label)
        ax.set_ylabel(names[i])
    for ax in axes.flat[n:]:
        ax.axis("off")
    axes.flat[0].legend(fontsize=8)
    for ax in axes[-1]:
        ax.set_xlabel("t")
    return fig


def positions(pred, obs, ax=None, *, upto: int | None = None, horizon_label: str = ""):
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


def energy_entropy(ts, E, S, *, E_true=None, S_true=None):
    """Energy and entropy along a rollout (learned potentials; true ones if known)."""
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 3.5), constrained_layout=True)
    a1.plot(ts, E, color="C3", label="learned E")
    a2.plot(ts, S, color="C0", label="learned S")
    if E_true is not None:
        a1.plot(ts, E_true, color="0.3", ls="--", label="true E along the true trajectory (affine fit)")
    if S_true is not None:
        a2.plot(ts, S_true, color="0.3", ls="--", label="true S along the true trajectory (affine fit)")
    a1.set_xlabel("t")
    a2.set_xlabel("t")
    a1.set_title("energy along the learned rollout")
    a2.set_title("entropy along the learned rollout")
    a1.legend(fontsize=8)
    a2.legend(fontsize=8)
    return fig


def error_over_time(ts, err, *, reference=None, per_variable=None, ax=None):
    """Relative rollout error against time (log scale), with a reference scheme's if given and
    each variable's error (divided by its data scale) as thin lines."""
    fig, ax = _axes(ax)
    for name, e in (per_variable or {}).items():
        ax.semilogy(ts, np.maximum(e, 1e-300), lw=0.7, alpha=0.7, label=name)
    ax.semilogy(ts, np.maximum(err, 1e-300), color="C3", lw=2, label="learned model")
    if reference is not None:
        ax.semilogy(ts, np.maximum(reference, 1e-300), color="0.4", ls="--",
                    label="ground truth, same scheme and dt")
    ax.set_xlabel("t")
    ax.set_ylabel("relative error")
    ax.legend(fontsize=8)
    ax.set_title("rollout error over time")
    return fig


def gauge_fit(true_vals, learned_vals, *, label: str, ax=None):
    """Learned potential against the true one after the best affine fit (a scatter)."""
    fig, ax = _axes(ax, (4.5, 4.5))
    a, b = np.polyfit(true_vals, learned_vals, 1)
    ax.plot(true_vals, learned_vals, ".", ms=2, color="C0", alpha=0.5)
    lo, hi = float(np.min(true_vals)), float(np.max(true_vals))
    ax.plot([lo, hi], [a * lo + b, a * hi + b], "k--", lw=1, label=f"fit {a:.3g}·{label}+{b:.3g}")
    ax.set_xlabel(f"true {label}")
    ax.set_ylabel(f"learned {label}")
    ax.legend(fontsize=8)
    ax.set_title(f"learned vs true {label}")
    return fig


def residual_over_time(ts, residual, names: Sequence[str], ax=None):
    """The scheme residual of each observed pair against time, per variable (log scale)."""
    fig, ax = _axes(ax)
    for i, name in enumerate(names[: residual.shape[1]]):
        ax.semilogy(ts, np.maximum(np.abs(residual[:, i]), 1e-300), lw=1, label=name)
    ax.set_xlabel("t")
    ax.set_ylabel("|residual| / data scale")
    ax.legend(fontsize=7, ncol=2)
    ax.set_title("one-step residual on the observed pairs")
    return fig
