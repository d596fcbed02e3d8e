"""Data-parallel training over 2 simulated CPU devices equals single-device training."""

import os
import subprocess
import sys
import textwrap

import pytest

import metriplex as mx
from helpers import damped_oscillator, make_data, oscillator_x0

SCRIPT = textwrap.dedent(
    """
    import os, sys
    import jax
    jax.config.update("jax_enable_x64", True)
    import equinox as eqx, jax.numpy as jnp, jax.random as jr, numpy as np
    import metriplex as mx
    assert len(jax.devices()) == 2, jax.devices()
    data = mx.read(sys.argv[1])  # written by the test: this process simulates nothing
    def model():
        k = jr.split(jr.key(0), 2)
        return mx.GenericModel(mx.MLPPotential(3, width=8, key=k[0]), mx.SumOf((2,)),
                               mx.CanonicalPoisson(3, 1), mx.CholeskyFriction(3, width=8, key=k[1]))
    field = eqx.filter_jit(lambda m, x: jax.vmap(m.vector_field)(x))
    out = []
    for parallel in (False, True):
        # lr 1e-3: the two runs differ in the order of the gradient's sum; a small rate keeps
        # that rounding from being amplified beyond the tolerance (after 50 steps the fields
        # differ by 1e-15 relative; a learning rate 1e-6 larger in one run fails the check).
        # Without the rollout check the evaluations compare the validation losses (checked
        # below), and the process compiles no rollout: what is compared is the sharded
        # training step.
        m, h = mx.fit(model(), data, steps=50, batch_size=64, learning_rate=1e-3, progress=False,
                      data_parallel=parallel, rollout_check=None, key=jr.key(1))
        out.append((np.asarray(field(m, jnp.asarray(data.x[:20]))), h.valid["total"]))
    np.testing.assert_allclose(out[0][0], out[1][0], rtol=1e-8, atol=1e-10)
    np.testing.assert_allclose(out[0][1], out[1][1], rtol=1e-8)
    try:
        mx.fit(model(), data, steps=1, batch_size=63, progress=False, data_parallel=True, key=jr.key(1))
    except mx.MetriplexError as e:
        assert "must be a multiple of 2; got 63" in str(e), e
    else:
        raise AssertionError("odd batch accepted")
    print("OK")
    """
)


@pytest.mark.slow
def test_two_cpu_devices_match_one(tmp_path):
    mx.write(tmp_path / "d.npz", make_data(damped_oscillator(), oscillator_x0(6), 0.1, 30))
    env = dict(os.environ, XLA_FLAGS="--xla_force_host_platform_device_count=2",
               JAX_PLATFORMS="cpu")
    res = subprocess.run([sys.executable, "-c", SCRIPT, str(tmp_path / "d.npz")],
                         capture_output=True, text=True, env=env,
                         cwd=os.path.dirname(os.path.dirname(__file__)), timeout=600)
    assert res.returncode == 0 and "OK" in res.stdout, res.stderr[-3000:]
