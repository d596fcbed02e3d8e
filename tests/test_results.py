"""What metriplex prints and writes about a run never reads better than the run."""

import json
from pathlib import Path

import jax
import numpy as np
import pytest

from metriplex.app._summary import train_summary
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
    line = train_summary(_history(0, 5000, True, "converged at step 5000"), metrics, 12.0,
                          Path("run"))
    assert "4 of 10 rollouts on validation trajectories FAILED" in line
    assert "error of the 6 completed: 5.000e-02" in line
    assert "NO trained model rolled out the held-out trajectories better than the untrained" in line
    assert "another --seed" in line and "--no-reversible-first" not in line
    staged = train_summary(_history(0, 5000, True, "converged at step 5000"), metrics, 12.0,
                            Path("run"), first_stage=True)
    # After a first stage, step 0 of the main stage is the first stage's trained model: the
    # line does not call it untrained, and names the stall as the cause to rule out.
    assert "NO trained" not in staged and "untrained one" not in staged
    assert "the main stage's start (the first stage's model" in staged
    assert "try another --seed; try --no-reversible-first" in staged
    # Where --repeats trained from other initialisations already, the line says so instead.
    repeated = train_summary(_history(0, 5000, True, "converged at step 5000"), metrics, 12.0,
                             Path("run"), trainings="kept training 1 of 3 (...)")
    assert "another --seed" not in repeated
    assert "poor fit (other initialisations did no better)" in repeated


def test_train_summary_says_when_the_budget_ended_training_before_convergence():
    metrics = {"trajectories": 4, "rollout_failures": 0, "rollout_error_mean": 0.01,
               "evaluated_on": "validation trajectories"}
    line = train_summary(_history(3000, 3000, False, "step budget reached (3000 steps)"),
                          metrics, 5.0, Path("run"))
    assert "not converged, allow more --steps" in line
    assert "rollout error on validation trajectories: 1.000e-02" in line
    # How long they run, with the error (new-user check 17: 5.5e-4 over trajectories of 0.5
    # time units, 30x under the error over 10 on unseen initial states, with nothing said).
    assert "over each whole trajectory, mean of 4" in line  # unknown: not said
    short = train_summary(_history(3000, 3000, False, "step budget reached (3000 steps)"),
                          {**metrics, "duration_median": 0.5}, 5.0, Path("run"))
    assert "over each whole trajectory, each 0.5 time units long (median), mean of 4" in short
    # A time cap is not lifted by more steps; after a first stage, its budget is what was left.
    timed = train_summary(_history(3000, 3000, False, "time budget reached (15.2 s) at step "
                                   "3000"), metrics, 30.0, Path("run"), first_stage=True)
    assert "--steps" not in timed
    assert "continue it with --resume and a larger --max-minutes" in timed
    assert ("(15.2 s: what the stages and trainings before it left of --max-minutes) at step "
            "3000") in timed
    # Capped with its best model earlier: still not converged, and said so (new-user check 17).
    capped = train_summary(_history(2000, 3000, False, "time budget reached (15.2 s) at step "
                                    "3000"), metrics, 30.0, Path("run"))
    assert "; not converged: continue it with --resume and a larger --max-minutes" in capped
    assert "never trained" not in timed
    # An interrupted training wants --resume, not more steps (new-user check 15).
    cut = train_summary(_history(3000, 3000, False, "interrupted at step 3000"), metrics, 5.0,
                        Path("run"))
    assert "not converged, continue it with --resume" in cut and "--steps" not in cut
    # A first stage that took the whole budget left the main stage (the friction) untrained.
    spent = train_summary(History(step=[0], best_step=0, converged=False,
                                  stopped="time budget reached (1 s) at step 0"),
                          metrics, 12.0, Path("run"), first_stage=True)
    assert "the first stage took the whole budget, so the main stage (the friction with it) " \
           "never trained: allow more time (--max-minutes)" in spent
    done = train_summary(_history(2000, 3000, True, "converged at step 3000"), metrics, 5.0,
                          Path("run"))
    assert "not converged" not in done and "FAILED" not in done and "NO trained" not in done
    # After a first stage the count is the main stage's, and the line says so.
    assert done.startswith("trained 3000 steps in 5.0 s")
    staged = train_summary(_history(2000, 3000, True, "converged at step 3000"), metrics, 5.0,
                            Path("run"), first_stage=True)
    assert staged.startswith("trained 3000 steps after the first stage's (L grad E alone, "
                             "above), both in 5.0 s")
    held = train_summary(_history(2000, 3000, True, "converged at step 3000"), metrics, 5.0,
                          Path("run"), first_stage=True, held_stage=True)
    assert held.startswith("trained 3000 steps after the first stage's (L grad E alone) and "
                           "the held one's (the friction to that energy; above), all in 5.0 s")
    # Where --repeats trained several times, the seconds are of them all (audit 10).
    again = train_summary(_history(2000, 3000, True, "converged at step 3000"), metrics, 5.0,
                          Path("run"), first_stage=True, trainings="kept training 2 of 3")
    assert again.startswith("trained 3000 steps after the first stage's (L grad E alone, "
                            "above), every training with its stages in 5.0 s")
    # ... and how training ended is the kept one's: the line before may tell of another cut
    # by the time budget (a new-user check read "converged" against it).
    assert "5.0 s (the kept training: converged at step 3000" in again


