"""``--repeats``: training again from another initialisation while the held-out rollouts of the
best model so far are poor, and keeping the best."""

import dataclasses
import json
import math
import pathlib
import re

import numpy as np
import pytest

import metriplex as mx
from metriplex import MetriplexError, TrainingDiverged
from metriplex._train import History
from metriplex.app import _repeats, _trainings_note
from metriplex.app.config import RunConfig, preset, validate
from metriplex.app.runs import train_run


def _history(score, *, failures=0, converged=True, stopped="converged at step 100"):
    return History(step=[0, 100], best_step=100, best_rollout=score,
                   best_rollout_failures=failures, converged=converged, stopped=stopped)


def _run(results, tmp_path, repeats=3, budget=None, began=0.0):
    """train_repeats over fake trainings: each entry of ``results`` a History, an exception
    to raise, or a callable of the call count."""
    calls, kept = [], []

    def one(r, resumed):
        calls.append((r, resumed))
        got = results[r]
        if isinstance(got, BaseException):
            raise got
        return f"model {r}", got

    model, history, outcomes, chosen = _repeats.train_repeats(
        one, repeats=repeats, out=tmp_path, resume=False, budget=budget, began=began,
        keep=lambda m, h: kept.append(m))
    return model, history, outcomes, chosen, calls, kept


def test_a_good_first_training_is_not_repeated(tmp_path, capsys):
    model, _, outcomes, chosen, calls, kept = _run([_history(0.01)], tmp_path)
    assert (model, chosen, len(outcomes)) == ("model 0", 0, 1)
    assert calls == [(0, False)] and kept == ["model 0"]
    assert "repeats:" not in capsys.readouterr().err
    # The threshold decides: at it, one training; just above it, another.
    assert len(_run([_history(_repeats.GOOD_SCORE)], tmp_path)[4]) == 1
    above = _history(_repeats.GOOD_SCORE * 1.01)
    assert len(_run([above, _history(0.001)], tmp_path)[4]) == 2


def test_poor_trainings_are_repeated_and_the_best_is_kept(tmp_path, capsys):
    poor = [_history(1.3), _history(0.4), _history(0.9)]
    model, history, outcomes, chosen, calls, kept = _run(poor, tmp_path)
    assert [r for r, _ in calls] == [0, 1, 2]
    assert (model, chosen) == ("model 1", 1) and history is poor[1]
    assert [o.score for o in outcomes] == [1.3, 0.4, 0.9]
    # Each new best is saved before the next training; the last one is the caller's to save.
    assert kept == ["model 0", "model 1"]
    err = capsys.readouterr().err
    assert "err by 1.3 of the data's spread" in err and "training 3 of at most 3" in err


def test_failed_held_out_rollouts_rank_below_any_score(tmp_path):
    runs = [_history(0.2, failures=1), _history(0.9), _history(0.5, failures=2)]
    model, *_ = _run(runs, tmp_path)
    assert model == "model 1"


def test_no_repeat_after_a_training_that_a_step_budget_ended(tmp_path):
    # It wants more steps, not another start.
    unconverged = _history(0.9, converged=False, stopped="step budget reached (60 steps)")
    *_, calls, _ = _run([unconverged, _history(0.001)], tmp_path)
    assert len(calls) == 1


def test_no_repeat_once_the_wall_time_budget_is_spent(tmp_path):
    *_, calls, _ = _run([_history(0.9), _history(0.001)], tmp_path, budget=1e-9)
    assert len(calls) == 1


def test_a_diverged_training_counts_as_failed_and_only_all_diverged_raises(tmp_path):
    boom = TrainingDiverged("training diverged at step 5")
    model, _, outcomes, chosen, _, _ = _run([boom, _history(0.3), _history(0.01)], tmp_path)
    assert (model, chosen) == ("model 2", 2)
    assert outcomes[0].diverged and outcomes[0].to_json()["score"] is None
    with pytest.raises(TrainingDiverged, match="step 5"):
        _run([boom, boom], tmp_path, repeats=2)


