"""States alone as one NumPy array (``.npy``), the way many datasets come: trajectories ×
snapshots × variables ``(K, T, n)``, or snapshots × variables ``(T, n)`` for one trajectory,
evenly spaced; the step is given by ``dt`` (the command line's ``--dt``), since the file holds
no times. Read only: written trajectories need their times (``.npz``, ``.csv``, ...).
Nothing is unpickled.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .._errors import MetriplexError
from ..data import Trajectories, uniform_times
from ._checks import stacked_table


def read_npy(path: Path, *, dt: float | None = None) -> Trajectories:
    """Trajectories from a ``(K, T, n)`` or ``(T, n)`` array of states, sampled every ``dt``."""
    where = f"NPY file {str(path)!r}"
    try:
        a = np.load(path, allow_pickle=False)
    except Exception as e:  # format errors differ by numpy version
        raise MetriplexError(
            f"{str(path)!r} is not a readable NPY array ({type(e).__name__}: {e}); it may be "
            "truncated, or hold Python objects, which are not read. Save it with numpy.save."
        ) from None
    if a.ndim not in (2, 3) or a.dtype.kind not in "fiu":
        raise MetriplexError(
            f"{where} holds a {a.ndim}-D array of {a.dtype} {a.shape}; a .npy data file is "
            "trajectories x snapshots x variables (K, T, n) or snapshots x variables (T, n), of "
            "numbers. Other layouts: the long table as .npz (trajectory, t, x)."
        )
    if dt is None:
        raise MetriplexError(
            f"{where} holds states only ({'x'.join(map(str, a.shape))}), no times: pass --dt "
            "STEP (read(path, dt=STEP) in Python), the time between snapshots; or store the "
            "times with the states as .npz (trajectory, t, x)."
        )
    table = stacked_table({"x": a}, where, dt)
    return Trajectories(table["trajectory"], uniform_times(table["trajectory"], dt), table["x"])