def test_train_summary_says_when_the_model_kept_is_barely_trained():
    # Found on a stand-in of a published dataset: the model of step 700 of 13 800 was kept,
    # every later one rolled out the held-out trajectories 10-50x worse, and its error (0.6,
    # better than x(t) = x(0)) came from a model that barely moves.
    metrics = {"trajectories": 8, "rollout_failures": 0, "rollout_error_mean": 0.6,
               "evaluated_on": "validation trajectories"}
    steps = list(range(0, 13_801, 100))

    def history(best, scores):
        return History(step=steps, rollout=scores, best_step=best, best_rollout=1.5,
                       converged=True, stopped="converged at step 13800")

    lost = [1.6] * 7 + [1.5] + [62.0] * (len(steps) - 8)
    line = train_summary(history(700, lost), metrics, 40.0, Path("run"))
    assert "the model of step 700 of 13800 was kept" in line
    assert "median score 62 against 1.5" in line and "barely trained" in line
    assert "(try another --seed)" in line
    again = train_summary(history(700, lost), metrics, 40.0, Path("run"),
                          trainings="kept training 2 of 3 (...)")
    assert "degraded it (other initialisations did no better)" in again
    staged = train_summary(history(700, lost), metrics, 40.0, Path("run"), first_stage=True)
    assert "the main stage's model of step 700 of 13800 was kept" in staged
    assert "friction added to the first stage's model may be barely trained" in staged
    # After a divergence the steps have one entry more than the scores: still said.
    diverged = History(step=steps + [13_900], rollout=lost, best_step=700, best_rollout=1.5,
                       stopped="diverged")
    assert "was kept" in train_summary(diverged, metrics, 40.0, Path("run"))
    # Not said where the later models roll out about as well (a plateau after an early best),
    # where the best came late, or where no rollouts were scored.
    flat = [1.6] * 7 + [1.5] + [2.9] * (len(steps) - 8)
    assert "barely trained" not in train_summary(history(700, flat), metrics, 40.0, Path("run"))
    late = train_summary(history(5000, lost), metrics, 40.0, Path("run"))
    assert "barely trained" not in late
    bare = History(step=steps, best_step=700, converged=True, stopped="converged")
    assert "barely trained" not in train_summary(bare, metrics, 40.0, Path("run"))


def test_evaluate_reports_the_error_of_predicting_no_motion():
    # The baseline x(t) = x(0) that a model must beat, computed by hand on the same data; a
    # model with no motion at all (zero L and M) scores exactly that baseline, and the first
    # second of the trajectories (to the horizon) less.
    import metriplex as mx
    from helpers import oscillator_data

    data = oscillator_data(k=4, n_t=21)
    ts, xs, lengths = data.padded()
    by_hand = np.mean([np.linalg.norm(xs[k, :T] - xs[k, :1]) / np.linalg.norm(xs[k, :T])
                       for k, T in enumerate(lengths)])
    still = mx.GenericModel(mx.ZeroPotential(), mx.SumOf((2,)),
                            mx.ZeroPoisson(3), mx.ZeroFriction(3))
    report = mx.evaluate(still, data, horizon=1.0, step_check=False)
    assert report["constant_prediction_error_mean"] == pytest.approx(by_hand, rel=1e-12)
    assert np.mean(report["constant_prediction_error"]) == pytest.approx(by_hand, rel=1e-12)
    assert report["rollout_error_mean"] == pytest.approx(by_hand, rel=1e-12)
    assert report["constant_prediction_error_mean_completed"] == pytest.approx(by_hand)
    # In standard deviations too (a new-user check read 7.7e-2 standardised beside 1.6e-3
    # plain), the model's own standardised error for the motionless model; no offset moves it.
    still_std = report["constant_prediction_error_standardised_mean"]
    assert still_std == pytest.approx(report["rollout_error_standardised_mean"], rel=1e-12)
    far = mx.Trajectories(data.trajectory, data.t, data.x + np.asarray([0.0, 0.0, 1e4]),
                          data.names)
    shifted = mx.evaluate(still, far, step_check=False)
    assert shifted["constant_prediction_error_standardised_mean"] == pytest.approx(still_std)
    assert shifted["constant_prediction_error_mean"] < 1e-2 * by_hand
    assert 0 < report["constant_prediction_error_to_horizon_mean"] < by_hand
    assert report["trajectories_ending_before_horizon"] == 0
    # A horizon beyond the data's end: the error is the whole length's, and the report says
    # for how many trajectories (it gave the full-length error under the horizon's name).
    span = max(t[-1] - t[0] for t, _ in data)
    beyond = mx.evaluate(still, data, horizon=10 * span, step_check=False)
    assert beyond["trajectories_ending_before_horizon"] == len(data)


