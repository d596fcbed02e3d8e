"""Small known systems for tests (the full reference systems live in metriplex.systems)."""

import jax.numpy as jnp
import jax.random as jr
import numpy as np

import metriplex as mx

INERTIA = jnp.array([10.0, 20.0, 40.0])


def lie_poisson(m):
    return jnp.array([[0.0, -m[2], m[1]], [m[2], 0.0, -m[0]], [-m[1], m[0], 0.0]])


def rigid_body() -> mx.GenericModel:
    return mx.GenericModel(
        mx.Known(lambda m: 0.5 * jnp.sum(m**2 / INERTIA)),
        mx.ZeroPotential(),
        mx.KnownPoisson(lie_poisson),
        mx.ZeroFriction(3),
    )


def damped_oscillator(kappa: float = 0.3) -> mx.GenericModel:
    """(q, p, s): E = (q^2 + p^2)/2 + s, S = s, friction moves kinetic energy into s.

    M = kappa * w w^T with w = (0, 1, -p): then M grad E = kappa w (w . (q, p, 1)) = 0 and
    dS/dt = kappa p^2 >= 0.
    """

    def friction(x):
        w = jnp.array([0.0, 1.0, -x[1]])
        return kappa * jnp.outer(w, w)

    return mx.GenericModel(
        mx.Known(lambda x: 0.5 * (x[0] ** 2 + x[1] ** 2) + x[2]),
        mx.SumOf((2,)),
        mx.CanonicalPoisson(3, 1),
        mx.KnownFriction(friction),
    )


def make_data(model, x0, dt, steps, names=()):
    ts = jnp.arange(steps + 1.0) * dt
    xs = mx.simulate(model, jnp.asarray(x0), ts)
    return mx.Trajectories.from_arrays(np.asarray(ts), np.asarray(xs), names)


def rigid_x0(k, seed=0):
    return np.asarray(jr.normal(jr.key(seed), (k, 3)))


def oscillator_x0(k, seed=0):
    return np.asarray(jr.uniform(jr.key(seed), (k, 3), minval=-1.0, maxval=1.0))