def test_an_interrupted_training_ends_the_repeats_and_says_so_on_the_kept_history(tmp_path):
    first = _history(0.5)
    cut = _history(0.2, converged=False, stopped="interrupted at step 40")
    cut.best_rollout_failures = 3  # worse than the first: the first stays kept
    model, history, outcomes, _, calls, _ = _run([first, cut, _history(0.001)], tmp_path)
    assert model == "model 0" and len(calls) == 2
    assert history.stopped == "interrupted at step 40 of training 2"
    # Ctrl-C in a later training's first stage: the best so far is kept, marked interrupted.
    model, history, *_ = _run([_history(0.5), KeyboardInterrupt()], tmp_path)
    assert model == "model 0" and history.stopped == "interrupted in training 2"
    with pytest.raises(KeyboardInterrupt):
        _run([KeyboardInterrupt()], tmp_path)


def test_repeats_default_needs_held_out_trajectories_and_presets_train_once():
    # The default network E gets a fourth training with a quadratic form; L = 0 beside an
    # entropy learns the exchange as the third instead; a quadratic E asked for, or a local
    # one, has no alternative form to try.
    assert _repeats.repeats_for(RunConfig(), valid="held out") == _repeats.REPEATS + 1
    for three in (RunConfig(poisson="zero", entropy="sum:0,1"), RunConfig(quadratic=True),
                  RunConfig(energy="local:2")):
        assert _repeats.repeats_for(three, valid="held out") == _repeats.REPEATS
    assert _repeats.repeats_for(RunConfig(), valid=None) == 1
    assert _repeats.repeats_for(RunConfig(repeats=5), valid="held out") == 5
    assert preset("gas-containers").repeats == 1  # tuned and measured with one training
    for bad in (0, -1, 2.5):
        with pytest.raises(MetriplexError, match="--repeats"):
            validate(RunConfig(repeats=bad), 3)


def test_a_run_trains_again_and_resumes_each_training_from_its_checkpoint(trained_run, tmp_path,
                                                                           capsys, monkeypatch):
    # The data and structure of the session's shared run (tests/conftest.py), whose worker has
    # compiled them already; every model "poor" (good only at a score <= 0): two short
    # trainings that converge (patience 1, no learning-rate cut), the better one kept.
    monkeypatch.setattr(_repeats, "GOOD_SCORE", 0.0)
    data = mx.read(trained_run / "data.npz")
    config = RunConfig(poisson="canonical:1", entropy="sum:2", width=8, steps=400,
                       eval_every=10, patience=1, lr_cuts=0, repeats=2)
    out = tmp_path / "run"
    split = dict(trajectories=range(6), validation_ids=[4, 5])
    model, history, *_ = train_run(data, config, out, progress=False, **split)
    header = json.loads((out / "config.json").read_text())
    assert header["decided"]["repeats"] == 2 and len(header["trainings"]) == 2
    scores = [t["score"] for t in header["trainings"]]
    assert all(t["converged"] for t in header["trainings"])
    assert history.best_rollout == min(scores) == scores[header["kept_training"]]
    assert scores[0] != scores[1]  # another initialisation, another model
    assert (out / "checkpoint.ckpt").is_file() and (out / "checkpoint-2.ckpt").is_file()
    assert not list(out.glob("first-stage*"))  # the stages' checkpoints go when the run ends
    assert "training 2 of at most 2" in capsys.readouterr().err
    # --resume of a finished run finds both trainings done and keeps the same model.
    _, again, *_ = train_run(data, config, out, resume=True, progress=False, **split)
    assert again.best_rollout == history.best_rollout
    assert json.loads((out / "config.json").read_text())["kept_training"] == \
        header["kept_training"]