def test_train_summary_says_when_the_model_does_not_beat_predicting_no_motion():
    metrics = {"trajectories": 4, "rollout_failures": 0, "rollout_error_mean": 0.9,
               "rollout_error_mean_completed": 0.9, "constant_prediction_error_mean": 0.8,
               "constant_prediction_error_mean_completed": 0.8,
               "evaluated_on": "validation trajectories"}
    history = _history(3000, 4000, True, "converged at step 4000")
    line = train_summary(history, metrics, 5.0, Path("run"))
    assert "NO better than predicting x(t) = x(0) (8.000e-01)" in line
    # Where the model beats x(t) = x(0) on most trajectories and a few decide the mean (a
    # new-user check: 2 of 6 held-out trajectories, while the test set erred 10x less than
    # the baseline), the line says so rather than "does not predict these trajectories".
    few = dict(metrics, rollout_error=[0.01, 0.02, 3.5, 0.03],
               constant_prediction_error=[0.5, 0.6, 1.0, 1.1])
    line = train_summary(history, few, 5.0, Path("run"))
    assert "NO better on average than predicting x(t) = x(0) (8.000e-01), though better on " \
           "3 of the 4 completed rollouts: the mean is decided by the other 1" in line
    assert "does not predict" not in line
    few["rollout_error"] = [0.9, 0.9, float("inf"), 0.03]  # 1 of the 3 completed
    assert "the model does not predict" in train_summary(history, few, 5.0, Path("run"))
    metrics.update(rollout_error_mean=0.02, rollout_error_mean_completed=0.02)
    line = train_summary(history, metrics, 5.0, Path("run"))
    assert "NO better" not in line and "predicting x(t) = x(0) gives 8.000e-01" in line
    metrics["constant_prediction_error_standardised_mean"] = 0.5
    line = train_summary(history, metrics, 5.0, Path("run"))
    assert "predicting x(t) = x(0) gives 8.000e-01 (5.000e-01 in standard deviations)" in line


def test_learned_temperatures_are_reported_and_negative_ones_warned_about():
    # dE/ds_i where S = sum of entropy variables: a model whose heat feeds the motion (E
    # falls with s) against the true oscillator in a bath; a learned S has no temperatures.
    import jax.numpy as jnp
    import metriplex as mx
    from metriplex.app._warnings import temperature_warnings
    from metriplex.diagnostics import structure_residuals
    from metriplex.systems import generate, get_system

    data = generate("oscillator-bath", trajectories=2, steps=20, seed=0)
    true = structure_residuals(get_system("oscillator-bath").model, data.x)
    assert true["temperature_negative_fraction"] == 0.0 and true["temperature_min"] > 0.5
    assert 0.01 < true["temperature_share"] < 1.0
    assert temperature_warnings(true) == []

    cold = mx.GenericModel(mx.Known(lambda x: 0.5 * (x[0]**2 + x[1]**2) - x[2]),
                           mx.SumOf((2,)), mx.CanonicalPoisson(3, 1), mx.ZeroFriction(3))
    r = structure_residuals(cold, data.x)
    assert r["temperature_negative_fraction"] == 1.0 and r["temperature_min"] == -1.0
    (line,) = temperature_warnings(r)
    assert "negative at 100% of the states (least -1)" in line and "--entropy sum:" in line

    learned_s = mx.GenericModel(mx.Known(lambda x: jnp.sum(x**2)), mx.Known(lambda x: x[2]),
                                mx.CanonicalPoisson(3, 1), mx.ZeroFriction(3))
    r = structure_residuals(learned_s, data.x)
    assert r["temperature_negative_fraction"] is None and temperature_warnings(r) == []
    assert "not a sum of entropy variables" in r["null_reasons"]["temperature_min"]


def test_a_learned_energy_that_drives_no_motion_is_reported_and_warned_about():
    # The oscillator in a bath written as pure friction: E = 0 (so L grad E = 0) and the
    # rank-one M = f f^T / (f . grad S) that reproduces the true flow f wherever the entropy
    # grows. The true model's energy drives most of the motion; L = 0 has no share at all.
    import jax
    import jax.numpy as jnp
    import metriplex as mx
    from metriplex.app._warnings import structure_warnings
    from metriplex.diagnostics import structure_residuals
    from metriplex.systems import generate, get_system

    true_model = get_system("oscillator-bath").model
    data = generate("oscillator-bath", trajectories=2, steps=20, seed=0)
    true = structure_residuals(true_model, data.x)
    assert true["reversible_share"] > 0.5 and structure_warnings(true) == []

    def pure_friction(x):
        f = true_model.terms(x).vector_field
        return jnp.outer(f, f) / f[2]

    friction = mx.GenericModel(mx.Known(lambda x: 0.0 * x[0]), mx.SumOf((2,)),
                               mx.CanonicalPoisson(3, 1), mx.KnownFriction(pure_friction))
    rates = jax.vmap(lambda z: true_model.terms(z).vector_field)(jnp.asarray(data.x))
    x = jnp.asarray(data.x)[rates[:, 2] > 1e-3 * jnp.max(rates[:, 2])]  # the entropy grows
    assert len(x) > 20
    assert np.allclose(jax.vmap(lambda z: friction.terms(z).vector_field)(x),
                       jax.vmap(lambda z: true_model.terms(z).vector_field)(x))
    r = structure_residuals(friction, x)
    assert r["reversible_share"] == 0.0
    (line,) = structure_warnings(r)
    assert "drives 0.0e+00 of the motion" in line and "does not identify E" in line

    heat = structure_residuals(get_system("heat-exchange").model,
                               generate("heat-exchange", trajectories=1, steps=5, seed=0).x)
    assert heat["reversible_share"] is None and structure_warnings(heat) == []
    # The friction's smallest eigenvalue beside its largest: what the verdict's PSD check reads.
    assert heat["friction_min_eigenvalue_relative"] == pytest.approx(
        heat["friction_min_eigenvalue"] / heat["friction_max_eigenvalue"])
    assert abs(heat["friction_min_eigenvalue_relative"]) < 1e-9
    assert "L is zero at every state" in heat["null_reasons"]["reversible_share"]


