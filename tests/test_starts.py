"""``--starts``: several initialisations trained briefly, the best one trained on."""

import dataclasses
import json
import logging

import jax
import jax.random as jr
import pytest

from metriplex import MetriplexError
from metriplex._train import History
from metriplex.app import _stages
from metriplex.app.config import RunConfig, validate
from metriplex.app.runs import train_run
from metriplex.systems import generate


@pytest.mark.parametrize("changes,starts", [
    (dict(), _stages.STARTS),  # L learned
    (dict(poisson="lie-poisson"), _stages.STARTS),
    (dict(poisson="canonical:1", entropy="sum:2"), 1),  # L given: no gauge to fall into
    (dict(poisson="zero"), 1),
    (dict(starts=5, poisson="canonical:1"), 5),  # asked for
    (dict(starts=1), 1),
])
def test_starts_are_tried_where_L_is_learned(changes, starts):
    assert _stages.starts_for(dataclasses.replace(RunConfig(), **changes)) == starts


@pytest.mark.parametrize("value", [0, -2, 1.5])
def test_a_start_count_below_one_is_refused(value):
    with pytest.raises(MetriplexError, match="--starts"):
        validate(RunConfig(starts=value), 3)


def test_best_start_goes_on_from_the_start_of_lowest_validation_loss(monkeypatch, capsys):
    built, calls = [], []

    def build(key):
        built.append(len(built))
        return f"start {built[-1]}"

    def fake_fit(scores):
        def fit(start, train, **kwargs):
            calls.append(kwargs)
            i = int(start.split()[1])
            return f"fitted {i}", History(best_valid=scores[i], stopped="step budget reached")
        return fit

    monkeypatch.setattr(_stages, "fit", fake_fit([float("nan"), 0.01, 0.3, 0.2]))
    best = _stages.best_start(build, jr.key(0), starts=4, train=None, valid=None,
                              fit_args=dict(steps=50_000, loss="L"), label="starts")
    # The chosen initialisation is returned untrained (a NaN score is never the best), so
    # the stage trains it from its start.
    assert best == "start 1"
    assert len(built) == 4 and len(calls) == 4
    # Each start trains exactly START_STEPS steps, judged by its validation loss alone.
    for kw in calls:
        assert kw["steps"] == _stages.START_STEPS and kw["stopping"] is None
        assert kw["rollout_check"] is None and kw["loss"] == "L"
    assert "starts: initialisation 2 of 4, trained from its start" in capsys.readouterr().err
    # Where the first is best, the stage gets exactly the model one start gives.
    built.clear()
    calls.clear()
    monkeypatch.setattr(_stages, "fit", fake_fit([0.1, 0.2]))
    assert _stages.best_start(build, jr.key(0), starts=2, train=None, valid=None,
                              fit_args=dict(steps=3000), label="starts") == "start 0"
    # A short stage gives each start a tenth of its steps.
    assert [kw["steps"] for kw in calls] == [300, 300]
    assert "initialisation 1 of 2" in capsys.readouterr().err
    # One start: the first initialisation, and no training and no line.
    built.clear()
    calls.clear()
    assert _stages.best_start(build, jr.key(0), starts=1, train=None, valid=None,
                              fit_args={}, label="starts") == "start 0"
    assert not calls and not capsys.readouterr().err


def test_train_tries_the_starts_and_records_their_number(tmp_path, capsys, caplog):
    data = generate("rigid-body", trajectories=4, steps=30, seed=0)
    config = RunConfig(entropy="zero", friction="zero", steps=200, eval_every=50,
                       average_steps=0, validation=0.25, starts=2)
    jax.clear_caches()  # count this run's compilations, whatever ran before in this process
    with jax.log_compiles(), caplog.at_level(logging.WARNING, logger="jax"):
        train_run(data, config, tmp_path / "run", progress=False)
    # Each start trains a tenth of --steps at most (20 here, 1000 by default).
    err = capsys.readouterr().err
    assert "starts: initialisation" in err and "after 20 steps each" in err
    header = json.loads((tmp_path / "run" / "config.json").read_text())
    assert header["decided"]["starts"] == 2
    # The starts' trials (20 steps each, on their cosine schedule) share one compiled chunk,
    # and the training of the chosen start (chunks of 50) another: the chunk's length is
    # traced and the optimisers are memoised. The pair losses compile once per subset shape.
    compiled = [r.getMessage().split(" with ")[0] for r in caplog.records
                if r.getMessage().startswith("Compiling jit(")]
    assert compiled.count("Compiling jit(_chunk)") == 2, compiled
    assert compiled.count("Compiling jit(_evaluate)") == 2, compiled


def test_the_starts_share_the_stage_wall_time_cap(monkeypatch):
    # --max-minutes caps the stages together: each start gets what the ones before it left
    # (at least a second), and none is capped without a cap. The clock advances 10 s a read.
    import itertools

    clock = itertools.count(0.0, 10.0)
    monkeypatch.setattr(_stages.time, "perf_counter", lambda: next(clock))
    caps = []

    def fit(start, train, **kwargs):
        caps.append(kwargs["max_seconds"])
        return start, History(best_valid=1.0, stopped="step budget reached")

    monkeypatch.setattr(_stages, "fit", fit)
    _stages.best_start(lambda k: "start", jr.key(0), starts=3, train=None, valid=None,
                       fit_args=dict(max_seconds=25.0), label="starts")
    assert caps == [15.0, 5.0, 1.0]
    caps.clear()
    _stages.best_start(lambda k: "start", jr.key(0), starts=2, train=None, valid=None,
                       fit_args={}, label="starts")
    assert caps == [None, None]
