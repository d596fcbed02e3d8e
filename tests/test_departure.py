"""A failed rollout says whether it had left the training data before it failed."""

import numpy as np
import pytest

from metriplex.app._commands import FAR_FROM_DATA, _departure

UNITS = {"shift": [0.0, 10.0], "scale": [1.0, 0.5]}


def test_the_furthest_excursion_is_named_with_its_variable_and_step():
    xs = np.array([[0.0, 10.0], [2.0, 11.0], [-9.0, 10.5], [3.0, 14.0], [np.nan, np.nan]])
    away = _departure(UNITS, xs, ["q", "T"])
    # q reaches 9 standard deviations at step 2; T reaches (14 - 10) / 0.5 = 8 at step 3
    assert away == {"variable": "q", "standard_deviations": 9.0, "step": 2}


def test_nothing_is_claimed_within_the_data_or_without_units():
    xs = np.array([[0.0, 10.0], [FAR_FROM_DATA * 0.99, 10.0 - 0.5 * FAR_FROM_DATA * 0.99]])
    assert _departure(UNITS, xs, ["q", "T"]) is None
    assert _departure({}, xs * 100, ["q", "T"]) is None
    assert _departure(UNITS, xs[:0], ["q", "T"]) is None


def test_evaluated_data_beyond_the_training_data_are_named():
    # A test set with one trajectory far from the training data gave a confident "NOT
    # consistent ... add the variable" and no word that the model was extrapolating there.
    import metriplex as mx
    from metriplex.app._warnings import training_range_warning

    t = np.arange(5) * 0.1
    near = np.stack([np.linspace(-1, 1, 5), np.full(5, 10.0)], axis=1)
    far = near + np.array([0.0, 0.5 * 7.5])  # T at 7.5 standard deviations
    data = mx.Trajectories.from_list([(t, near), (t, far), (t, near)], ("q", "T"))
    (line,) = training_range_warning(UNITS, data)
    assert "1 of 3 trajectories (1)" in line and "T at 7.5 training standard deviations" in line
    assert training_range_warning(UNITS, data.select([0, 2])) == []
    assert training_range_warning({}, data) == []  # an older run without units


def test_a_share_of_evaluated_states_beyond_three_standard_deviations_is_noted():
    # Test states of higher energy than any training one (12 % beyond 3 sd, none beyond the
    # range named above) erred 4x the validation error with nothing said (new-user check 13).
    import metriplex as mx
    from metriplex.app._warnings import training_range_warning

    t = np.arange(10) * 0.1
    q = np.linspace(-1, 1, 10)
    inside = np.stack([q, np.full(10, 10.0)], axis=1)
    beyond = np.stack([q, 10.0 + 0.5 * np.r_[np.zeros(8), 4.0, 4.0]], axis=1)  # T at 4 sd
    (line,) = training_range_warning(UNITS, mx.Trajectories.from_list(
        [(t, inside), (t, beyond)], ("q", "T")))
    assert line.startswith("note: 10% of the evaluated states lie beyond 3 training standard")
    assert "(most often T)" in line
    few = mx.Trajectories.from_list([(t, inside)] * 3 + [(t, beyond)], ("q", "T"))  # 5 %
    assert training_range_warning(UNITS, few) == []


def test_states_beyond_three_standard_deviations_but_within_the_training_range_are_no_note():
    # A damped oscillator's large first swings are rare: 4 % of a new-user check's training
    # states lay beyond 3 standard deviations, and its test states, reaching no further than
    # the training ones, were told "there the model extrapolates".
    import metriplex as mx
    from metriplex.app._warnings import training_range_warning

    t = np.arange(200) * 0.1
    swings = [np.stack([a * np.exp(-0.3 * t) * np.cos(t), -a * np.exp(-0.3 * t) * np.sin(t)], 1)
              for a in (1.0, 1.2, 1.4, 1.6)]
    train = mx.Trajectories.from_list([(t, x) for x in swings], ("q", "p"))
    units = mx.Units.from_data(train)
    assert units.low is not None and units.high is not None
    from metriplex._verdict_training import BEYOND

    z = np.abs((train.x - np.asarray(units.shift)) / np.asarray(units.scale))
    assert np.mean(np.any(z > BEYOND, axis=1)) > 0.05  # the training data's own share
    same = train.select([1, 3])
    assert training_range_warning(units.to_json(), same) == []
    # Without the range (an older run's units) the same data get the note.
    old = {k: v for k, v in units.to_json().items() if k not in ("low", "high")}
    (line,) = training_range_warning(old, same)
    assert line.startswith("note:")
    # Beyond the range they still do: an undamped swing, up to 4 standard deviations.
    larger = mx.Trajectories.from_list([(t, np.stack([np.cos(t), -np.sin(t)], 1))], ("q", "p"))
    (line,) = training_range_warning(units.to_json(), larger)
    assert line.startswith("note:") and "beyond the training data's range" in line


