"""The figure of the learned energy and entropy along a rollout and along the data
(:func:`energy_entropy`, re-exported by :mod:`metriplex.app.plots`)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import matplotlib.pyplot as plt
import numpy as np

from .._energy_along import ENERGY_ROUNDING_LIMIT
from .._roughness import range_beyond_noise
from ._layout import line as _line, time_limits as _time_limits

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure


#: The least span of the energy and entropy axes, a fraction of each potential's spread over
#: the data (autoscaled, a relative change of 5e-5 filled the panel and read as a violation).
LEAST_SPAN = 1e-2


def energy_entropy(ts: np.ndarray, E: np.ndarray, S: np.ndarray, *,
                   E_true: np.ndarray | None = None, S_true: np.ndarray | None = None,
                   E_data: np.ndarray | None = None, S_data: np.ndarray | None = None,
                   spreads: tuple[float, float] | None = None,
                   failed_at: float | None = None,
                   energy_rounding: float | None = None) -> Figure:
    """Energy and entropy along a rollout (learned potentials; true ones if known) and the
    learned ones along the observed trajectory (``E_data``, ``S_data``: for GENERIC data E
    stays constant there and S does not decrease); the titles say how far each moves against
    ``spreads``, each potential's spread over the data (of which an axis spans at least
    :data:`LEAST_SPAN`). ``failed_at``: where the rollout failed; the potentials stop there.
    ``energy_rounding``: the float rounding of E's values in units of its spread over the data
    (``energy_rounding_over_data_spread``); above :data:`ENERGY_ROUNDING_LIMIT` E is constant
    to rounding, and its title says so instead of how far it moves (a new-user check read
    "moves by 0" beside a warning that it moved by 0.89 of its spread)."""
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 3.9), constrained_layout=True)
    E, S = (np.where(np.isfinite(a), a, np.nan) for a in (E, S))
    _line(a1, ts, E, color="C3", label="learned E along the learned rollout")
    _line(a2, ts, S, color="C0", label="learned S along the learned rollout")
    if E_data is not None:
        a1.plot(ts, E_data, color="C1", ls=":", lw=1.5, label="learned E along the data")
    if S_data is not None:
        a2.plot(ts, S_data, color="C9", ls=":", lw=1.5, label="learned S along the data")
    if E_true is not None:
        a1.plot(ts, E_true, color="0.3", ls="--",
                label="true E along the true trajectory (affine fit)")
    if S_true is not None:
        a2.plot(ts, S_true, color="0.3", ls="--",
                label="true S along the true trajectory (affine fit)")
    suffix = "" if failed_at is None else f"\n(the rollout failed at t = {failed_at:.4g})"
    panels = ((a1, "energy E", E, E_data), (a2, "entropy S", S, S_data))
    for (ax, what, v, on_data), spread in zip(panels, spreads or (None, None)):
        if failed_at is not None:
            ax.axvline(failed_at, color="0.4", lw=0.8, ls=":", label="rollout failed")
        _time_limits(ax, ts)
        rounded = (what.startswith("energy") and energy_rounding is not None
                   and energy_rounding > ENERGY_ROUNDING_LIMIT)
        if rounded:
            spread = None
            mid = float(np.nanmedian(E)) if np.isfinite(E).any() else 0.0
            ax.set_ylim(mid - max(abs(mid), 1.0) / 20, mid + max(abs(mid), 1.0) / 20)
        _least_span(ax, spread)
        ax.ticklabel_format(axis="y", useOffset=False)  # an offset label overlapped the title
        ax.set_xlabel("t")
        ax.set_ylabel(f"learned {what}")
        moved = "".join(f"\non the {w}: moves by {np.nanmax(c) - np.nanmin(c):.3g}, "
                        f"{(np.nanmax(c) - np.nanmin(c)) / spread:.2%} of its spread over the data"
                        + (_drift(c, ts, spread) if w == "data" and what.startswith("energy")
                           else "")
                        for w, c in (("rollout", v), ("data", on_data))
                        if spread and c is not None and np.isfinite(c).any())
        if rounded:
            moved = (f"\nconstant over the data to rounding ({energy_rounding:.2g} of its "
                     "spread there):\nno energy learned, or one whose offset dwarfs its spread")
        ax.set_title(f"{what.split()[0]} along the learned rollout and the data{moved}{suffix}",
                     fontsize=9)
        ax.legend(fontsize=8)
    return fig


def _drift(E: np.ndarray, ts: np.ndarray, spread: float) -> str:
    """The learned energy's drift along the data beyond noise and oscillation, as the metric
    ``energy_change_along_data_over_spread`` measures it on each trajectory (the range of its
    means over stretches): a new-user check read 1.80 % in the title beside 0.36 % there."""
    ok = np.isfinite(E)
    return f" (drift beyond noise: {range_beyond_noise(E[ok], ts[ok]) / spread:.2%})"


def _least_span(ax: Axes, spread: float | None) -> None:
    """Widen the y-axis about its middle to :data:`LEAST_SPAN` of ``spread``, if narrower."""
    lo, hi = ax.get_ylim()
    if spread is not None and np.isfinite(spread) and 0 < spread and hi - lo < LEAST_SPAN * spread:
        mid, half = 0.5 * (lo + hi), 0.5 * LEAST_SPAN * spread
        ax.set_ylim(mid - half, mid + half)