@pytest.mark.parametrize("kept", ["checkpoint.ckpt", "first-stage.ckpt", "held-stage.ckpt"])
def test_an_interrupted_train_says_whether_there_is_anything_to_resume(tmp_path, kept):
    # Ctrl-C before the first checkpoint (in the choice of initialisation) keeps nothing:
    # --resume would refuse, and so would a plain train into the non-empty folder. The
    # checkpoint of the main training or of a stage before it can be resumed.
    import argparse

    from metriplex.app.cli import _what_is_kept
    from metriplex.app.runs import check_run_folder

    args = argparse.Namespace(command="train", out=str(tmp_path))
    (tmp_path / "config.json").write_text("{}")
    said = _what_is_kept(args)
    assert "nothing to resume" in said and "--overwrite" in said
    with pytest.raises(mx.MetriplexError, match="Start it again with --overwrite instead of "
                       "--resume"):
        check_run_folder(tmp_path, resume=True)
    (tmp_path / kept).write_bytes(b"")
    assert "--resume" in _what_is_kept(args)
    check_run_folder(tmp_path, resume=True)
    assert _what_is_kept(argparse.Namespace(command="evaluate", out=str(tmp_path))) == ""


def test_the_last_of_three_trainings_learns_the_pairwise_exchange_where_l_is_zero():
    heat = RunConfig(poisson="zero", entropy="sum:0,1,2")
    last = _repeats.config_for(heat, 2, 3)
    assert last.friction == "exchange" and last.poisson == "zero"
    assert heat.friction == "neural"  # the run's own settings are untouched
    # Only the last of three or more, only where L = 0 beside an entropy and the friction is
    # the default Cholesky form.
    assert _repeats.config_for(heat, 1, 3) is heat
    assert _repeats.config_for(heat, 2, 4) is heat
    assert _repeats.config_for(heat, 3, 4).friction == "exchange"
    assert _repeats.config_for(heat, 1, 2) is heat
    for other in (RunConfig(poisson="canonical:1", entropy="sum:2"),
                  RunConfig(poisson="zero", entropy="zero"),
                  RunConfig(poisson="zero", entropy="sum:0,1", friction="diagonal"),
                  RunConfig()):
        assert _repeats.config_for(other, 2, 3) is other


def test_the_fourth_training_learns_e_with_a_quadratic_form_after_three_of_the_network():
    # Six coupled oscillators with two baths: three trainings of the network E at 0.20-0.21
    # held out, the quadratic form 0.018 on the test data (docs/zoo.md). The first three
    # trainings are the run's own, so a case the network fits keeps them.
    config = RunConfig(poisson="canonical:6", entropy="sum:12,13")
    assert [_repeats.config_for(config, r, 4) is config for r in range(3)] == [True] * 3
    fourth = _repeats.config_for(config, 3, 4)
    assert fourth.quadratic and not config.quadratic
    assert dataclasses.replace(fourth, quadratic=False) == config
    assert _repeats.config_for(config, 2, 3) is config  # --repeats 3: none with it
    # Only where E is the default network without the form, and not where the exchange is
    # the alternative.
    for other in (RunConfig(quadratic=True), RunConfig(energy="local:2"),
                  RunConfig(poisson="zero", entropy="sum:0,1")):
        assert _repeats.config_for(other, 3, 4).quadratic == other.quadratic
    training = _repeats.Training.__new__(_repeats.Training)
    object.__setattr__(training, "config", config)
    object.__setattr__(training, "repeats", 4)
    assert [training.change_of(r) for r in range(4)] == ["", "", "", "--quadratic"]


def test_a_training_with_other_settings_says_so_and_its_outcome_keeps_them(tmp_path, capsys):
    calls = []

    def one(r, resumed):
        calls.append(r)
        return f"model {r}", [_history(0.5), _history(0.4), _history(0.1)][r]

    change = {2: "--friction exchange"}.get
    _, _, outcomes, chosen = _repeats.train_repeats(
        one, repeats=3, out=tmp_path, resume=False, budget=None, began=0.0,
        keep=lambda m, h: None, change=lambda r: change(r, ""))
    assert chosen == 2 and [o.change for o in outcomes] == ["", "", "--friction exchange"]
    err = capsys.readouterr().err
    assert "training 2 of at most 3 from another initialisation" in err
    assert "training 3 of at most 3 with --friction exchange" in err
    note = _trainings_note.trainings_note({"trainings": [o.to_json() for o in outcomes],
                                    "kept_training": chosen})
    assert note.startswith("kept training 3 of 3, with --friction exchange (")
    assert "0.1 [--friction exchange]" in note