def test_the_verdict_cannot_tell_where_friction_carries_the_motion():
    from metriplex._verdict_checks import _structure_checks
    from metriplex.verdict import Thresholds

    sr = {"degeneracy_L_gradS_relative": 0.0, "degeneracy_M_gradE_relative": 0.0,
          "jacobi_residual_relative": None, "jacobi_residual_to_L": None,
          "friction_min_eigenvalue": 0.0, "friction_min_eigenvalue_relative": 0.0,
          "friction_max_eigenvalue": 1.0, "poisson_antisymmetry_relative": 0.0,
          "temperature_negative_fraction": 0.0, "temperature_min": 0.5,
          "reversible_share": 2e-9,
          "null_reasons": {"jacobi_residual_to_L": "L is zero"}}
    report = {"entropy_production_negative_fraction": 0.0}

    def check():
        return [r for r in _structure_checks(sr, report, Thresholds())
                if r["name"] == "reversible_share"]

    (carried,) = check()
    assert carried["passed"] is False and carried["effect"] == "cannot tell"
    assert "does not identify E" in carried["note"]
    sr["reversible_share"] = 0.7
    (driven,) = check()
    assert driven["passed"] is True and "identify" not in driven["note"]
    sr["reversible_share"] = None
    sr["null_reasons"]["reversible_share"] = "L is zero at every state"
    (none,) = check()
    assert none["passed"] is None and "L is zero" in none["note"]


def test_the_verdict_cannot_tell_where_learned_temperatures_are_negative():
    from metriplex._verdict_checks import _structure_checks
    from metriplex.verdict import Thresholds

    sr = {"degeneracy_L_gradS_relative": 0.0, "degeneracy_M_gradE_relative": 0.01,
          "jacobi_residual_relative": None, "jacobi_residual_to_L": None,
          "friction_min_eigenvalue": 0.0, "friction_min_eigenvalue_relative": 0.0,
          "friction_max_eigenvalue": 1.0, "poisson_antisymmetry_relative": 0.0,
          "temperature_negative_fraction": 0.3, "temperature_min": -2.5e-5,
          "null_reasons": {"jacobi_residual_to_L": "L is zero"}}
    report = {"entropy_production_negative_fraction": 0.0}
    def check():
        return [r for r in _structure_checks(sr, report, Thresholds())
                if r["name"] == "temperatures"]

    (cold,) = check()
    assert cold["passed"] is False and cold["effect"] == "cannot tell"
    assert "least -2.5e-05" in cold["note"] and "feeds the motion" in cold["note"]
    sr.update(temperature_negative_fraction=0.0, temperature_min=0.9)
    (warm,) = check()
    assert warm["passed"] is True and "feeds" not in warm["note"]
    sr.update(temperature_negative_fraction=None, temperature_min=None)
    sr["null_reasons"]["temperature_negative_fraction"] = "S is not a sum of entropy variables"
    (none,) = check()
    assert none["passed"] is None and none["value"] is None and "not a sum" in none["note"]


def test_generalisation_gap_is_read_at_the_kept_step():
    history = History(step=[0, 100, 200], train={"total": [1.0, 0.5, 0.25]},
                      valid={"total": [1.0, 1.5, 1.0]}, best_step=100)
    assert history.generalisation_gap() == 3.0  # 1.5 / 0.5 at step 100, not the last step's 4
    assert History(step=[0, 100], train={"total": [1.0, 0.5]},
                   best_step=100).generalisation_gap() is None  # no validation trajectories
    diverged = History(step=[0, 100], train={"total": [1.0, float("nan")]},
                       valid={"total": [1.0, 2.0]}, best_step=100)
    assert diverged.generalisation_gap() is None


