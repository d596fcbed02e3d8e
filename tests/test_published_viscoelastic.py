"""The stand-in of benchmarks/published_viscoelastic.py: the equations its docstring states, a
converged time integration, and the dataset's shape (y constant along each trajectory)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))

from published_viscoelastic import NAMES, Couette, split  # noqa: E402

SMALL = dict(nodes=20, snapshots=31, dt=1.0, substeps=80)  # to t = 30, RK4 stable (h = 1/80)


def test_the_flow_settles_to_the_steady_couette_profile():
    # Steady state of the stated equations: v = U y, tau = Wi dv/dy, de/dt = (beta + G Wi)
    # (dv/dy)^2 = 1 with U = 1 and G = (1 - beta) / Wi.
    flow = Couette(**SMALL)
    xs = flow.simulate()
    assert xs.shape == (20, 31, 5) and len(NAMES) == 5
    last = xs[:, -1]
    np.testing.assert_allclose(last[:, 2], flow.y, atol=1e-6)
    np.testing.assert_allclose(last[:, 4], 1.0, atol=1e-6)
    np.testing.assert_allclose(xs[:, -1, 3] - xs[:, -2, 3], 1.0, atol=1e-6)
    # y never moves; x is the integral of v (trapezoid over the last steady second)
    assert np.all(xs[:, :, 1] == flow.y[:, None])
    np.testing.assert_allclose(xs[:, -1, 0] - xs[:, -2, 0], flow.y, atol=1e-6)


def test_the_start_up_overshoots_and_the_integration_is_converged():
    flow = Couette(nodes=30, snapshots=40, dt=0.05, substeps=20)
    xs = flow.simulate()
    finer = Couette(nodes=30, snapshots=40, dt=0.05, substeps=40).simulate()
    assert np.max(np.abs(finer - xs)) < 1e-5  # of states of size 1
    # elastic shear waves: the middle of the gap runs faster than its steady speed for a while
    middle = xs[15]
    assert middle[:, 2].max() > 1.2 * flow.y[15]


def test_the_split_is_eighty_twenty_and_disjoint():
    train, test = split(100, seed=0)
    assert len(train) == 80 and len(test) == 20 and not set(train) & set(test)
    assert sorted(train + test) == list(range(100))
    data = Couette(**SMALL).data()
    assert data.names == NAMES and len(data.select(split(20)[1])) == 4
