"""Training on noisy data degrades gracefully (the CN pair loss needs no derivatives of data)."""

import re

import jax.random as jr
import numpy as np
import pytest

import metriplex as mx
from helpers import damped_oscillator, make_data, oscillator_x0


def add_noise(data: mx.Trajectories, level: float, seed: int) -> mx.Trajectories:
    """Gaussian noise of ``level`` times each variable's standard deviation."""
    rng = np.random.default_rng(seed)
    x = data.x + level * data.x.std(axis=0)[None, :] * rng.standard_normal(data.x.shape)
    return mx.Trajectories(data.trajectory, data.t, x, data.names)


def train_and_score(data, test):
    k = jr.split(jr.key(0), 2)
    model = mx.GenericModel(
        mx.MLPPotential(3, width=32, data=data.x, key=k[0]), mx.SumOf((2,)),
        mx.CanonicalPoisson(3, 1),
        mx.CholeskyFriction(3, width=32, scaling=mx.Scaling.from_data(data.x), key=k[1]),
    )
    loss = mx.CrankNicolsonResidual() + 10.0 * mx.FrictionDegeneracy()
    model, _ = mx.fit(model, data, loss=loss, steps=1500, batch_size=256, learning_rate=1e-2,
                      progress=False, key=jr.key(1))
    return mx.evaluate(model, test)["rollout_error_mean"]


# Three trainings of 1500 steps: an end-to-end accuracy run (about 3 minutes on 2 loaded cores),
# so `-m slow`. The same training path (fit of this model and loss on oscillator data) runs by
# default in test_train.py::test_fit_learns_damped_oscillator_far_better_than_untrained.
@pytest.mark.slow
def test_graceful_degradation_with_noise():
    truth = damped_oscillator()
    clean = make_data(truth, oscillator_x0(24), 0.1, 40, names=("q", "p", "s"))
    test = make_data(truth, oscillator_x0(4, seed=9), 0.1, 60, names=("q", "p", "s"))
    errors = {level: train_and_score(add_noise(clean, level, 1) if level else clean, test)
              for level in (0.0, 1e-3, 1e-2)}
    print("rollout error vs relative noise:", errors)
    # Clean and 0.1% noise train equally well; 1% noise costs accuracy but no blow-up.
    assert errors[0.0] < 0.06 and errors[1e-3] < 0.06, errors
    assert errors[1e-2] < 0.25, errors
    assert errors[1e-2] >= 0.5 * errors[0.0], errors


def test_every_kth_sample_keeps_each_trajectory_from_its_first_state():
    # What `metriplex evaluate --every K` evaluates on, where the verdict names noise.
    data = mx.Trajectories.from_list([(np.arange(7.0), np.arange(7.0)[:, None]),
                                      (0.5 * np.arange(4.0), -np.arange(4.0)[:, None])])
    two = data.every(2)
    assert list(two.lengths()) == [4, 2]
    np.testing.assert_array_equal(two.t, [0, 2, 4, 6, 0, 1])
    np.testing.assert_array_equal(two.x[:, 0], [0, 2, 4, 6, 0, -2])
    np.testing.assert_array_equal(data.every(1).x, data.x)
    with pytest.raises(mx.MetriplexError, match=r"samples k must be an integer >= 1; got 0"):
        data.every(0)


def test_interleaved_trajectories_pair_samples_k_apart_and_keep_every_sample():
    data = mx.Trajectories.from_list([(np.arange(7.0), np.arange(7.0)[:, None]),
                                      (0.5 * np.arange(4.0), -np.arange(4.0)[:, None])])
    three = data.interleaved(3)
    np.testing.assert_array_equal(three.ids, [0, 1, 2, 3])  # 3 * id + offset
    # Every sample once, but for the second trajectory's samples 1 and 2: alone in their
    # offsets, they pair with nothing.
    assert sorted(three.x[:, 0]) == [-3, 0, 0, 1, 2, 3, 4, 5, 6]
    np.testing.assert_array_equal(three.pairs().x1[:, 0] - three.pairs().x0[:, 0],
                                  [3, 3, 3, 3, -3])  # pairs 3 samples apart, none across ids
    np.testing.assert_array_equal(data.interleaved(1).x, data.x)


