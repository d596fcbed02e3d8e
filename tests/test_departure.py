"""A failed rollout says whether it had left the training data before it failed."""

import numpy as np

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
