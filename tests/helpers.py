"""Small known systems for tests (the full reference systems live in metriplex.systems)."""

import functools

import jax.numpy as jnp
import jax.random as jr
import numpy as np

import metriplex as mx

INERTIA = jnp.array([10.0, 20.0, 40.0])


def lie_poisson(m):
    return jnp.array([[0.0, -m[2], m[1]], [m[2], 0.0, -m[0]], [-m[1], m[0], 0.0]])


# Each system is built once per process: its functions are static parts of every compiled call
# on it, so a model rebuilt for every test would have every test compile its rollouts anew.
@functools.cache
def rigid_body() -> mx.GenericModel:
    return mx.GenericModel(
        mx.Known(lambda m: 0.5 * jnp.sum(m**2 / INERTIA)),
        mx.ZeroPotential(),
        mx.KnownPoisson(lie_poisson),
        mx.ZeroFriction(3),
    )


@functools.cache
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


#: make_data simulates at least this many trajectories of this many steps and keeps the ones
#: asked for, so that the tests' data sets of a system share one compiled rollout.
SIMULATED_TRAJECTORIES, SIMULATED_STEPS = 32, 60


def make_data(model, x0, dt, steps, names=()):
    """``len(x0)`` trajectories of ``model`` from ``x0``, ``steps`` Crank–Nicolson steps of
    ``dt`` each.

    The rollout covers SIMULATED_STEPS steps (or more) and pads the batch with copies of the
    first state up to SIMULATED_TRAJECTORIES: a time step depends only on the ones before it,
    and a copy changes no decision the batched solver takes for the batch as a whole.
    """
    x0 = np.asarray(x0)
    k = len(x0)
    total = max(steps, SIMULATED_STEPS)
    padded = np.concatenate([x0, np.repeat(x0[:1], max(SIMULATED_TRAJECTORIES - k, 0), 0)])
    ts = jnp.arange(total + 1.0) * dt
    xs = np.asarray(mx.simulate(model, jnp.asarray(padded), ts))[:k, : steps + 1]
    return mx.Trajectories.from_arrays(np.asarray(ts)[: steps + 1], xs, names)


def rigid_x0(k, seed=0):
    return np.asarray(jr.normal(jr.key(seed), (k, 3)))


def oscillator_x0(k, seed=0):
    return np.asarray(jr.uniform(jr.key(seed), (k, 3), minval=-1.0, maxval=1.0))


def oscillator_data(k=8, n_t=21, names=("q", "p", "s")) -> mx.Trajectories:
    """``k`` smooth trajectories of ``n_t`` states (q, p, s), made with NumPy alone (no JAX
    compilation)."""
    t = np.arange(n_t) * 0.1
    return mx.Trajectories.from_list(
        [(t, np.c_[np.cos(t + j), -np.sin(t + j), 0.01 * t + 0.1 * j]) for j in range(k)], names)


#: The options of the session's shared training run (``trained_run`` in conftest.py): 20 steps
#: on 6 of the 8 trajectories of ``oscillator_data()``, 4 and 5 validating.
TRAINED_RUN_OPTIONS = ("--entropy", "sum:2", "--poisson", "canonical:1", "--width", "8",
                       "--steps", "20", "--trajectories", "0-5", "--validation-ids", "4,5",
                       "--quiet")


def assert_exactly_generic(L, M, grad_energy, grad_entropy) -> np.ndarray:
    """Check a batch of GENERIC terms (``L``, ``M`` of shape (b, n, n), the gradients (b, n))
    to rounding: L antisymmetric and M symmetric exactly, M positive semi-definite, L grad S = 0
    and M grad E = 0 relative to the size of the products' terms (honest at 1e-12 even with
    states ~1e4), and dS/dt = grad S . M grad S >= 0. Returns the entropy production per state."""
    L, M, gE, gS = (np.asarray(a, np.float64) for a in (L, M, grad_energy, grad_entropy))
    np.testing.assert_array_equal(L, -np.swapaxes(L, 1, 2))
    np.testing.assert_array_equal(M, np.swapaxes(M, 1, 2))
    norm_M = np.linalg.norm(M, axis=(1, 2))
    assert np.all(np.linalg.eigvalsh(M)[:, 0] >= -1e-12 * norm_M)
    LgS = np.linalg.norm(np.einsum("bij,bj->bi", L, gS), axis=1)
    MgE = np.linalg.norm(np.einsum("bij,bj->bi", M, gE), axis=1)
    assert np.all(LgS <= 1e-12 * np.linalg.norm(L, axis=(1, 2)) * np.linalg.norm(gS, axis=1))
    assert np.all(MgE <= 1e-12 * norm_M * np.linalg.norm(gE, axis=1))
    production = np.einsum("bi,bij,bj->b", gS, M, gS)
    assert np.all(production >= -1e-13 * norm_M * np.sum(gS**2, axis=1))
    return production