def test_pair_spacing_is_one_on_smooth_motion_and_grows_with_noise():
    from metriplex.data import pair_spacing, roughness

    t = np.arange(400) * 0.02
    clean = mx.Trajectories.from_list(
        [(t, np.stack([np.sin(t + j), np.cos(t + j)], -1)) for j in range(4)])
    assert pair_spacing(clean) == 1  # in any unit of time
    assert pair_spacing(mx.Trajectories(clean.trajectory, 1e3 * clean.t, clean.x)) == 1
    rng = np.random.default_rng(0)
    chosen = []
    for level in (0.01, 0.05):
        noisy = mx.Trajectories(clean.trajectory, clean.t,
                                clean.x + level * rng.normal(size=clean.x.shape))
        k = pair_spacing(noisy)
        # The spacing chosen is the least rough one, and rougher noise moves it further.
        assert k > 1 and roughness(noisy.interleaved(k)) < roughness(noisy)
        # Measured on the data themselves, pairs k apart are those of the interleaved data.
        assert roughness(noisy, spacing=k) == pytest.approx(
            roughness(noisy.interleaved(k), np.std(noisy.x, axis=0)), rel=1e-12)
        chosen.append(k)
    assert chosen[1] > chosen[0]


def test_train_pairs_noisy_samples_further_apart_and_records_the_spacing(tmp_path, capsys):
    import json

    from helpers import oscillator_data
    from metriplex.runs import train_run
    from metriplex.config import RunConfig

    data = add_noise(oscillator_data(k=6, n_t=161), 0.05, seed=0)
    # (one start, one training, no first stage: each has tests of its own)
    config = RunConfig(entropy="sum:2", poisson="canonical:1", width=8, steps=10, eval_every=10,
                       float64=True, starts=1, repeats=1, reversible_first=False)
    train_run(data, config, tmp_path / "run", validation_ids=[4, 5], progress=False)
    header = json.loads((tmp_path / "run" / "config.json").read_text())
    k = header["decided"]["every"]
    err = capsys.readouterr().err
    assert k > 1 and f"training uses pairs {k} samples apart" in err
    # It says how noisy the states are: 5 % of each variable's standard deviation here, and
    # over which data (a new-user check read 4.7 % here and 6.8 % in the final line, which
    # judges the validation trajectories, as one estimate that changed).
    said = re.search(r"the noise is about ([0-9.]+)% of a variable's standard deviation over "
                     r"the training data", err)
    assert said and 4.0 < float(said[1]) < 6.0
    # The split is of the file's trajectories; the roughness recorded is of the pairs trained on.
    assert header["train_trajectories"] == [0, 1, 2, 3]
    # ... and so is the count that the verdict's training_trajectories check reads: four
    # recorded, not 4k interleaved (a new-user check's one trajectory passed it as 12).
    assert header["units"]["trajectories"] == 4
    from metriplex.data import roughness
    train = data.select([0, 1, 2, 3])
    assert header["units"]["roughness"] == pytest.approx(
        roughness(train.interleaved(k), np.asarray(header["units"]["scale"])))
    assert header["units"]["roughness"] < roughness(train)
    # A resumed run keeps its spacing: one from before the choice (no decided.every) trained
    # on neighbouring samples.
    del header["decided"]["every"]
    # ... and its scheme: "cn" among the options, as runs wrote before the data chose it.
    header["config"]["scheme"] = "cn"
    del header["decided"]["scheme"]
    (tmp_path / "run" / "config.json").write_text(json.dumps(header))
    train_run(data, config, tmp_path / "run", validation_ids=[4, 5], resume=True,
              progress=False)
    resumed = json.loads((tmp_path / "run" / "config.json").read_text())
    assert resumed["decided"]["every"] == 1 and resumed["decided"]["scheme"] == "cn"
    # Given (--every K), it is used without a note; K < 1 is refused before anything is read.
    from metriplex.app._data_checks import spacing_note
    from metriplex.app.config import validate

    assert spacing_note(train, k, given=k) == [] and spacing_note(train, 1, given=None) == []
    with pytest.raises(mx.MetriplexError, match=r"--every must be .*>= 1.*got 0"):
        validate(RunConfig(every=0), 3)


