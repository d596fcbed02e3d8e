"""`metriplex rollout` keeps the data's trajectory ids and writes each trajectory's status."""

import contextlib
import io
import json

import numpy as np

import metriplex as mx
from metriplex.cli import main


def _run(*args) -> int:
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
        return main([str(a) for a in args])


def test_predictions_keep_the_data_ids_and_a_status_per_trajectory(trained_run, tmp_path):
    # The session's shared run (tests/conftest.py), rolled out on its data under other ids.
    data = mx.read(trained_run / "data.npz")
    run_dir = trained_run / "run"
    # Ids that are not 0..K-1, in the order the file holds them.
    remap = {int(i): j for i, j in zip(data.ids, (7, 0, 5, 12, 3, 9, 21, 14))}
    assert len(remap) == len(data.ids)
    test = mx.Trajectories(np.array([remap[int(i)] for i in data.trajectory]), data.t, data.x,
                           data.names)
    mx.write(tmp_path / "test.csv", test)
    assert _run("rollout", run_dir, tmp_path / "test.csv", "--out", tmp_path / "pred.csv") == 0
    pred = mx.read(tmp_path / "pred.csv")
    assert sorted(pred.ids) == sorted(test.ids)
    for tid in test.ids:  # matched by id: same first state, same time grid
        p, o = pred.select([tid]), test.select([tid])
        np.testing.assert_array_equal(p.t, o.t)
        np.testing.assert_allclose(p.x[0], o.x[0], rtol=1e-6)
    status = json.loads((tmp_path / "pred.csv.status.json").read_text())
    assert {e["trajectory"] for e in status["trajectories"]} == set(int(i) for i in test.ids)
    assert all(e["status"] == "ok" and e["states"] == e["samples"] for e in status["trajectories"])
    # The status file is an output like the predictions: never overwritten without --overwrite.
    assert _run("rollout", run_dir, tmp_path / "test.csv", "--out", tmp_path / "pred.csv") == 2