def test_a_run_that_keeps_the_exchange_records_it_and_its_model_has_it(tmp_path, monkeypatch):
    from helpers import oscillator_data

    # Every training "converged" untrained and poor, the one with other settings ranked first
    # whatever its score: what is checked is the record of a kept exchange (which training
    # the held-out rollouts choose is the test above's), without compiling a training.
    monkeypatch.setattr(_repeats, "fit", lambda model, *a, **k: (model, _history(0.5)))
    monkeypatch.setattr(_repeats.Outcome, "rank",
                        lambda self, limit=0.02: (not self.change, self.score))
    data = oscillator_data()
    config = RunConfig(poisson="zero", entropy="sum:2", width=8, steps=200, eval_every=10,
                       patience=1, lr_cuts=0)
    out = tmp_path / "run"
    model, *_ = train_run(data, config, out, progress=False, trajectories=range(6),
                          validation_ids=[4, 5])
    header = json.loads((out / "config.json").read_text())
    assert [t["change"] for t in header["trainings"]] == ["", "", "--friction exchange"]
    assert header["kept_training"] == 2 and header["decided"]["friction"] == "exchange"
    assert header["config"]["friction"] == "neural"  # what the user gave stays
    assert header["decided"]["exact_friction_degeneracy"] is True
    assert header["loss_terms"] == ["residual"]  # no penalty where M grad E = 0 is exact
    assert isinstance(mx.load(out).friction, mx.structure.ExchangeFriction)


def test_a_resumed_run_counts_the_time_its_interrupted_run_spent(tmp_path):
    # --max-minutes caps the whole run: a new-user check resumed a run capped at 3 minutes with
    # --max-minutes 4 and got 261 s more, two trainings from scratch, after being told that
    # the budget counts the time already trained.
    import time

    from metriplex.app._resume import checkpoint_seconds, spent_seconds
    from metriplex.io import save

    assert spent_seconds(tmp_path) == 0.0 and checkpoint_seconds(tmp_path / "none.ckpt") == 0.0
    model = mx.GenericModel(mx.SumOf((0,)), mx.ZeroPotential(), mx.CanonicalPoisson(2, 1),
                            mx.ZeroFriction(2))
    save(tmp_path / "model.mpx", model, n=2, extra={"train_seconds": 185.5})
    assert spent_seconds(tmp_path) == 185.5
    # A checkpoint's training time is read from its header line alone.
    (tmp_path / "c.ckpt").write_bytes(b"METRIPLEX-CHECKPOINT\n" + json.dumps(
        {"history": {"time": [1.0, 2.5, 61.25]}}).encode() + b"\n" + b"\0" * 8)
    assert checkpoint_seconds(tmp_path / "c.ckpt") == 61.25
    # A run whose earlier part spent the budget starts no other training after the first.
    *_, calls, _ = _run([_history(0.9), _history(0.001)], tmp_path, budget=240.0,
                        began=time.perf_counter() - 250.0)
    assert len(calls) == 1