def test_trains_final_line_says_its_error_includes_the_noise_of_the_validation_states(tmp_path):
    # At 5 % noise the held-out error on train's last line read 2x the clean-test one, unsaid
    # (audit 10).
    from helpers import oscillator_data
    from metriplex.app._summary import train_summary
    from metriplex.data import noise_level
    from metriplex.train import History

    clean = oscillator_data(k=4, n_t=200)
    noisy = add_noise(clean, 0.05, seed=1)
    assert noise_level(clean) < 0.001 and noise_level(noisy) == pytest.approx(0.05, rel=0.2)
    metrics = {"trajectories": 4, "rollout_failures": 0, "rollout_error_mean": 0.1,
               "evaluated_on": "validation trajectories"}
    line = train_summary(History(), {**metrics, "noise_over_spread": noise_level(noisy)}, 1.0,
                         tmp_path)
    assert "whose noise (about 5." in line and "includes" in line
    assert "over the evaluated trajectories" in line
    quiet = train_summary(History(), {**metrics, "noise_over_spread": noise_level(clean)}, 1.0,
                          tmp_path)
    assert "noise" not in quiet


def test_coarse_or_uneven_clean_steps_are_not_read_as_noise():
    # Clean data at an adaptive solver's own steps (about 18 per period) and a random
    # sub-sample of a fine grid read 1.0 % and 2.9 % "noise" from third differences on an even
    # grid (a new-user check); the divided differences at the samples' own times do not.
    from metriplex.data import noise_level, range_beyond_noise, state_noise

    rng = np.random.default_rng(0)
    grids = {"coarse": np.arange(0.0, 20.0, 0.33),
             "uneven": np.sort(rng.uniform(0.0, 20.0, 80)),
             "adaptive": np.cumsum(np.r_[0.0, rng.uniform(0.005, 0.5, 60)])}
    for name, t in grids.items():
        x = np.stack([np.sin(t), np.cos(t), 0.01 * t], axis=1)
        clean = mx.Trajectories(np.zeros(len(t), int), t, x)
        assert noise_level(clean) < 1e-3, name
        noisy = add_noise(clean, 0.05, seed=2)
        assert noise_level(noisy) == pytest.approx(0.05, rel=0.25), name
    # No unit of time changes it; on an even grid it reads noise as the third differences did.
    t = np.linspace(0.0, 10.0, 200)
    data = add_noise(mx.Trajectories(np.zeros(200, int), t, np.stack([np.sin(t)], 1)), 0.01, 3)
    ms = mx.Trajectories(data.trajectory, 1e3 * data.t, data.x)
    np.testing.assert_allclose(state_noise(ms), state_noise(data), rtol=1e-9)
    third = np.diff(data.x[:, 0], 3)
    assert state_noise(data)[0] == pytest.approx(np.sqrt(np.mean(third**2) / 20), rel=0.2)
    # Trajectories of 4 to 6 samples fall back to lower orders; fewer than 4: zeros.
    short = mx.Trajectories(np.repeat([0, 1], 5), np.tile(np.arange(5.0), 2),
                            0.1 * rng.normal(size=(10, 1)))
    assert 0.0 < state_noise(short)[0] < 1.0
    assert state_noise(mx.Trajectories(np.zeros(3, int), np.arange(3.0), np.ones((3, 1))))[0] == 0
    assert range_beyond_noise(0.01 * rng.normal(size=200)) == 0.0
    # A smooth quantity along uneven times loses nothing to "noise" at its own times.
    t = grids["uneven"]
    means = [m.mean() for m in np.array_split(np.sin(0.3 * t), 10)]
    assert range_beyond_noise(np.sin(0.3 * t), t) == pytest.approx(np.ptp(means), rel=1e-3)


