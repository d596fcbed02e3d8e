"""The SciPy-simulated oscillator of benchmarks/issue_table.py (data that metriplex did not
make): its energy is conserved and its entropy grows along the trajectories, as a GENERIC
system's do, and its states follow the equations its docstring states."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))

import issue_table  # noqa: E402


def test_the_scipy_oscillator_conserves_energy_and_makes_entropy():
    data = issue_table._scipy_trajectories(3, seed=0, steps=100)
    assert data.n == 3 and data.names == ("q", "p", "s")
    for t, x in data:
        q, p, s = x.T
        energy = p**2 / 2 + q**2 / 2 + np.expm1(s)  # m = k = c = theta0 = 1
        assert np.ptp(energy) < 1e-8 * np.abs(energy).max()
        assert np.all(np.diff(s) >= 0) and s[-1] > s[0]
        # q' = p by finite differences of the dense output (second order in dt = 0.05)
        dq = np.gradient(q, t)
        assert np.allclose(dq[1:-1], p[1:-1], atol=2e-3)
