"""What ``train`` says of its data before training (``metriplex.app._data_checks``): each
warning fires on the mistake a new user made with their own data, and stays silent on exactly
GENERIC data of every zoo system and on noise."""

import numpy as np
import pytest

import metriplex as mx
from metriplex.app._data_checks import data_notes, data_summary, entropy_warnings, gap_warning
from metriplex.systems import generate
from metriplex.systems.zoo import ZOO


def _with(data, x=None, t=None):
    return mx.Trajectories(data.trajectory, data.t if t is None else t,
                           data.x if x is None else x, data.names)


@pytest.fixture(scope="module")
def bath():
    return generate("oscillator-bath", trajectories=6, steps=60, seed=0)


@pytest.mark.parametrize("name", sorted(ZOO))
def test_exactly_generic_data_give_only_the_summary(name):
    case = ZOO[name]
    data = generate(case.system, trajectories=6, steps=40, dt=case.dt, seed=0)
    train, valid = data.split(0.34, seed=0)
    notes = data_notes(train, valid, case.flags.get("entropy", "neural"))
    assert len(notes) == 1 and notes[0].startswith("data: 6 trajectories (4 to train, 2 to "
                                                   "validate) of 41 samples;")


def test_the_summary_says_what_was_read(bath):
    train, valid = bath.split(0.34, seed=0)
    line = data_summary(train, valid)
    assert line.startswith("data: 6 trajectories (4 to train, 2 to validate) of 61 samples; 3 "
                           "variables (q, p, s); time steps ")
    (t, x), = [next(iter(bath))]
    one = mx.Trajectories.from_list([(t, x)], names=bath.names)
    assert "1 trajectory split in time (49 samples to train, the last 13 to validate)" in \
        data_summary(*one.split(0.2))


def test_time_and_variables_swapped_are_pointed_at(bath):
    # A 10 x 100 x 3 array read as 100 variables of 3 samples trained without a word.
    rng = np.random.default_rng(0)
    swapped = mx.Trajectories.from_list([(np.arange(3) * 0.1, rng.normal(size=(3, 100)))
                                         for _ in range(4)])
    warning = data_notes(swapped, None, "neural")[1]
    assert warning.startswith("warning: every trajectory has at most 3 samples but there are "
                              "100 variables: were time and variables swapped")


def test_two_recordings_under_one_id_are_pointed_at(bath):
    # Two logging sessions concatenated, each numbering its runs from 0: one pair per
    # trajectory spans 3990 time units against a median step of 0.1.
    t = bath.t.copy()
    first = np.flatnonzero(bath.trajectory == bath.ids[2])
    t[first[30:]] += 1000.0
    (line,) = gap_warning([_with(bath, t=t)])
    assert line.startswith("warning: 1 time step(s) of more than 100x their trajectory's median")
    assert f"trajectory {bath.ids[2]} from t = {bath.t[first[29]]:.6g} to " in line
    # Irregular steps (up to 20x apart) are no gap.
    rng = np.random.default_rng(1)
    irregular = mx.Trajectories.from_list(
        [(np.cumsum(rng.uniform(0.01, 0.2, 50)), rng.normal(size=(50, 2))) for _ in range(3)])
    assert gap_warning([irregular]) == []


def test_an_entropy_that_falls_or_never_moves_is_pointed_at(bath):
    flipped = bath.x.copy()
    flipped[:, 2] *= -1.0
    (line,) = entropy_warnings([_with(bath, x=flipped)], "sum:2")
    assert line.startswith("warning: the entropy of --entropy sum:2 (s) falls along 6 of 6 "
                           "trajectories")
    assert entropy_warnings([bath], "sum:2") == []
    # Noise on a conserved S (no dissipation) is no fall.
    rng = np.random.default_rng(0)
    still = bath.x.copy()
    still[:, 2] = 1.0 + 1e-3 * rng.normal(size=len(still))
    assert entropy_warnings([_with(bath, x=still)], "sum:2") == []
    constant = bath.x.copy()
    constant[:, 2] = 9.81
    (line,) = entropy_warnings([_with(bath, x=constant)], "sum:2")
    assert "does not change anywhere in the data, so S is constant, M grad S = 0" in line


def test_data_where_nothing_moves_are_pointed_at(bath):
    frozen = _with(bath, x=np.ones_like(bath.x))
    assert any(n.startswith("warning: no variable changes along any trajectory")
               for n in data_notes(frozen, None, "neural"))


