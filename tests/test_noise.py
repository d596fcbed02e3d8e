"""Training on noisy data degrades gracefully (the CN pair loss needs no derivatives of data)."""

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
    with pytest.raises(mx.MetriplexError, match=r"k >= 1 .*got 0"):
        data.every(0)