def test_a_learned_entropy_that_the_flow_decreases_is_warned_about():
    # S = q on the oscillator in a bath: with the canonical L, dS/dt = p, negative on half the
    # orbit, because L grad S != 0 (the penalty can leave that); the true model has none.
    import metriplex as mx
    from metriplex.app._warnings import structure_warnings
    from metriplex.diagnostics import evaluate
    from metriplex.systems import generate, get_system

    data = generate("oscillator-bath", trajectories=2, steps=40, seed=0)
    true = evaluate(get_system("oscillator-bath").model, data, step_check=False)
    assert true["entropy_production_negative_fraction"] == 0.0
    assert not [w for w in structure_warnings(true) if "entropy decreases" in w]

    wrong = mx.GenericModel(mx.Known(lambda x: 0.5 * (x[0]**2 + x[1]**2)),
                            mx.Known(lambda x: x[0]), mx.CanonicalPoisson(3, 1),
                            mx.ZeroFriction(3))
    r = evaluate(wrong, data, step_check=False)
    assert 0.2 < r["entropy_production_negative_fraction"] < 0.8
    (line,) = [w for w in structure_warnings(r) if "entropy decreases" in w]
    assert f"{r['entropy_production_negative_fraction']:.0%} of the rollout states" in line
    assert "--degeneracy exact" in line
    # No friction: S plays no part in this model, and the warning says so (a conservative
    # system's learned S is not determined by any data).
    assert r["reversible_share"] == 1.0
    assert "The friction drives none of the motion, so this S plays almost no part" in line
    # ... and what that means for a system that is damped or conducts heat (a new-user check:
    # "if it conserves its energy ...; if it dissipates ..." for a piston that does both).
    assert "if it is damped or heat flows" in line and "the friction was not learned" in line
    busy = structure_warnings({**r, "reversible_share": 0.9})
    (line,) = [w for w in busy if "entropy decreases" in w]
    assert "plays almost no part" not in line


def test_a_model_that_makes_more_entropy_than_the_data_show_is_warned_about():
    # Found on a published-data stand-in: each entropy variable's rate fitted, their sum (the
    # production) 1000x the data's, and the rollouts' entropy rose 17 spreads beyond the data's.
    # Here the damped oscillator in a bath, data with friction 0.01 from s = 0, rolled out by
    # the same model with friction 0.03 (3x the entropy).
    import metriplex as mx
    from helpers import damped_oscillator, make_data
    from metriplex.app._warnings import structure_warnings

    x0 = np.array([[1.0, 0.0, 0.0], [0.0, 1.2, 0.0], [0.8, 0.5, 0.0], [-0.7, 0.3, 0.0]])
    data = make_data(damped_oscillator(0.01), x0, 0.1, 60)
    true = mx.evaluate(damped_oscillator(0.01), data, step_check=False)
    assert abs(true["entropy_rise_over_data_spread"]) < 1e-9
    assert not [w for w in structure_warnings(true) if "makes entropy" in w]
    more = damped_oscillator(0.03)
    r = mx.evaluate(more, data, step_check=False)
    (line,) = [w for w in structure_warnings(r) if "makes entropy" in w]
    rise = r["entropy_rise_over_data_spread"]
    assert f"by {rise:.3g} times its whole range" in line and "--friction file:" in line
    # 3x the friction: the error still looks fair (under 10 %), the entropy does not.
    assert rise > 1.0 and r["rollout_error_mean"] < 0.1
    assert true["entropy_rise_over_data_rise"] == pytest.approx(1.0, abs=1e-6)
    times = r["entropy_rise_over_data_rise"]
    assert times > 2.0 and f"rises {times:.3g} times as much as along the data" in line
    # Where S spreads across the trajectories far more than along each (a new-user check's
    # brake at 290-330 K, heated by 0.5 K along each: 0.066 of the spread, 5.8x the data's
    # rise), the spread figure says little; the ratio, the same as above, still warns.
    offset = mx.Trajectories(data.trajectory, data.t,
                             data.x + np.c_[0.0, 0.0, 3.0][0] * data.trajectory[:, None],
                             data.names)
    r = mx.evaluate(more, offset, step_check=False)
    assert r["entropy_rise_over_data_spread"] < 0.1 * rise
    assert r["entropy_rise_over_data_rise"] == pytest.approx(times, rel=1e-6)
    (line,) = [w for w in structure_warnings(r) if "makes entropy" in w]
    assert "(entropy_rise_over_data_rise)" in line and "whole range" not in line
    # Data whose entropy never changes leave nothing to compare with: null, with the reason
    # (the same shapes as above, so the rollout is not compiled again).
    t = np.arange(61) * 0.1
    still = mx.Trajectories.from_list(
        [(t, np.c_[np.cos(t + j), -np.sin(t + j), np.zeros_like(t)]) for j in range(4)])
    r = mx.evaluate(more, still, step_check=False)
    assert r["entropy_rise_over_data_spread"] is None
    assert r["null_reasons"]["entropy_rise_over_data_spread"] == (
        "the learned entropy is constant over the data's states")
    assert r["entropy_rise_over_data_rise"] is None
    assert "the data raise the learned entropy by less than" in \
        r["null_reasons"]["entropy_rise_over_data_rise"]
    assert not [w for w in structure_warnings(r) if "makes entropy" in w]


