"""The library's entry points compute matrix products at full float32 precision (on NVIDIA GPUs
JAX would otherwise use TensorFloat-32), unless the caller chose a precision."""

import jax
import jax.numpy as jnp
import numpy as np

import metriplex as mx
from metriplex.verdict import verdict


def _recording_model(seen: list):
    def energy(x):
        seen.append(jax.config.jax_default_matmul_precision)  # read while tracing
        return 0.5 * x @ x

    return mx.GenericModel(mx.Known(energy), mx.ZeroPotential(), mx.CanonicalPoisson(2, 1),
                           mx.ZeroFriction(2))


def test_solve_and_simulate_trace_in_full_precision_unless_the_caller_chose():
    seen: list = []
    model = _recording_model(seen)
    x0 = jnp.asarray([[1.0, 0.0], [0.5, 0.5]])
    ts = jnp.asarray(np.arange(5) * 0.1)
    mx.solve(model, x0, ts)
    mx.simulate(model, x0, ts)
    assert seen and set(seen) == {"highest"}, seen
    assert jax.config.jax_default_matmul_precision is None  # restored after the call
    seen.clear()
    with jax.default_matmul_precision("tensorfloat32"):
        mx.solve(model, x0, ts)
    assert seen and set(seen) == {"tensorfloat32"}, seen


def test_fit_traces_in_full_precision():
    seen: list = []

    def poisson(x):
        seen.append(jax.config.jax_default_matmul_precision)  # read while tracing
        return jnp.asarray([[0.0, 1.0], [-1.0, 0.0]], x.dtype)

    data = mx.Trajectories(np.repeat(np.arange(3), 20), np.tile(np.arange(20) * 0.1, 3),
                           np.random.default_rng(0).normal(size=(60, 2)), ("q", "p"))
    model = mx.GenericModel(mx.MLPPotential(2, width=4, depth=1, key=jax.random.key(0)),
                            mx.ZeroPotential(), mx.KnownPoisson(poisson), mx.ZeroFriction(2))
    mx.fit(model, data, steps=2, eval_every=1, validation=None, stopping=None, average=None,
           rollout_check=None, progress=False, key=jax.random.key(1))
    assert seen and set(seen) == {"highest"}, seen
    assert jax.config.jax_default_matmul_precision is None


def test_the_verdict_traces_in_full_precision():
    # It scores the model's residuals itself, outside evaluate and the structure checks.
    seen: list = []
    model = _recording_model(seen)
    ts = jnp.asarray(np.arange(12) * 0.1)
    x0 = jnp.asarray([[1.0, 0.0], [0.5, 0.5], [0.0, 0.8], [0.3, -0.6]])
    xs = np.asarray(mx.solve(model, x0, ts).xs)
    data = mx.Trajectories(np.repeat(np.arange(4), 12), np.tile(np.asarray(ts), 4),
                           xs.reshape(-1, 2), ("q", "p"))
    seen.clear()
    verdict(model, data, steps=2, width=4, depth=1, batch_size=8, validation=0.25)
    assert seen and set(seen) == {"highest"}, seen
    assert jax.config.jax_default_matmul_precision is None