def test_trainings_that_did_alike_say_that_the_start_is_not_the_limit():
    # A new-user check's two coupled spins (32 trajectories) trained four times at 0.25-0.30
    # of the spread and were told nothing but the scores; 128 trajectories met the bar at once.
    def outcomes(*scores, change=None, failures=0):
        return {"trainings": [{"score": s, "failures": failures, "change": ""} for s in scores]
                + ([{"score": 0.248, "failures": 0, "change": change}] if change else []),
                "kept_training": 0}

    note = _trainings_note.trainings_note(outcomes(0.255, 0.304, 0.258, change="--quadratic"))
    assert "3 trainings from different initialisations did alike (scores within 1.19x" in note
    # two scores 4 % apart: "within 1.04x", not "within 1x" (a new-user check read the latter)
    assert "within 1.04x" in _trainings_note.trainings_note(outcomes(0.300, 0.312))
    assert "too few trajectories" in note and "more of the structure" in note
    # ... or data that no GENERIC model fits (a new-user check's hidden bath, drive, noise).
    assert "not GENERIC in these variables" in note and "metriplex evaluate" in note
    solved = outcomes(0.045, 0.056, 0.042, change="--quadratic")
    solved["trainings"][-1]["score"] = 0.0067  # another form served: nothing to blame
    for unlike in (solved,
                   outcomes(1.27, 0.18, 0.19),          # another start helped: no such note
                   outcomes(0.015, 0.016, 0.017),       # good ones
                   outcomes(0.25, 0.26, failures=1),    # failing rollouts
                   outcomes(0.25),                      # one training: no note at all
                   # one cut short by the time budget (a new-user check's "did alike")
                   {"trainings": [{"score": 0.626, "converged": True, "change": ""},
                                  {"score": 0.734, "converged": False, "change": ""}],
                    "kept_training": 0}):
        assert "did alike" not in _trainings_note.trainings_note(unlike)
    # Where none was good and they did not do alike, the note says that none was good (a
    # new-user check read 0.0343, 0.0212, 0.035, 0.0207 as good ones); not where one was.
    note = _trainings_note.trainings_note(outcomes(0.0343, 0.0212, 0.035, change="--quadratic"))
    assert "did alike" not in note and "none scored under 0.02" in note, note
    assert "none scored" not in _trainings_note.trainings_note(solved)
    assert "none scored" not in _trainings_note.trainings_note(outcomes(0.015, 0.016, 0.017))
    assert "none scored" not in _trainings_note.trainings_note(outcomes(0.25, 0.26, 0.27))


def test_on_noisy_held_out_states_a_score_at_the_noise_is_good(tmp_path, capsys):
    # A new-user check's 5 % noise: the held-out scores (against noisy states) could not fall
    # under 2 % of the spread, so every run trained four times, each scoring about the noise.
    from helpers import oscillator_data
    from test_noise import add_noise

    clean = oscillator_data(k=4, n_t=200)
    assert _repeats.good_score(clean) == _repeats.GOOD_SCORE  # clean: the bar itself
    assert _repeats.good_score(None) == _repeats.GOOD_SCORE
    noisy = add_noise(clean, 0.05, seed=1)
    good = _repeats.good_score(noisy)
    assert good == pytest.approx(_repeats.NOISE_FLOOR * 0.05, rel=0.2)
    calls = []

    def one(r, resumed):
        calls.append(r)
        return f"model {r}", _history(0.064)

    _repeats.train_repeats(one, repeats=4, out=tmp_path, resume=False, budget=None, began=0.0,
                           keep=lambda m, h: None, good=good)
    assert calls == [0]  # at the noise: good, one training
    calls.clear()
    _repeats.train_repeats(lambda r, resumed: one(r, resumed) if r else ("model 0", _history(
        2 * good)), repeats=2, out=tmp_path, resume=False, budget=None, began=0.0,
        keep=lambda m, h: None, good=good)
    err = capsys.readouterr().err
    assert f"(good: <= {good:.3g}, 1.5x the noise on the held-out states)" in err
    # The note on trainings that did alike judges them by the run's own limit.
    header = {"trainings": [{"score": s, "failures": 0, "change": ""} for s in (0.064, 0.07)],
              "kept_training": 0, "decided": {"good_score": good}}
    assert "did alike" not in _trainings_note.trainings_note(header)


def test_a_time_budget_that_cuts_the_trainings_short_is_said(tmp_path, capsys):
    # A new-user check's max_minutes ended train_run in its second training, and nothing said
    # so in Python (no final line there); the kept first training had converged.
    cut = _history(0.3, converged=False, stopped="time budget reached (240 s)")
    model, _, outcomes, chosen, calls, _ = _run([_history(0.4), cut, _history(0.01)], tmp_path)
    assert [r for r, _ in calls] == [0, 1] and chosen == 1
    err = capsys.readouterr().err
    assert "the time budget ended training 2 of at most 3 before it converged" in err
    _run([_history(0.01, converged=False, stopped="time budget reached (240 s)")], tmp_path)
    assert "time budget ended" not in capsys.readouterr().err  # good: nothing to add