def test_a_decrease_of_the_entropy_that_float32_rounding_alone_makes_is_not_counted():
    # A stiff friction that conducts between two variables at nearly equal temperatures:
    # M = c v v^T with v . grad S = 0 in exact arithmetic (c ~ 1e3), so dS/dt = grad S . M grad
    # S = 0, but its float32 sums cancel and round to either sign, beyond 1 % of the state's
    # speed (the reference pendulum's exactly GENERIC model "decreased" its entropy at 1.8 %
    # of its rollout states that way). The rounding bound of those sums decides; a model
    # whose L moves its S (L grad S != 0) still counts in float32.
    import jax.numpy as jnp
    import jax.random as jr

    import metriplex as mx
    from metriplex._model import with_dtype
    from metriplex.diagnostics import entropy_production_negative_fraction

    def friction(x):
        v = jnp.asarray([0.7, -0.3], x.dtype)
        return 1e3 * (1.0 + x[0] ** 2) * (v[:, None] * v[None, :])

    energy = mx.MLPPotential(2, width=4, depth=1, key=jr.key(0))
    entropy = mx.Known(lambda x: 0.3 * x[0] + 0.7 * x[1])
    model = with_dtype(mx.GenericModel(energy, entropy, mx.ZeroPoisson(2),
                                       mx.KnownFriction(friction)), jnp.float32)
    states = np.stack([np.linspace(-1.0, 1.0, 64), np.linspace(0.3, 0.9, 64)], axis=1)
    x = jnp.asarray(states, jnp.float32)
    f = np.asarray(jax.vmap(model.vector_field)(x), np.float64)
    gS = np.asarray(jax.vmap(jax.grad(model.entropy))(x), np.float64)
    rate = np.sum(gS * f, axis=1)
    size = np.linalg.norm(gS, axis=1) * np.linalg.norm(f, axis=1)
    assert np.mean(rate < -1e-2 * size) > 0.1  # what the 1 % rule alone counted
    assert entropy_production_negative_fraction(model, states, np.ones(2)) == 0.0
    moved = with_dtype(mx.GenericModel(mx.MLPPotential(3, width=4, depth=1, key=jr.key(0)),
                                       mx.Known(lambda x: x[0]), mx.CanonicalPoisson(3, 1),
                                       mx.ZeroFriction(3)), jnp.float32)
    orbit = np.stack([np.cos(np.linspace(0, 6, 64)), np.sin(np.linspace(0, 6, 64)),
                      np.zeros(64)], axis=1)
    assert 0.2 < entropy_production_negative_fraction(moved, orbit, np.ones(3)) < 0.8


def test_the_decreasing_entropy_warning_names_the_friction_where_l_grad_s_is_zero():
    from metriplex.app._warnings import structure_warnings

    def line(residual):
        (w,) = [w for w in structure_warnings({"entropy_production_negative_fraction": 0.2,
                                               "degeneracy_L_gradS_relative": residual})
                if "entropy decreases" in w]
        return w

    assert "L grad S is not zero (relative residual 0.3)" in line(0.3)
    held = line(0.0)
    assert "L grad S is not zero" not in held
    assert "L grad S is zero (relative residual 0), so the friction M is not positive" in held


def test_the_entropy_rise_is_judged_on_completed_rollouts_only():
    # A rollout that fails can reach any state before it does (1e18 under an explicit step):
    # its entropy does not count; it is counted in rollout_failures instead.
    from metriplex._entropy_rise import entropy_rise

    S_data = np.tile(np.linspace(0.0, 1.0, 5), (2, 1))
    S = S_data.copy()
    S[1] = [0.0, 1e3, 1e9, 1e18, np.nan]
    lengths = np.array([5, 5])
    reasons = {}
    assert entropy_rise(S, S_data, lengths, np.array([-1, 4]), reasons) == 0.0
    assert entropy_rise(S, S_data, lengths, np.array([3, 4]), reasons) is None
    assert "no rollout completed" in reasons["entropy_rise_over_data_spread"]


def test_evaluate_says_on_stderr_how_many_rollouts_failed(monkeypatch, tmp_path):
    import io
    from contextlib import redirect_stderr, redirect_stdout

    import jax.random as jr

    import metriplex as mx
    import metriplex.app.runs as runs
    import metriplex.app._data_checks as _data_checks
    from metriplex.cli import main

    data = tmp_path / "d.npz"
    t = np.arange(5) * 0.1
    mx.write(data, mx.Trajectories.from_list([(t, np.c_[np.cos(t), np.sin(t), t])] * 2,
                                             ("q", "p", "s")))
    (tmp_path / "run").mkdir()
    energy = mx.MLPPotential(3, width=4, depth=1, key=jr.key(0))
    mx.save(tmp_path / "run" / "model.mpx",
            mx.GenericModel(energy, mx.SumOf((2,)), mx.CanonicalPoisson(3, 1),
                            mx.ZeroFriction(3)), n=3, names=("q", "p", "s"))
    metrics = {"trajectories": 8, "rollout_failures": 3, "rollout_error_mean": None,
               "rollout_error_mean_completed": 1.43,
               "constant_prediction_error_mean_completed": 1.415}
    monkeypatch.setattr(runs, "evaluate_run", lambda *a, **k: dict(metrics))
    monkeypatch.setattr(_data_checks, "check_names", lambda *a, **k: None)
    err = io.StringIO()
    with redirect_stderr(err), redirect_stdout(io.StringIO()):
        main(["evaluate", str(tmp_path / "run"), str(data), "--no-verdict", "--quiet"])
    said = err.getvalue()
    assert "warning: 3 of 8 rollouts FAILED (blew up or did not converge)" in said
    assert "NO better than predicting x(t) = x(0)" in said


