"""The verdict says yes on GENERIC data and no on data that break the fitted structure."""

import jax.numpy as jnp
import jax.random as jr
import numpy as np
import pytest

import metriplex as mx
from metriplex.verdict import verdict
from helpers import make_data, rigid_body, rigid_x0


def _pumped(x):
    """q' = p, p' = -q + 0.5 p, s' = 0: energy pumped in by a non-conservative force.

    Not GENERIC with L canonical and S = s given: s' = 0 forces M_ss = 0, so (M PSD) the whole
    s-column of M vanishes, M grad S = 0, and the flow would be Hamiltonian (divergence-free),
    but its divergence is 0.5.
    """
    return np.array([x[1], -x[0] + 0.5 * x[1], 0.0 * x[2]])


def _damped(x):
    """GENERIC: E = (q^2 + p^2)/2 + s, S = s, M = 0.3 w w^T with w = (0, 1, -p)."""
    return np.array([x[1], -x[0] - 0.3 * x[1], 0.3 * x[1] ** 2])


def _oscillator_data(field, k, seed, dt=0.05, steps=60, sub=20):
    rng = np.random.default_rng(seed)
    out = []
    for x in rng.uniform(-1.0, 1.0, (k, 3)):
        xs = [x]
        h = dt / sub
        for _ in range(steps * sub):  # RK4, fine substeps: accurate ground truth
            k1 = field(x)
            k2 = field(x + 0.5 * h * k1)
            k3 = field(x + 0.5 * h * k2)
            k4 = field(x + h * k3)
            x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
            xs.append(x)
        out.append((np.arange(steps + 1.0) * dt, np.asarray(xs[::sub])))
    return mx.Trajectories.from_list(out, ("q", "p", "s"))


def _fit_structured(data, seed):
    k = jr.split(jr.key(seed), 2)
    model = mx.GenericModel(
        mx.MLPPotential(3, width=32, data=data.x, key=k[0]), mx.SumOf((2,)),
        mx.CanonicalPoisson(3, 1),
        mx.CholeskyFriction(3, width=32, scaling=mx.Scaling.from_data(data.x), key=k[1]),
    )
    loss = mx.CrankNicolsonResidual() + 10.0 * mx.FrictionDegeneracy()
    model, _ = mx.fit(model, data, loss=loss, steps=1500, batch_size=256, learning_rate=1e-2,
                      progress=False, key=jr.key(seed + 1))
    return model


@pytest.mark.parametrize("seed", [0, 1])
def test_verdict_yes_on_dissipative_generic_data_and_no_on_pumped_energy(seed):
    good = _oscillator_data(_damped, 24, seed)
    bad = _oscillator_data(_pumped, 24, seed)
    v_good = verdict(_fit_structured(good, seed), good, width=32, steps=1500, learning_rate=1e-2,
                     seed=seed)
    v_bad = verdict(_fit_structured(bad, seed), bad, width=32, steps=1500, learning_rate=1e-2,
                    seed=seed)
    assert v_good["consistent"], v_good
    assert not v_bad["consistent"], v_bad
    assert v_bad["ratio"] > 3 * v_good["ratio"]
    assert "NOT consistent" in v_bad["statement"] and "p" in v_bad["statement"]


def test_verdict_yes_on_rigid_body():
    data = make_data(rigid_body(), rigid_x0(10), 0.1, 60)
    k = jr.split(jr.key(0), 2)
    model = mx.GenericModel(mx.MLPPotential(3, width=32, data=data.x, key=k[0]),
                            mx.ZeroPotential(), mx.SkewMLPPoisson(3, width=32, key=k[1]),
                            mx.ZeroFriction(3))
    model, _ = mx.fit(model, data, loss=mx.CrankNicolsonResidual() + mx.JacobiPenalty("exact"),
                      steps=1500, batch_size=256, learning_rate=1e-2, progress=False,
                      key=jr.key(1))
    v = verdict(model, data, width=32, steps=1500, learning_rate=1e-2)
    assert v["consistent"], v
