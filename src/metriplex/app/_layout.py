"""Saving a figure: laid out once, then written as PNG and PDF with its raw numbers (NPZ)
(#16); :func:`save_figure` is public as ``metriplex.plots.save_figure``. And the figures'
shared placement of legends and time axes."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import matplotlib
import numpy as np

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure
    from numpy.typing import ArrayLike


def lay_out_once(fig: Figure, dpi: float) -> None:
    """Run ``fig``'s layout engine once, at the resolution ``dpi`` of its raster output, and
    remove the engine, so that each later ``savefig`` draws the figure once.

    With any layout engine set, even the placeholder that ``set_layout_engine("none")`` leaves,
    ``savefig`` first draws the whole figure without output to lay it out and then draws it
    for real: two draws per format, where the layout needs one pass in all. The files are the
    same bytes either way (checked on the report figures, PNG and PDF).
    """
    engine = fig.get_layout_engine()
    if engine is None:
        return
    if fig.axes:  # as Figure.draw does: a figure without axes has nothing to lay out
        old = fig.get_dpi()
        fig.set_dpi(dpi)  # savefig measures the text at the output's dpi
        try:
            engine.execute(fig)
        except ValueError:  # as Figure.draw does (a layout that cannot be satisfied)
            pass
        finally:
            fig.set_dpi(old)
    # None, not "none": print_figure draws once more before saving whenever an engine is set.
    # The rc settings would otherwise turn None back into a default engine.
    with matplotlib.rc_context({"figure.autolayout": False,
                                "figure.constrained_layout.use": False}):
        fig.set_layout_engine(None)


#: The resolution of the PNGs (the PDFs are vector graphics).
SAVE_DPI = 150


def save_figure(fig: Figure, stem: str | Path, **raw: ArrayLike) -> list[Path]:
    """Write ``stem.png``, ``stem.pdf`` and the raw data ``stem.npz``; return the paths."""
    import matplotlib.pyplot as plt  # after metriplex.plots chose the backend

    from ..io import atomic_write

    stem = Path(stem)
    stem.parent.mkdir(parents=True, exist_ok=True)
    paths = []
    lay_out_once(fig, SAVE_DPI)
    for ext in ("png", "pdf"):
        p = stem.with_suffix(f".{ext}")
        with atomic_write(p, "wb") as f:
            # No bbox_inches="tight": the constrained layout already fits every label and
            # outside legend in the canvas, and a tight box would draw each figure once more
            # to measure it (a fifth of the report's time after training, #16).
            fig.savefig(f, format=ext, dpi=SAVE_DPI)
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


def legend(ax: Axes, many: bool, **kw: Any) -> None:
    """A legend inside the axes, or outside to the right when it has many entries, so it
    never covers the lines."""
    if not ax.get_legend_handles_labels()[0]:
        return
    if many:
        ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0,
                  **kw)
    else:
        ax.legend(fontsize=8, **kw)


def time_limits(ax: Axes, ts: ArrayLike) -> None:
    """The whole time grid, even where nothing could be drawn (a rollout that failed at once)."""
    ts = np.asarray(ts, dtype=np.float64)
    ts = ts[np.isfinite(ts)]
    if len(ts) and ts.max() > ts.min():
        ax.set_xlim(ts.min(), ts.max())


def line(ax: Axes, ts: ArrayLike, y: ArrayLike, **kw: Any) -> list:
    """``ax.plot``, with markers when fewer than three points are finite (else they vanish)."""
    few = np.sum(np.isfinite(np.asarray(y, dtype=np.float64))) < 3
    return ax.plot(ts, y, marker="o" if few else None, ms=4, **kw)
