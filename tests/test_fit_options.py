"""fit's option objects, Checkpoint and LBFGSFinish: checked when made, and fit refuses
anything else in their place with a message that shows the object to pass."""

import jax
import numpy as np
import pytest

import metriplex as mx


@pytest.mark.parametrize("make, match", [
    (lambda: mx.Checkpoint("c.ckpt", every=0), r"integer >= 1; got 0\. Example: Checkpoint"),
    (lambda: mx.Checkpoint("c.ckpt", every=2.5), r"integer >= 1; got 2\.5"),
    (lambda: mx.LBFGSFinish(steps=-1),
     r"LBFGSFinish's steps must be an integer >= 0; got -1\. Example: LBFGSFinish"),
    (lambda: mx.LBFGSFinish(steps=True), r"LBFGSFinish's steps must be an integer >= 0; got True"),
    (lambda: mx.LBFGSFinish(pairs=0), r"LBFGSFinish's pairs must be an integer >= 1; got 0\."),
])
def test_options_out_of_range_are_refused(make, match):
    with pytest.raises(mx.MetriplexError, match=match):
        make()


def test_every_count_takes_numpy_integers_alike():
    # One check (metriplex._errors.expect_integer) for every count an option takes: a NumPy
    # integer, as from np.arange or a config read with NumPy, is an integer everywhere.
    three = np.int64(3)
    counts = (mx.LBFGSFinish(steps=three, pairs=three).pairs,
              mx.Checkpoint("c.ckpt", every=three).every,
              mx.StochasticJacobi(probes=three).probes,
              mx.RolloutWindow(steps=three, windows=three).windows)
    assert all(type(c) is int and c == 3 for c in counts), counts  # kept as Python ints
    for make in (lambda: mx.StochasticJacobi(probes=np.float64(3.0)),
                 lambda: mx.RolloutWindow(steps=3.0)):
        with pytest.raises(mx.MetriplexError, match=r"must be an integer >= 1; got"):
            make()


def test_seeds_are_checked_as_counts_are():
    # A seed is one more integer option, with an upper bound (what NumPy and JAX accept).
    from metriplex.app.config import check_seed

    assert type(check_seed(np.uint32(7))) is int and check_seed(np.uint32(7)) == 7
    for bad in (2**32, -1, 1.0, True):
        with pytest.raises(mx.MetriplexError,
                           match=rf"--seed must be an integer from 0 to 4294967295; got {bad!r}"):
            check_seed(bad)


@pytest.mark.parametrize("option, value, match", [
    ("checkpoint", "run/checkpoint.ckpt",
     r"checkpoint= must be None or Checkpoint\(\.\.\.\); got str .*checkpoint=Checkpoint\("),
    ("finish", 1000, r"finish= must be None or LBFGSFinish\(\.\.\.\); got int 1000.*LBFGSFinish\(steps"),
])
def test_fit_names_the_object_it_takes(option, value, match):
    t = np.linspace(0.0, 1.0, 5)
    data = mx.Trajectories.from_list([(t, np.stack([np.cos(t), np.sin(t)], axis=1))] * 2)
    model = mx.GenericModel(mx.MLPPotential(2, width=4, key=jax.random.key(0)),
                            mx.ZeroPotential(), mx.CanonicalPoisson(2, 1), mx.ZeroFriction(2))
    with pytest.raises(mx.MetriplexError, match=match):
        mx.fit(model, data, steps=1, **{option: value}, key=jax.random.key(1))