def test_an_outcome_reads_back_as_written_and_judges_alike():
    # train's final line judges the trainings of config.json with Outcome.good itself.
    from metriplex.app._repeats import Outcome
    from metriplex.app._trainings_note import _good

    for outcome in (Outcome(0.01, 0, 900, "converged", 3.0, converged=True),
                    Outcome(math.inf, 0, 0, "diverged", 1.0, diverged=True),
                    Outcome(0.01, 2, 900, "converged", 3.0, change="exchange")):
        assert Outcome.from_json(json.loads(json.dumps(outcome.to_json()))) == outcome
        assert _good(outcome.to_json(), 0.02) is outcome.good(0.02)
    assert Outcome(0.01, 0, 900, "converged", 3.0).good(0.02)
    assert Outcome.from_json({"score": 0.03}).good(0.02) is False  # an older file's few keys


def test_a_search_the_time_budget_cut_short_is_no_converged_training_for_the_verdict(tmp_path):
    # A new-user check's gantry crane (exactly GENERIC data): the time budget ended training 3
    # of at most 4, none judged good, and the verdict read the kept training 2's "converged"
    # and said NOT consistent at a residual ratio of 2.1.
    import json

    from metriplex._verdict_checks import _soundness_checks
    from metriplex.app.runs import training_outcome
    from metriplex.verdict import Thresholds

    def run(trainings, kept):
        (tmp_path / "history.json").write_text(json.dumps(
            {"converged": True, "stopped": "converged at step 24800"}))
        (tmp_path / "config.json").write_text(json.dumps(
            {"config": {}, "trainings": trainings, "kept_training": kept}))
        return training_outcome(tmp_path)

    done = {"failures": 0, "converged": True, "stopped": "converged at step 20000"}
    cut = {"score": 0.151, "failures": 0, "converged": False, "stopped": "time budget (600 s)"}
    ended = run([dict(done, score=0.112), dict(done, score=0.0777), cut], 1)
    assert ended["converged"] is False
    assert ended["stopped"].startswith("time budget: the search for a good training was cut "
                                       "short (it ended training 3 before it converged)")
    assert "none judged good at <= 0.02; the one kept, training 2, scored 0.0777" \
        in ended["stopped"]
    reasons = _soundness_checks({"trajectories": 8}, 8, ended["converged"], ended["stopped"],
                                Thresholds(), held_out=100)
    (conv,) = [r for r in reasons if r["name"] == "training_converged"]
    assert conv["passed"] is False and "--resume with a larger --max-minutes" in conv["note"]
    # Not where one was good, where the last training converged, or where the cut one is kept.
    assert run([dict(done, score=0.01), cut], 0)["converged"] is True
    assert run([dict(done, score=0.112), dict(done, score=0.0777)], 1)["converged"] is True
    assert run([dict(done, score=0.112), dict(cut, score=0.05)], 1)["converged"] is True
    (tmp_path / "config.json").write_text("{damaged")  # as before: the history's word
    assert training_outcome(tmp_path)["converged"] is True
    # train's final line says it too (new-user check 29: it read "the kept training:
    # converged", the cut search on stderr only), and what --resume would run.
    header = {"trainings": [dict(done, score=0.112), dict(done, score=0.0777), cut],
              "kept_training": 1, "decided": {"repeats": 4}}
    note = _trainings_note.trainings_note(header)
    assert "time budget: the search for a good training was cut short (it ended training 3" \
        in note
    assert note.endswith(": --resume with a larger --max-minutes goes on with training 3, then "
                         "the 1 left of --repeats"), note
    assert "none scored under" not in note
    header["decided"]["repeats"] = 3
    assert _trainings_note.trainings_note(header).endswith(
        "scored 0.0777: --resume with a larger --max-minutes goes on with training 3")


