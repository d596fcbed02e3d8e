"""The implicit fourth-order Hermite step: stable where a step is stiff, and trainable on."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

import metriplex as mx
from metriplex.integrate import RK4, Hermite, solve
from helpers import damped_oscillator, make_data, oscillator_x0


def _relaxation(x):
    return -50.0 * x[0] ** 2  # S = -k x^2/2 with M = 1: dx/dt = -k x, k = 100


#: A fast linear relaxation as GENERIC (E = 0, L = 0, M = 1): :math:`\dot x = -100\,x`.
RELAXATION = mx.GenericModel(mx.ZeroPotential(), mx.Known(_relaxation), mx.ZeroPoisson(1),
                             mx.KnownFriction(lambda x: jnp.ones((1, 1), x.dtype)))


def test_a_step_far_beyond_the_relaxation_time_stays_bounded_where_rk4_blows_up():
    ts = jnp.linspace(0.0, 5.0, 51)  # 10 relaxation times a step
    hermite = np.asarray(solve(RELAXATION, jnp.array([1.0]), ts, scheme=Hermite()).xs[:, 0])
    # Its map is the (2, 2) Pade approximant of exp(z), z = -10: (1 + z/2 + z^2/12)/(1 - z/2 + z^2/12).
    z = -10.0
    ratio = (1 + z / 2 + z * z / 12) / (1 - z / 2 + z * z / 12)
    np.testing.assert_allclose(hermite, ratio ** np.arange(51), rtol=1e-9, atol=1e-12)
    assert np.all(np.abs(hermite[1:]) <= np.abs(hermite[:-1]) + 1e-12)  # never grows
    rk4 = np.asarray(solve(RELAXATION, jnp.array([1.0]), ts, scheme=RK4()).xs[:, 0])
    assert abs(rk4[-1]) > 1e100  # the explicit step of the same order grows 291-fold a step


def test_the_residual_is_zero_on_the_schemes_own_steps_and_differentiable():
    model = damped_oscillator()
    data = make_data(model, oscillator_x0(3), 0.1, 20)  # Crank-Nicolson steps
    p = data.pairs()
    ts = jnp.linspace(0.0, 2.0, 21)  # the same 20 steps of 0.1
    own = np.asarray(solve(model, jnp.asarray(oscillator_x0(3)), ts, scheme=Hermite()).xs)
    scheme = Hermite()

    def mean_square(model, x0, x1, dt):
        t0, t1 = jax.vmap(model.terms)(x0), jax.vmap(model.terms)(x1)
        r = jax.vmap(scheme.residual, in_axes=(None, 0, 0, 0, 0, 0))(model, x0, x1, dt, t0, t1)
        return jnp.mean(r**2)

    on_own = mean_square(model, jnp.asarray(own[:, :-1].reshape(-1, 3)),
                         jnp.asarray(own[:, 1:].reshape(-1, 3)), jnp.full(60, 0.1))
    on_cn = mean_square(model, jnp.asarray(p.x0), jnp.asarray(p.x1), jnp.asarray(p.dt))
    assert float(on_own) < 1e-20
    assert float(on_cn) > 1e6 * float(on_own)  # another scheme's steps leave a defect
    # Training differentiates through the field's rate along the flow (a forward-mode product).
    grads = eqx.filter_grad(mean_square)(model, jnp.asarray(p.x0), jnp.asarray(p.x1),
                                         jnp.asarray(p.dt))
    assert all(np.all(np.isfinite(g)) for g in jax.tree.leaves(grads))