def test_a_validation_part_that_does_not_move_is_warned_about():
    # One long trajectory of a damped system: the last fifth, which validates, has come to
    # rest, and every held-out score (which keeps the model and stops training) was taken there.
    import metriplex as mx
    from metriplex.app._warnings import still_validation_warning

    t = np.linspace(0.0, 300.0, 3001)
    x = np.stack([np.exp(-0.1 * t) * np.cos(t), -np.exp(-0.1 * t) * np.sin(t),
                  1.0 - np.exp(-0.2 * t)], axis=1)
    single = mx.Trajectories.from_list([(t, x)], ("q", "p", "s"))
    (line,) = still_validation_warning(*single.split(0.2))
    assert "the only trajectory's samples from t = 240 on" in line and "barely moves" in line
    # The first fifth of the same motion, on trajectories of their own, moves: no warning.
    moving = mx.Trajectories.from_list([(t[:600], x[:600] * (1 + 0.1 * k)) for k in range(5)],
                                       ("q", "p", "s"))
    assert still_validation_warning(*moving.split(0.2)) == []


def test_a_sample_that_jumps_away_and_back_is_named():
    # One spiked sample in 4 500 made a model 80x worse on clean data, and nothing named it.
    import metriplex as mx
    from metriplex.app._warnings import outlier_warning
    from metriplex.systems import generate

    data = generate("oscillator-bath", trajectories=6, steps=100, seed=0)
    assert outlier_warning(data) == []
    x = data.x.copy()
    row = np.flatnonzero(data.trajectory == data.ids[3])[40]
    x[row, 0] += 20 * np.std(x[:, 0])
    spiked = mx.Trajectories(data.trajectory, data.t, x, data.names)
    (line,) = outlier_warning(spiked)
    assert "1 sample(s) of the training data" in line
    assert f"trajectory {data.ids[3]} at t = {data.t[row]:.6g} ({data.names[0]})" in line
    # Noise on every sample is no outlier.
    noisy = data.x + 0.05 * np.std(data.x, axis=0) * np.random.default_rng(0).normal(
        size=data.x.shape)
    assert outlier_warning(mx.Trajectories(data.trajectory, data.t, noisy, data.names)) == []


@pytest.mark.parametrize("offset", [-0.5, 100.0])
def test_the_energy_drift_does_not_depend_on_the_energy_offset(offset):
    # A learned energy's offset is arbitrary: with E = 0 at a starting state the exact model's
    # drift read as 85 (max |dE| / |E(x0)|), with E + 100 as 2e-6.
    import metriplex as mx

    model = mx.GenericModel(mx.Known(lambda x: 0.5 * (x[0] ** 2 + x[1] ** 2) + offset),
                            mx.SumOf((2,)), mx.CanonicalPoisson(3, 1), mx.ZeroFriction(3))
    ts = np.arange(41) * 0.05
    xs = [np.stack([a * np.cos(ts), -a * np.sin(ts), np.zeros_like(ts)], axis=1)
          for a in (1.0, 0.7, 1.3)]  # a = 1 starts at E = 0 where offset = -0.5
    data = mx.Trajectories.from_list([(ts, x) for x in xs], ("q", "p", "s"))
    report = mx.evaluate(model, data, scheme=mx.RK4(), step_check=False)
    assert report["energy_relative_drift"] < 1e-6


def test_training_data_written_again_are_told_in_sample():
    # evaluate compared the whole file's hash: the training data exported with 8 digits, or
    # with a test trajectory added, read as a test.
    import metriplex as mx
    from metriplex.app.config import RunConfig
    from metriplex.app._warnings import trained_on
    from metriplex.app.runs import RunData
    from metriplex.systems import generate

    data = generate("oscillator-bath", trajectories=6, steps=20, seed=0)
    parts = RunData.of(data, RunConfig(validation=0.34))
    run = {"data": parts.info}
    rounded = mx.Trajectories(data.trajectory, data.t,
                              np.array([[float(f"{v:.8g}") for v in row] for row in data.x]),
                              data.names)
    assert trained_on(run, rounded) == sorted(int(i) for i in parts.train.ids)
    assert trained_on(run, generate("oscillator-bath", trajectories=6, steps=20, seed=1)) == []