def test_a_resumed_training_counts_the_seconds_it_had_taken_and_says_it_goes_on(
        tmp_path, monkeypatch, capsys):
    from metriplex.app import _resume

    # A new-user check resumed a training that its time budget had cut: it was told "kept as
    # it was", trained on to convergence, and recorded 134 s for a training of 735 s.
    _repeats.checkpoint_path(tmp_path, 0).write_bytes(b"")
    (tmp_path / "config.json").write_text(json.dumps({"trainings": [{"seconds": 601.0}]}))
    _, _, outcomes, _ = _repeats.train_repeats(
        lambda r, resumed: (f"model {r}", _history(0.5)), repeats=2, out=tmp_path,
        resume=True, budget=None, began=0.0, keep=lambda m, h: None,
        earlier=_resume.earlier_seconds(tmp_path))
    assert 601.0 <= outcomes[0].seconds < 700.0
    assert outcomes[1].seconds < 100.0  # the second left no checkpoint: it started here
    # A run killed before it recorded them: the checkpoint's own time, where it tells one.
    monkeypatch.setattr(_repeats, "checkpoint_seconds", lambda path: 500.0)
    (tmp_path / "config.json").write_text(json.dumps({"config": {}}))
    _, _, again, _ = _repeats.train_repeats(
        lambda r, resumed: (f"model {r}", _history(0.01)), repeats=1, out=tmp_path,
        resume=True, budget=None, began=0.0, keep=lambda m, h: None,
        earlier=_resume.earlier_seconds(tmp_path))
    assert 500.0 <= again[0].seconds < 600.0
    stops = {"time budget reached (518.599 s) at step 43700": "from its checkpoint at step 43 "
             "700, where it had stopped (time budget reached (518.599 s) at step 43700); it "
             "trains on where --max-minutes allows more",
             "step budget reached (43700 steps)": "had ended at step 43 700 (step budget",
             "converged at step 100 (no improvement)": "had ended at step 43 700 (converged at "
             "step 100 (no improvement)); kept as it was",
             "interrupted at step 43700": "from its checkpoint at step 43 700"}
    for stopped, said in stops.items():
        monkeypatch.setattr(_resume, "_checkpoint_meta",
                            lambda path: {"done": 43700, "history": {"stopped": stopped}})
        line = _resume.resuming_line(tmp_path / "checkpoint.ckpt", "training 1")
        assert said in line, line
        assert ("kept" in line) == stopped.startswith(("converged", "step budget")), line


