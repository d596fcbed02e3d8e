"""The running average of the parameters that evaluations judge (``fit(average=...)``)."""

import math

import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np
import pytest
from helpers import damped_oscillator, make_data, oscillator_x0

import metriplex as mx


def test_the_average_spans_its_steps_and_at_most_a_twentieth_of_the_budget():
    average = mx.Average(steps=500)
    assert average.weight(100, budget=100_000) == pytest.approx(math.exp(-100 / 500))
    assert average.weight(100, budget=2_000) == pytest.approx(math.exp(-100 / 100))
    assert average.weight(100, budget=10) == pytest.approx(math.exp(-100))  # a 1-step horizon
    old = {"w": jnp.array([0.0, 2.0])}
    new = {"w": jnp.array([1.0, 4.0])}
    beta = average.weight(100, budget=100_000)
    out = average.update(old, new, 100, budget=100_000)
    np.testing.assert_allclose(np.asarray(out["w"]), [1 - beta, 2 * beta + 4 * (1 - beta)])
    with pytest.raises(mx.MetriplexError, match=r"Average's steps must be an integer >= 1; "
                                                r"got 0\. Example: Average\(steps=500\)"):
        mx.Average(steps=0)


def test_evaluations_judge_the_average_and_the_optimiser_is_untouched():
    # A fixed cosine schedule (no plateau restarts): the optimiser's path is the same with and
    # without the average, so the training losses agree to the last bit, while the validation
    # losses (and the model kept) are the average's.
    data = make_data(damped_oscillator(), oscillator_x0(6), 0.1, 20, names=("q", "p", "s"))
    k = jr.split(jr.key(0), 2)
    model = mx.GenericModel(mx.MLPPotential(3, width=8, data=data.x, key=k[0]), mx.SumOf((2,)),
                            mx.CanonicalPoisson(3, 1), mx.CholeskyFriction(3, width=8, key=k[1]))
    runs = {}
    for name, average in (("plain", None), ("averaged", mx.Average())):
        runs[name] = mx.fit(model, data, steps=200, eval_every=20, stopping=None,
                            rollout_check=None, average=average, progress=False,
                            key=jr.key(1))
    (plain, h_plain), (averaged, h_avg) = runs["plain"], runs["averaged"]
    assert h_plain.train["total"][1:] == h_avg.train["total"][1:]
    assert h_plain.valid["total"][0] == h_avg.valid["total"][0]  # the same initial model
    assert h_plain.valid["total"][1:] != h_avg.valid["total"][1:]
    x = jnp.asarray(data.x[:5])
    assert not np.allclose(np.asarray(jax.vmap(plain.vector_field)(x)),
                           np.asarray(jax.vmap(averaged.vector_field)(x)))


def test_fit_names_the_average_it_takes():
    data = make_data(damped_oscillator(), oscillator_x0(2), 0.1, 5, names=("q", "p", "s"))
    model = mx.GenericModel(mx.MLPPotential(3, width=4, key=jr.key(0)), mx.SumOf((2,)),
                            mx.CanonicalPoisson(3, 1), mx.ZeroFriction(3))
    with pytest.raises(mx.MetriplexError, match=r"average= must be None or Average\(\.\.\.\); "
                                                r"got int 500.*Average\(steps=500\)"):
        mx.fit(model, data, steps=1, average=500, key=jr.key(1))
