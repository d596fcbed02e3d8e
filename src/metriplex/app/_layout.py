"""Laying a figure out once before it is saved in several formats (#16)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import matplotlib

if TYPE_CHECKING:
    from matplotlib.figure import Figure


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