def test_where_l_is_zero_a_training_that_breaks_m_grad_e_is_not_good(tmp_path, capsys):
    # Two new-user checks (a reactor, bodies exchanging heat by radiation): with L = 0 and S
    # given, the learned E shrank and broke M grad E = 0 (0.15, 0.63) while its held-out score
    # counted as good, so the exchange training, which keeps it by construction, never ran.
    calls = []

    def one(r, resumed):
        calls.append(r)
        return f"model {r}", _history(0.005 + 0.003 * r)

    _, _, outcomes, chosen = _repeats.train_repeats(
        one, repeats=3, out=tmp_path, resume=False, budget=None, began=0.0,
        keep=lambda m, h: None, degenerate=lambda model, r: r == 1)
    # The good one is kept, though the other scored lower, and no third training runs.
    assert calls == [0, 1] and chosen == 1 and [o.degenerate for o in outcomes] == [False, True]
    assert "leaves M grad E = 0 unmet at the held-out states" in capsys.readouterr().err
    # train's notes on the trainings speak of their scores: 0.005 was under the limit.
    header = {"trainings": [o.to_json() for o in outcomes], "kept_training": chosen}
    assert "none scored under" not in _trainings_note.trainings_note(header)
    assert _repeats.Outcome.from_json({"score": 0.01}).good()  # a run's record without it
    unmeasured = _repeats.Outcome.from_json({"score": 0.01, "degenerate": None})
    assert unmeasured.degenerate is None and unmeasured.good()
    # Where it is not measured, the outcome says so (None), not that the model keeps it.
    _, _, outcomes, _ = _repeats.train_repeats(
        one, repeats=1, out=tmp_path, resume=False, budget=None, began=0.0,
        keep=lambda m, h: None)
    assert outcomes[0].degenerate is None and outcomes[0].to_json()["degenerate"] is None

    # Ctrl-C while a finished training is measured: it is ranked (unmeasured) and kept where
    # best, and the run ends, interrupted, so that train exits as interrupted.
    def check(model, r):
        if r == 1:
            raise KeyboardInterrupt
        return False

    calls.clear()
    model, history, outcomes, chosen = _repeats.train_repeats(
        one, repeats=3, out=tmp_path, resume=False, budget=None, began=0.0,
        keep=lambda m, h: None, degenerate=check)
    assert calls == [0, 1] and (model, chosen) == ("model 1", 1)
    assert outcomes[1].degenerate is None
    assert history.stopped == "interrupted after training 2 had ended (converged at step 100)"
    # ... and where the interrupted one is not the best, the kept one says so, once.
    calls.clear()
    model, history, outcomes, chosen = _repeats.train_repeats(
        lambda r, resumed: (calls.append(r), (f"model {r}", _history(0.05 + 0.3 * r)))[1],
        repeats=3, out=tmp_path, resume=False, budget=None, began=0.0,
        keep=lambda m, h: None, degenerate=lambda model, r: check(model, r) or None)
    assert calls == [0, 1] and (model, chosen) == ("model 0", 0)
    assert history.stopped == "interrupted after training 2 had ended"
    # A training that Ctrl-C ended is not measured (the check would take a second Ctrl-C).
    _, _, outcomes, _ = _repeats.train_repeats(
        lambda r, resumed: (f"model {r}", _history(0.5, stopped="interrupted at step 40")),
        repeats=3, out=tmp_path, resume=False, budget=None, began=0.0,
        keep=lambda m, h: None, degenerate=check)
    assert len(outcomes) == 1 and outcomes[0].degenerate is None

    x = np.random.default_rng(0).normal(size=(40, 2))
    data = mx.Trajectories(np.repeat(np.arange(4), 10), np.tile(np.arange(10.0), 4), x)
    friction = mx.ConstantFriction(np.asarray([[1.0, -1.0], [-1.0, 1.0]]))  # keeps x1 + x2
    config = RunConfig(poisson="zero", entropy="sum:0,1")
    training = _repeats.Training(config, data, data, *[None] * 11, repeats=3)
    for weights, kept in (((1.0, 1.0), True), ((1.0, 2.0), False)):
        energy = mx.Known(lambda s, w=np.asarray(weights): s @ w)
        model = mx.GenericModel(energy, mx.SumOf((0, 1)), mx.ZeroPoisson(2), friction)
        assert training.degenerate(model, 0) is kept
        assert training.degenerate(model, 2) is None  # the exchange: not measured
        alone = _repeats.Training(config, data, data, *[None] * 11, repeats=1)
        assert alone.degenerate(model, 0) is None  # one training: nothing to choose


def test_how_a_training_ended_is_read_from_one_place():
    # Every reader asks _fit_loop.ending, never the prose (it was read by prefix in 15 places).
    from metriplex._fit_loop import (CONVERGED, DIVERGED, INTERRUPTED, STEP_BUDGET, TIME_BUDGET,
                                     ending)
    said = {"converged at step 100 (no improvement in 20 evaluations after 3 learning-rate "
            "cuts); L-BFGS stopped at iteration 4 (non-finite loss)": CONVERGED,
            "time budget reached (60 s) at step 300": TIME_BUDGET,
            "step budget reached (20 steps)": STEP_BUDGET,
            "interrupted as training 2 ended (converged at step 100)": INTERRUPTED,
            "diverged at step 5 (non-finite: total)": DIVERGED, "": "", "completed": ""}
    assert {k: ending(k) for k in said} == said
    src = pathlib.Path(mx.__file__).parent
    prefix_reads = [f"{path.relative_to(src)}:{i + 1}" for path in sorted(src.rglob("*.py"))
                    for i, line in enumerate(path.read_text().splitlines())
                    if re.search(r"stopped\b[^=]*\.startswith\((?!e\))|\.startswith\(\(?\"("
                                 r"interrupted|converged|early stop|time budget|step budget|"
                                 r"diverged)", line)]
    assert not prefix_reads, prefix_reads
