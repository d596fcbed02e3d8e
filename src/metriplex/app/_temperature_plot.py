r"""The learned temperatures figure of the report: :math:`T_i = \partial E/\partial s_i` against
:math:`s_i` at the data's states, where S is a sum of entropy variables, with what the data
determine of them in its title (:func:`metriplex.diagnostics.identified`)."""

from __future__ import annotations

import textwrap
from typing import TYPE_CHECKING, Sequence

import matplotlib.pyplot as plt
import numpy as np

if TYPE_CHECKING:
    from matplotlib.figure import Figure

#: The title's line for each gauge of the temperatures (``identified``'s ``temperatures``).
GAUGE = {
    "determined": "no gauge freedom where heat flows (L and S given): determined by the "
                  "data, but only as well as the model fits them{fit}, and noise on the data "
                  "limits them too (no error bar drawn)",
    "factor": "up to E's factor: L is learned, and (L/a, aE) give the same flow; where the "
              "motion conserves another quantity C (a Casimir), (L/F_E, F(E, C)) too, and the "
              "factor then varies with the state",
    "ratios": "only their ratios are determined: with L = 0 their common scale and sign are "
              "not (-E gives the same flow)",
}


def temperatures(s: np.ndarray, T: np.ndarray, names: Sequence[str], *,
                 gauge: str | None = None, true: np.ndarray | None = None,
                 fit: str = "") -> Figure:
    """One panel per entropy variable: the learned temperature ``T[:, i]`` against ``s[:, i]``
    at the same states (shape ``(states, k)`` both), a dotted line at zero; ``gauge``: a key of
    :data:`GAUGE`, said in the title; ``true``: the true temperatures at the same states in the
    learned energy's gauge (a known model's, scaled by the energy fit's slope), drawn beside;
    ``fit``: how well the model fits these data (:func:`fit_clause`), said where the gauge is
    ``determined`` (a new-user check's temperatures were 0.56-1.0 of the truth beside rollouts
    that erred by 8 %, under a title that called them as accurate as the fit)."""
    k = T.shape[1]
    cols = min(k, 4)
    rows = -(-k // cols)
    width = max(3.6 * cols, 5.0)  # wide enough for the title's first line
    fig, axes = plt.subplots(rows, cols, figsize=(width, 3.0 * rows + 0.6),
                             constrained_layout=True, squeeze=False)
    for i, ax in enumerate(axes.flat):
        if i >= k:
            ax.set_visible(False)
            continue
        finite = np.isfinite(s[:, i]) & np.isfinite(T[:, i])
        ax.scatter(s[finite, i], T[finite, i], s=5, color="C3", alpha=0.6, label="learned")
        if true is not None:
            ax.scatter(s[finite, i], true[finite, i], s=5, color="0.2", marker="x", lw=0.6,
                       alpha=0.6, label="true × E fit's slope")
            ax.legend(fontsize=7, loc="best")
        ax.axhline(0.0, color="0.5", lw=0.8, ls=":")
        ax.set_xlabel(names[i])
        ax.set_ylabel(f"learned dE/d{names[i]}")
    fig.suptitle("learned temperatures dE/ds_i at the data's states"
                 # about 12 characters of 10-point text per inch
                 + ("\n" + textwrap.fill(GAUGE[gauge].format(fit=fit), int(12 * width))
                    if gauge in GAUGE else ""),
                 fontsize=10)
    return fig


def fit_clause(errors: np.ndarray, failed_step: np.ndarray) -> str:
    """How well the rollouts fit the data, for the temperatures' title: ``errors`` the
    standardised error of each trajectory (rows) over time, NaN past its end, and
    ``failed_step`` where each failed (-1: it did not), as the report's error figure has them.
    The root mean square over the times of the ones that finished, averaged over them, is
    evaluate's ``rollout_error_standardised``."""
    done = np.asarray(failed_step) < 0
    with np.errstate(invalid="ignore"):
        rms = np.sqrt(np.nanmean(np.asarray(errors)[done] ** 2, axis=1))
    if not done.any():
        return " (no rollout of these data finished)"
    failed = int(np.sum(~done))
    return (f" (its rollouts of these data err by {np.mean(rms):.2g} of "
            "their spread, standardised" + (f"; {failed} of {len(done)} failed)" if failed
                                            else ")"))