def test_times_that_do_not_increase_get_the_cause_that_applies():
    # "Sort the samples by time" would interleave two recordings numbered alike, and cannot
    # help float32 times that are too coarse for an epoch clock.
    x = np.zeros((4, 1))
    with pytest.raises(mx.MetriplexError,
                       match=r"2 separate blocks \(rows 0-1, 4-5 counted from 0 after any "
                             r"header\) and repeat times: two recordings under one id"):
        mx.Trajectories(np.array([0, 0, 1, 1, 0, 0]), np.array([0.0, 1, 0, 1, 0, 1]),
                        np.zeros((6, 1)))
    epoch = np.float32(1.7e9) + np.arange(4, dtype=np.float32)  # rounds to equal values
    with pytest.raises(mx.MetriplexError, match=r"float32, which at t = 1\.7e\+09 resolve only "
                                                r"128"):
        mx.Trajectories(np.zeros(4, int), epoch, x)
    with pytest.raises(mx.MetriplexError, match=r"not in time order.*sort the rows by "
                                                r"trajectory and time"):
        mx.Trajectories(np.zeros(4, int), np.array([0.0, 2.0, 1.0, 3.0]), x)
    # Rows shuffled (as after a merge): one trajectory in many blocks, every time distinct, was
    # "two recordings under one id?" (a new-user check).
    order = np.random.default_rng(0).permutation(8)
    with pytest.raises(mx.MetriplexError, match=r"Its 4 rows \(in \d+ separate blocks, rows .*\) "
                                                r"are not in time order, and no time repeats"):
        mx.Trajectories(np.array([0, 0, 0, 0, 1, 1, 1, 1])[order],
                        np.array([0.0, 1, 2, 3, 0, 1, 2, 3])[order], np.zeros((8, 1)))
    with pytest.raises(mx.MetriplexError, match="Some times repeat: drop the duplicated"):
        mx.Trajectories(np.zeros(4, int), np.array([0.0, 1.0, 1.0, 3.0]), x)


def test_a_mat_file_holding_L_and_M_says_so(tmp_path):
    import scipy.io

    from metriplex.app._data_checks import operators_note

    Z = np.random.default_rng(0).normal(size=(2, 2, 5))
    scipy.io.savemat(tmp_path / "db.mat", {"Z": Z, "dt": 0.1, "L": [[0, 1], [-1, 0]],
                                           "M": np.zeros((2, 2))})
    path = tmp_path / "db.mat"
    (line,) = operators_note(path, "neural", "neural")
    assert "also holds a constant L and M, which this run learns instead; --poisson file:" in line
    (line,) = operators_note(path, f"file:{path}", "neural")
    assert "constant M" in line and "--poisson" not in line
    assert operators_note(path, f"file:{path}", f"file:{path}") == []


def test_numpy_dates_and_durations_are_read_in_seconds():
    # datetime64[ms] times became counts of milliseconds without a word.
    x = np.zeros((3, 1))
    dates = np.array(["2024-01-01T00:00:00.000", "2024-01-01T00:00:00.100",
                      "2024-01-01T00:00:00.200"], dtype="datetime64[ms]")
    t = mx.Trajectories(np.zeros(3, int), dates, x).t
    np.testing.assert_allclose(np.diff(t), 0.1, rtol=1e-5)
    assert abs(t[0] - 1704067200.0) < 1e-3  # seconds since 1970
    spans = np.array([0, 100_000, 250_000], dtype="timedelta64[us]")
    np.testing.assert_array_equal(mx.Trajectories(np.zeros(3, int), spans, x).t, [0, 0.1, 0.25])


def test_a_variable_recorded_twice_is_pointed_at(bath):
    from metriplex.app._data_checks import repeated_column_warning

    twice = mx.Trajectories(bath.trajectory, bath.t, np.c_[bath.x, bath.x[:, 0]],
                            (*bath.names, "q2"))
    (line,) = repeated_column_warning([twice])
    assert line.startswith("warning: q2 repeats q (the same values in every sample)")
    assert repeated_column_warning([bath]) == []