def test_states_far_from_the_mean_but_within_the_training_extent_were_trained_on():
    # A new-user check's reactor: training states gathered near equilibrium (N_A 0.28, standard
    # deviation 0.087) with a few trajectories from far out (up to 1.06); a test trajectory
    # reaching 0.84 was told "never trained on" at 6.4 deviations and the verdict cannot tell.
    import metriplex as mx
    from metriplex.app._warnings import training_range_warning

    t = np.arange(50) * 0.1
    rest = [np.stack([0.28 + 0.01 * np.sin(t + k), np.full(50, 1.0)], 1) for k in range(30)]
    out = np.stack([0.28 + 0.78 * np.exp(-t), np.full(50, 1.0)], 1)
    train = mx.Trajectories.from_list([(t, x) for x in rest + [out]], ("N_A", "c"))
    units = mx.Units.from_data(train)
    test = mx.Trajectories.from_list([(t, np.stack([0.28 + 0.56 * np.exp(-t),
                                                      np.full(50, 1.0)], 1))], ("N_A", "c"))
    assert (0.84 - units.shift[0]) / units.scale[0] > FAR_FROM_DATA  # far from the mean ...
    assert units.farthest(test.x)[0] == 0.0  # ... inside what training saw
    assert not [w for w in training_range_warning(units.to_json(), test) if "never" in w]
    beyond = mx.Trajectories.from_list([(t, np.stack([0.28 + 1.5 * np.exp(-t),
                                                        np.full(50, 1.0)], 1))], ("N_A", "c"))
    (line,) = training_range_warning(units.to_json(), beyond)
    assert "never trained on (N_A at" in line


def test_steps_far_larger_than_the_training_steps_are_warned_about():
    # A new-user check gave rollout its initial states with one more sample at t = 10, 200
    # training steps away: each was predicted in one step (errors up to 7.6, an entropy
    # that fell), every status "ok", nothing said.
    import metriplex as mx
    from metriplex.app._warnings import time_unit_warning

    t = np.arange(101) * 0.05
    swing = np.stack([np.cos(t), -np.sin(t)], axis=1)
    units = mx.Units.from_data(mx.Trajectories.from_list([(t, swing), (t, 0.5 * swing)],
                                                         ("q", "p"))).to_json()
    assert units["step"] == pytest.approx(0.05)
    two = mx.Trajectories.from_list([(np.array([0.0, 5.0]), swing[[0, 100]])], ("q", "p"))
    (line,) = [w for w in time_unit_warning(units, two) if "steps reach" in w]
    assert "steps reach 5, 100 times the training data's largest (0.05)" in line
    assert "repeat the initial state at every time wanted" in line
    fine = mx.Trajectories.from_list([(t[:21] * 2, swing[:21])], ("q", "p"))  # steps 0.1: 2x
    assert not [w for w in time_unit_warning(units, fine) if "steps reach" in w]
    assert not [w for w in time_unit_warning({k: v for k, v in units.items() if k != "step"},
                                             two) if "steps reach" in w]  # an older run


def test_evaluate_every_k_says_its_rollouts_step_k_samples_at_a_time():
    # A new-user check followed the verdict's advice for noisy data (evaluate --every K) and
    # read the rollout error at K = 16 as the model's: 0.187 against 0.034 at the data's step.
    from metriplex.app._horizon_note import every_note
    from metriplex.app._warnings import structure_warnings

    assert every_note({}) == [] and every_note({"every": 1}) == []
    (line,) = every_note({"every": 16})
    assert "16 samples at a time" in line and "without --every" in line
    assert line in structure_warnings({"every": 16})