def test_evaluate_reports_how_far_the_learned_energy_moves_along_the_data():
    # A learned E that GENERIC data do not keep constant (found with 5 % noise: 29 % of its
    # spread along the data, while the rollouts conserved it) is a number in the report.
    import metriplex as mx
    from metriplex import systems

    system = systems.get_system("oscillator-bath")
    data = systems.generate(system, trajectories=3, steps=30, seed=0)
    truth = system.model
    kept = mx.evaluate(truth, data, scheme=mx.RK4(), step_check=False)
    assert kept["energy_change_along_data_over_spread"] < 1e-6
    tilted = mx.GenericModel(mx.Known(lambda x: truth.energy(x) + x[1]), truth.entropy,
                             truth.poisson, truth.friction)
    moved = mx.evaluate(tilted, data, scheme=mx.RK4(), step_check=False)
    assert moved["energy_change_along_data_over_spread"] > 0.05
    # train and evaluate warn where it is more than a tenth (the zoo's clean fits: at most 4 %).
    from metriplex.app._warnings import ENERGY_CHANGE, structure_warnings

    said = [w for w in structure_warnings(moved) if "energy_change_along_data" in w]
    assert (len(said) == 1) == (moved["energy_change_along_data_over_spread"] > ENERGY_CHANGE)
    assert not any("energy_change_along_data" in w for w in structure_warnings(kept))
    assert said and f"{moved['energy_change_along_data_over_spread']:.2g}" in said[0]
    # Only beyond noise on the data: with 5 % noise the true E spans 7 % of its spread over
    # the data along a trajectory of 100 states, noise alone.
    from metriplex.data import range_beyond_noise

    longer = systems.generate(system, trajectories=3, steps=100, seed=0)
    rng = np.random.default_rng(0)
    noisy = mx.Trajectories(longer.trajectory, longer.t, longer.x + 0.05 * np.std(
        longer.x, axis=0) * rng.normal(size=longer.x.shape))
    report = mx.evaluate(truth, noisy, scheme=mx.RK4(), step_check=False)
    assert report["energy_change_along_data_over_spread"] < 0.05
    E = np.asarray([float(truth.energy(x)) for x in noisy.x[:101]])
    assert np.ptp(E) > 0.05 * np.ptp([float(truth.energy(x)) for x in noisy.x])  # noise is there
    assert range_beyond_noise(E) < 0.2 * np.ptp(E)
    assert 0.85 < range_beyond_noise(np.linspace(0.0, 1.0, 100)) < 0.95  # a drift: most of it


def test_an_energy_constant_to_rounding_over_the_data_gets_no_energy_figures_but_a_warning():
    # A new-user check's E with L = 0 and S given collapsed to a spread of ~1e-9 at values near
    # 0.08 (float32 rounding 7e-9): the report said it changed by 0.89 of its spread along the
    # data (rounding over a tiny spread) and its figure "moves by 0". Its moves cannot be
    # measured: the figures are null, with the reason, and train and evaluate say why.
    import metriplex as mx
    from metriplex import systems
    from metriplex._energy_along import ENERGY_ROUNDING_LIMIT, energy_rounding
    from metriplex.app._warnings import structure_warnings

    system = systems.get_system("oscillator-bath")
    data = systems.generate(system, trajectories=2, steps=20, seed=0)
    truth = system.model
    flat = mx.GenericModel(mx.Known(lambda x: 0.084 + 1e-16 * x[1]), truth.entropy,
                           truth.poisson, truth.friction)
    report = mx.evaluate(flat, data, scheme=mx.RK4(), step_check=False)
    assert report["energy_rounding_over_data_spread"] > ENERGY_ROUNDING_LIMIT
    for key in ("energy_relative_drift", "energy_drift_over_data_spread",
                "energy_change_along_data_over_spread"):
        assert report[key] is None
        assert "constant over the data to float64 rounding" in report["null_reasons"][key]
    said = [w for w in structure_warnings(report) if "to rounding" in w]
    assert len(said) == 1 and "the learned energy is constant over the data" in said[0]
    assert "Known limits" in said[0]
    # The true E varies over the data: its figures are numbers, its rounding ~1e-16.
    kept = mx.evaluate(truth, data, scheme=mx.RK4(), step_check=False)
    assert kept["energy_rounding_over_data_spread"] < 1e-12
    assert kept["energy_change_along_data_over_spread"] < 1e-6
    # In float32 the same spread is rounding, where float64 resolves it.
    E = 0.084 + 1e-9 * np.sin(np.arange(50.0))
    assert energy_rounding(E.astype(np.float32), np.float32) > ENERGY_ROUNDING_LIMIT
    assert energy_rounding(E, np.float64) < ENERGY_ROUNDING_LIMIT
    assert energy_rounding(np.zeros(5), np.float32) == np.inf  # E = 0: no move to measure
    assert energy_rounding(np.full(5, 2.0), np.float32) == np.inf
    assert np.isnan(energy_rounding(np.full(5, np.nan), np.float32))


def test_many_variables_that_train_poorly_get_the_blocks_for_cells_named():
    # A new-user check's chain (n = 18) trained to 0.38 with the default blocks and nothing
    # named the cells' blocks, which gave 0.067.
    from metriplex.app._warnings import cells_hint
    from metriplex.config import RunConfig

    poor = {"rollout_error_mean_completed": 0.28}
    (hint,) = cells_hint(poor, RunConfig(), 18)
    assert "--energy local:CELLS --friction local:CELLS" in hint and "18 variables" in hint
    assert "give them time" in hint  # their steps cost more (a 40-cell rod: 10x)
    assert cells_hint(poor, RunConfig(), 5) == []  # few variables
    assert cells_hint({"rollout_error_mean_completed": 0.01}, RunConfig(), 18) == []
    assert cells_hint(poor, RunConfig(energy="local:6", friction="local:6"), 18) == []
    assert cells_hint({}, RunConfig(), 18) == []  # no rollout completed: other warnings