def test_train_notes_clean_pairs_whose_steps_are_coarse_for_the_motion():
    # An adaptive solver's own steps (about 18 a period) trained a model that erred 16x more at
    # a finer step than at the data's, with nothing said (a new-user check).
    from metriplex.app._data_checks import chosen_scheme, coarse_note, coarse_steps, spacing_note
    from metriplex.data import roughness
    from metriplex.app._summary import train_summary
    from metriplex.train import History

    rng = np.random.default_rng(0)

    def circles(t):
        return mx.Trajectories(np.repeat(np.arange(4), len(t)), np.tile(t, 4), np.concatenate(
            [np.stack([np.sin(t + a), np.cos(t + a)], 1) for a in rng.uniform(0, 6, 4)]))

    coarse = circles(np.arange(0.0, 30.0, 0.35))
    rough = coarse_steps(coarse, 1, "cn")
    (note,) = coarse_note(rough, "cn")  # --scheme cn given
    assert "steps are coarse" in note and "roughness 0.2" in note and "--scheme hermite" in note
    assert "Crank-Nicolson pairs" in note
    assert coarse_steps(coarse, 1, "rk4") is None  # fourth order: no such error
    # Where no scheme is given the coarse steps choose the fourth-order Hermite step, and say so.
    assert chosen_scheme(rough) == "hermite" and chosen_scheme(None) == "cn"
    (chosen,) = coarse_note(rough, "hermite", chosen=True)
    assert "fourth-order Hermite step" in chosen and "--scheme cn" in chosen
    assert coarse_note(rough, "hermite") == []  # given: nothing to say
    assert coarse_note(None) == [] and spacing_note(coarse, 1, None) == []
    # Pairs further apart on clean data are not said to be for noise (a 40-cell heat rod).
    (apart,) = spacing_note(coarse, 3, None)
    assert "no noise on the states" in apart and "as noise" not in apart
    # The final line says its held-out error is at those steps.
    metrics = {"trajectories": 4, "rollout_failures": 0, "rollout_error_mean": 3.5e-3,
               "evaluated_on": "validation trajectories", "coarse_steps": coarse_steps(coarse)}
    line = train_summary(History(), metrics, 1.0, "run")
    assert "at the data's own steps, coarse for their motion (roughness 0.2" in line
    assert coarse_steps(circles(np.arange(0.0, 30.0, 0.05))) is None
    # A fast transient that has relaxed by the second halves is stiffness, not coarse motion
    # (a new-user check's heat rod): no fourth-order gain there, so no note and no choice.
    t = np.arange(0.0, 30.0, 0.1)
    stiff = circles(t)
    stiff = mx.Trajectories(stiff.trajectory, stiff.t, np.concatenate(
        [stiff.x, stiff.x[:, :1] + 20.0 * np.exp(-20.0 * stiff.t)[:, None]], 1))
    assert roughness(stiff) > 0.5 and coarse_steps(stiff) is None
    # Noisy data get the note on noise instead (pairs further apart), never this one.
    noisy = add_noise(circles(np.arange(0.0, 30.0, 0.05)), 0.05, seed=4)
    assert coarse_steps(noisy, 8) is None
    assert all("coarse" not in n for n in spacing_note(noisy, 8, None))


def test_uneven_steps_count_by_their_duration_so_long_steps_among_short_ones_read_coarse():
    # A chain sampled at random times (steps from 1e-5 to 1.1) read 0.15 "rough" counted by
    # pairs, its many short steps hiding the long ones that set a rollout's error, and trained
    # with Crank-Nicolson at 3.5x the Hermite step's error with nothing said (new-user check 13).
    from metriplex.app._data_checks import COARSE_STEPS, coarse_steps
    from metriplex.data import roughness

    def circles(t):
        return mx.Trajectories(np.repeat(np.arange(4), len(t)), np.tile(t, 4), np.concatenate(
            [np.stack([np.sin(t + a), np.cos(t + a)], 1) for a in (0.0, 1.0, 2.0, 3.0)]))

    def by_pairs(data):  # every neighbouring pair of pairs counted once
        x, t = data.x / data.x.std(axis=0), data.t
        v = np.diff(x, axis=0) / np.diff(t)[:, None]
        ok = data.trajectory[:-2] == data.trajectory[2:]
        a, b = v[:-1][ok], v[1:][ok]
        return np.sqrt(np.sum((b - a) ** 2) / 3 / (0.5 * np.sum(a * a + b * b)))

    even = circles(np.arange(0.0, 30.0, 0.2))  # on an even grid the weights change nothing
    assert roughness(even) == pytest.approx(by_pairs(even), rel=1e-12)
    # Every tenth step 0.6 long, the others 0.01: by pairs smooth, by time coarse.
    uneven = circles(np.concatenate([[0.0], np.cumsum(np.tile([0.01] * 9 + [0.6], 20))]))
    assert by_pairs(uneven) < COARSE_STEPS < roughness(uneven)
    assert coarse_steps(uneven) == roughness(uneven)


def test_evaluate_says_its_errors_include_the_noise_of_the_states_it_judges():
    # A new-user check read evaluate's 0.063 at 5 % noise as the model's error; against the
    # clean truth from the same initial states it was 0.034. train's final line said so of its
    # held-out error; evaluate now does too.
    from metriplex.app._summary import NOTED_NOISE, evaluated_noise_note

    assert evaluated_noise_note({}) == []
    assert evaluated_noise_note({"noise_over_spread": NOTED_NOISE / 2}) == []
    (line,) = evaluated_noise_note({"noise_over_spread": 0.05})
    assert "about 5.0% of a variable's" in line and "noise included" in line
