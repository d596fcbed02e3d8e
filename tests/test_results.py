"""What metriplex prints and writes about a run never reads better than the run."""

import json
from pathlib import Path

import numpy as np

from metriplex.cli import _train_summary
from metriplex.io import write_json
from metriplex.train import History


def test_json_files_are_strict_and_a_failed_number_is_null(tmp_path):
    path = tmp_path / "m.json"
    write_json(path, {"rollout_error_mean": float("inf"), "per": [1.0, float("nan")],
                      "arr": np.array([np.inf, 2.0]), "rollout_failures": 3})
    text = path.read_text()
    assert "Infinity" not in text and "NaN" not in text
    obj = json.loads(text)
    assert obj == {"rollout_error_mean": None, "per": [1.0, None], "arr": [None, 2.0],
                   "rollout_failures": 3}


def _history(best_step, last, converged, stopped):
    return History(step=[0, last], best_step=best_step, converged=converged, stopped=stopped)


def test_train_summary_counts_failed_rollouts_and_says_when_nothing_was_learned():
    metrics = {"trajectories": 10, "rollout_failures": 4, "rollout_error_mean": float("inf"),
               "rollout_error_mean_completed": 0.05, "evaluated_on": "validation trajectories"}
    line = _train_summary(_history(0, 5000, True, "converged at step 5000"), metrics, 12.0,
                          Path("run"))
    assert "4 of 10 rollouts on validation trajectories FAILED" in line
    assert "error of the 6 completed: 5.000e-02" in line
    assert "NO trained model rolled out the held-out trajectories better than the untrained" in line


def test_train_summary_says_when_the_budget_ended_training_before_convergence():
    metrics = {"trajectories": 4, "rollout_failures": 0, "rollout_error_mean": 0.01,
               "evaluated_on": "validation trajectories"}
    line = _train_summary(_history(3000, 3000, False, "step budget reached (3000 steps)"),
                          metrics, 5.0, Path("run"))
    assert "not converged, allow more --steps" in line
    assert "rollout error on validation trajectories: 1.000e-02" in line
    done = _train_summary(_history(2000, 3000, True, "converged at step 3000"), metrics, 5.0,
                          Path("run"))
    assert "not converged" not in done and "FAILED" not in done and "NO trained" not in done
