"""fit's option objects, Checkpoint and LBFGSFinish: checked when made, and fit refuses
anything else in their place with a message that shows the object to pass."""

import jax
import numpy as np
import pytest

import metriplex as mx


@pytest.mark.parametrize("make, match", [
    (lambda: mx.Checkpoint("c.ckpt", every=0), r"integer >= 1; got 0\. Example: Checkpoint"),
    (lambda: mx.Checkpoint("c.ckpt", every=2.5), r"integer >= 1; got 2\.5"),
    (lambda: mx.LBFGSFinish(steps=-1), r"steps >= 0 and pairs >= 1 .*got steps=-1, pairs=8192"),
    (lambda: mx.LBFGSFinish(pairs=0), r"got steps=1000, pairs=0"),
])
def test_options_out_of_range_are_refused(make, match):
    with pytest.raises(mx.MetriplexError, match=match):
        make()


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
