"""The reference experiments (``metriplex reproduce NAME --quick``) learn something real.

Each quick run must beat the untrained model of the same configuration by a wide margin in
rollout error on unseen test initial conditions, and write its metrics and figures (PNG, PDF and
the raw NPZ). Three run by default (about 30 s, 60 s and 110 s on a busy 2-core CPU); the
temperature pendulum (learned L, M, E and S with a stochastic Jacobi penalty, about 160 s)
carries the ``slow`` marker.
"""

import json
import math

import pytest

from metriplex.experiments import EXPERIMENTS, run_experiment

# The requirement for --quick: at least 5x below the untrained model's test error
# (measured margins in docs/experiments.md).
MARGIN = 5.0

FIGURES = ("trajectories", "error", "energy_fit", "energy_entropy", "loss")


@pytest.mark.parametrize(
    "name",
    [
        "pendulum-energetic",
        "gas-containers",
        "rigid-body",
        pytest.param("pendulum-temperature", marks=pytest.mark.slow),
    ],
)
def test_quick_experiment_learns(name, tmp_path):
    out = tmp_path / name
    metrics = run_experiment(name, quick=True, out=out, progress=False)
    key = "rollout_error_to_horizon_mean" if EXPERIMENTS[name].horizon else "rollout_error_mean"
    learned, untrained = metrics[key], metrics["untrained_rollout_error"]
    assert math.isfinite(learned)
    assert learned * MARGIN < untrained, (learned, untrained)
    assert metrics["rollout_failures"] == 0
    saved = json.loads((out / "metrics.json").read_text())
    assert saved[key] == pytest.approx(learned)
    assert set(saved["bars"]) == set(EXPERIMENTS[name].bars)
    for k in ("ground_truth_cn", "energy_gauge_fit", "energy_relative_drift_gauge_fixed",
              "true_energy_relative_drift", "train_seconds"):
        assert k in saved, k
    assert (out / "model.mpx").exists() and (out / "history.json").exists()
    figures = out / "figures"
    for stem in FIGURES + (("positions",) if name.startswith("pendulum") else ()):
        for ext in ("png", "pdf", "npz"):
            assert (figures / f"{stem}.{ext}").exists(), f"{stem}.{ext}"