def test_one_or_two_training_trajectories_are_noted():
    # One damped trajectory split in time: held-out 1.6e-3 on its end, 0.91 from other initial
    # states, with nothing said (a new-user check).
    from metriplex.app._data_checks import data_notes

    t = np.linspace(0.0, 10.0, 50)
    one = mx.Trajectories(np.zeros(50, int), t, np.stack([np.exp(-t), np.sin(t)], 1))
    head = mx.Trajectories(np.zeros(40, int), t[:40], one.x[:40])
    tail = mx.Trajectories(np.zeros(10, int), t[40:], one.x[40:])
    (note,) = [n for n in data_notes(head, tail, "neural") if "training trajector" in n]
    assert "only 1 training trajectory" in note and "the end of the same trajectory" in note
    (alone,) = [n for n in data_notes(one, None, "neural") if "training trajector" in n]
    assert "the error on the training data themselves says little" in alone
    many = mx.Trajectories(np.repeat(np.arange(3), 50), np.tile(t, 3),
                           np.random.default_rng(0).normal(size=(150, 2)))
    assert not any("training trajector" in n for n in data_notes(many, None, "neural"))


def _rotating(angle_of, k=4, n_t=200):
    """``k`` pendulums turning over the top, their angle stored by ``angle_of(q)``."""
    t = np.arange(n_t) * 0.1
    return mx.Trajectories.from_list(
        [(t, np.c_[angle_of((1.0 + 0.3 * j) * t + 0.5 * j), np.full(n_t, 1.0 + 0.3 * j),
                   0.01 * t]) for j in range(k)], ("q", "p", "s"))


def test_an_angle_stored_modulo_a_turn_is_named_with_the_fix():
    from metriplex.app._data_checks import sample_warnings, wrapped_angle_warning

    (line,) = wrapped_angle_warning(_rotating(lambda q: np.mod(q, 2.0 * np.pi)))
    assert "q stays within" in line and "half a turn (2 pi)" in line
    assert "trajectory 0 at t = 6.3" in line and "numpy.unwrap(q)" in line
    # In degrees, on (-180, 180], and among the training data's notes.
    degrees = _rotating(lambda q: np.mod(np.degrees(q) + 180.0, 360.0) - 180.0)
    assert "half a turn (360)" in wrapped_angle_warning(degrees)[0]
    assert any("an angle stored modulo a full turn" in x
               for x in data_notes(degrees, None, "sum:2"))
    assert "in the evaluated data" in sample_warnings(degrees, "evaluated data")[0]
    # Unwrapped, nothing; nor where a variable falls from one end of its range to the other
    # at a stiff start, and goes on falling; nor where it never jumps.
    assert wrapped_angle_warning(_rotating(lambda q: q)) == []
    stiff = _rotating(lambda q: 0.2 + 6.0 * np.exp(-30.0 * q))
    assert np.ptp(stiff.x[:, 0]) > 0.75 * 2.0 * np.pi and np.max(np.abs(np.diff(
        stiff.x[:20, 0]))) > np.pi  # a turn's range, and a fall of more than half a turn
    assert wrapped_angle_warning(stiff) == []
    assert wrapped_angle_warning(_rotating(lambda q: 3.0 * np.sin(q))) == []


def test_an_entropy_named_as_a_temperature_is_warned_about():
    # A new-user check gave --entropy sum:2 on a column named theta: trained without a word,
    # and its report drew "temperatures dE/d(theta) = 1" as determined by the data.
    from metriplex.app._data_checks import data_notes, temperature_named_warning

    (line,) = temperature_named_warning(("q", "p", "theta"), "sum:2")
    assert "theta (column 2)" in line and "leave --entropy out" in line
    assert len(temperature_named_warning(("q", "p", "T1", "T_2"), "sum:2,3")[0].split("column")) == 3
    for names, entropy in ((("q", "p", "s"), "sum:2"), (("q", "theta", "s"), "sum:2"),
                           (("q", "p", "theta"), "neural"), (("q", "p", "tempo"), "sum:2")):
        assert temperature_named_warning(names, entropy) == []
    data = mx.Trajectories.from_list(
        [(np.arange(5.0), np.c_[np.cos(np.arange(5.0) + j), np.sin(np.arange(5.0) + j),
                                1.0 + 0.1 * np.arange(5.0)]) for j in range(3)],
        ("q", "p", "theta"))
    assert any("named as a temperature" in w for w in data_notes(data, None, "sum:2"))
