"""Zoo systems heat-exchange, relaxing-rigid-body, spinning-satellite, stiff-thermal-oscillator,
oscillator-family: exact GENERIC structure, the equations of motion written out by hand, and generated data."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from helpers import assert_exactly_generic
from metriplex import MetriplexError
from metriplex.systems import generate
from metriplex.systems.zoo import (
    heat_exchange,
    oscillator_family,
    relaxing_rigid_body,
    spinning_satellite,
    stiff_thermal_oscillator,
)

MODULES = {
    "heat-exchange": heat_exchange,
    "relaxing-rigid-body": relaxing_rigid_body,
    "spinning-satellite": spinning_satellite,
    "stiff-thermal-oscillator": stiff_thermal_oscillator,
    "oscillator-family": oscillator_family,
}

# Bound on max_t |E(t) - E(0)| / |E(0)| along the generated (RK4) data; measured (2 trajectories,
# seed 0, the case's steps and dt): 2e-15, 2e-14, 1e-14, 1.5e-10 (the stiff conduction, at
# h * rate = 0.1 per RK4 substep, dominates it), 3.0e-11 (oscillator-family).
ENERGY_DRIFT = {
    "heat-exchange": 1e-13,
    "relaxing-rigid-body": 1e-12,
    "spinning-satellite": 1e-12,
    "stiff-thermal-oscillator": 1e-9,
    "oscillator-family": 1e-10,
}


def batched(fn):
    """``fn`` mapped over a leading axis, compiled once (eager vmap compiles op by op)."""
    return jax.jit(jax.vmap(fn))


def case(name):
    return MODULES[name].CASE


@functools.cache
def data(name: str) -> np.ndarray:
    """Two generated trajectories over the case's full horizon, shape (2, steps + 1, n)."""
    c = case(name)
    out = generate(c.system, trajectories=2, steps=c.steps, dt=c.dt, seed=0)
    assert out.names == c.system.names
    return np.asarray(out.x).reshape(2, c.steps + 1, c.system.n)


@functools.cache
def states(name: str) -> jnp.ndarray:
    """64 states: 32 sampled initial states and 32 spread along the generated trajectories."""
    s = case(name).system
    sampled = s.sample_initial(32, seed=1)
    along = data(name).reshape(-1, s.n)
    along = along[np.linspace(0, len(along) - 1, 32).astype(int)]
    return jnp.asarray(np.concatenate([sampled, along]))


@functools.cache
def terms(name: str):
    t = batched(case(name).system.model.terms)(states(name))
    return tuple(np.asarray(a) for a in (t.poisson, t.friction, t.grad_energy, t.grad_entropy))


def _norm(a, axes):
    return np.sqrt(np.sum(a**2, axis=axes))


# -- structure ------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", MODULES)
def test_generic_structure(name):
    L, M, gE, gS = terms(name)
    assert np.all(_norm(M, (1, 2)) > 0.0)
    assert_exactly_generic(L, M, gE, gS)


@pytest.mark.parametrize("name", MODULES)
def test_jacobi_identity(name):
    model = case(name).system.model
    x = states(name)[::2]
    residual = np.asarray(batched(model.jacobi_tensor)(x))
    L = np.asarray(batched(model.poisson_matrix)(x))
    dL = np.asarray(batched(jax.jacfwd(model.poisson_matrix))(x))
    n = x.shape[1]
    # Each entry of the residual is a sum of 3n products d_k L^{ij} L^{kl}.
    scale = 3 * n * np.max(np.abs(dL), axis=(1, 2, 3)) * np.max(np.abs(L), axis=(1, 2))
    assert np.all(np.max(np.abs(residual), axis=(1, 2, 3)) <= 1e-10 * scale)


# -- explicit equations of motion -----------------------------------------------------------------
def _heat_exchange(c, x):
    T = c.temperature * np.exp((x - np.asarray(c.entropy_offset)) / np.asarray(c.heat_capacity))
    T1, T2 = T[:, 0], T[:, 1]
    return np.stack([c.kappa * (T2 / T1 - 1.0), c.kappa * (T1 / T2 - 1.0)], axis=1)


def _relaxing_rigid_body(c, m):
    omega = m / np.asarray(c.inertia)
    w2 = np.sum(omega**2, axis=1, keepdims=True)
    om = np.sum(omega * m, axis=1, keepdims=True)
    return np.cross(m, omega) - c.kappa * c.gamma * (w2 * m - om * omega)


def _spinning_satellite(c, x):
    m, s = x[:, :3], x[:, 3]
    omega = m / np.asarray(c.inertia)
    mxo = np.cross(m, omega)
    theta = c.theta0 * np.exp(s / c.heat_capacity)
    dm = mxo + c.damping * np.cross(m, mxo)
    ds = c.damping * np.sum(mxo**2, axis=1) / theta
    return np.concatenate([dm, ds[:, None]], axis=1)


def _stiff_thermal_oscillator(c, x):
    q, p = x[:, 0], x[:, 1]
    v = p / c.mass
    th1, th2 = (c.theta0 * np.exp(x[:, 2 + i] / c.heat_capacity[i]) for i in range(2))
    dp = -c.stiffness * q - c.quartic * q**3 - c.friction * v
    ds1 = c.friction * v**2 / th1 + c.kappa * (th2 / th1 - 1.0)
    ds2 = c.kappa * (th1 / th2 - 1.0)
    return np.stack([v, dp, ds1, ds2], axis=1)


def _oscillator_family(c, x):
    q, p, s, k = x.T
    v = p / c.mass
    theta = c.theta0 * np.exp(s / c.heat_capacity)
    dp = -k * q - c.quartic * q**3 - c.damping * v
    return np.stack([v, dp, c.damping * v**2 / theta, np.zeros_like(k)], axis=1)


EXPLICIT = {
    "heat-exchange": _heat_exchange,
    "relaxing-rigid-body": _relaxing_rigid_body,
    "spinning-satellite": _spinning_satellite,
    "stiff-thermal-oscillator": _stiff_thermal_oscillator,
    "oscillator-family": _oscillator_family,
}


@pytest.mark.parametrize("name", MODULES)
def test_equations_of_motion(name):
    s = case(name).system
    x = states(name)
    f = np.asarray(batched(s.model.vector_field)(x))
    expected = EXPLICIT[name](s.config, np.asarray(x))
    scale = np.max(np.abs(expected), axis=0, keepdims=True)
    scale = np.where(scale > 0.0, scale, 1.0)  # a rate that is zero everywhere: absolute
    np.testing.assert_allclose(f / scale, expected / scale, rtol=0.0, atol=1e-12)


# -- generated data -------------------------------------------------------------------------------
@pytest.mark.parametrize("name", MODULES)
def test_trajectory_conserves_energy_and_produces_entropy(name):
    model = case(name).system.model
    x = jnp.asarray(data(name))
    E = np.asarray(jax.jit(jax.vmap(jax.vmap(model.energy)))(x))
    S = np.asarray(jax.jit(jax.vmap(jax.vmap(model.entropy)))(x))
    drift = np.max(np.abs(E - E[:, :1]) / np.abs(E[:, :1]))
    assert drift <= ENERGY_DRIFT[name]
    assert np.all(np.diff(S, axis=1) >= -1e-13 * np.max(np.abs(S)))
    # Dissipation is visible: S rises over the horizon, though not all within the first 5 %.
    gain = S[:, -1] - S[:, 0]
    early = S[:, len(S[0]) // 20] - S[:, 0]
    assert np.all(gain > 0.0) and np.all(early < 0.6 * gain)


def test_case_settings():
    for name, module in MODULES.items():
        c = module.CASE
        assert c.name == name and c.system.name == name
        d = c.system.defaults
        assert (d.dt, d.steps, d.trajectories) == (c.dt, c.steps, c.trajectories)
        assert c.held_out == (name in ("heat-exchange", "stiff-thermal-oscillator",
                                       "oscillator-family"))
    assert stiff_thermal_oscillator.CASE.system.config.stiffness_ratio >= 50.0


# -- configuration errors -------------------------------------------------------------------------
def test_config_validation():
    with pytest.raises(MetriplexError, match="positive heat capacities"):
        heat_exchange.HeatExchangeConfig(kappa=-1.0)
    with pytest.raises(MetriplexError, match="basin of the m1 axis"):
        relaxing_rigid_body.RelaxingRigidBodyConfig(center=(1.0, 0.0, 0.0))
    with pytest.raises(MetriplexError, match="I3 the strictly largest"):
        spinning_satellite.SpinningSatelliteConfig(inertia=(1000.0, 900.0, 800.0))
    with pytest.raises(MetriplexError, match="imbalance"):
        stiff_thermal_oscillator.StiffThermalOscillatorConfig(imbalance=0.7)
    with pytest.raises(MetriplexError, match=r"every initial stiffness > 0.*x0_center\[3\]=1"):
        oscillator_family.OscillatorFamilyConfig(x0_center=(0.0, 0.0, 0.0, 1.0))
    with pytest.raises(MetriplexError, match="positive mass"):
        oscillator_family.OscillatorFamilyConfig(mass=0.0)


def test_the_family_parameter_is_constant_along_each_trajectory_and_differs_between_them():
    k = data("oscillator-family")[..., 3]
    assert np.all(k == k[:, :1]) and k[0, 0] != k[1, 0]
    assert generate("oscillator-family", trajectories=3, steps=10, dt=0.02,
                    seed=0).constant_variables() == (3,)


def test_config_validation_of_the_stiff_case():
    with pytest.raises(MetriplexError, match="has no parameter"):
        stiff_thermal_oscillator.CASE.system.with_params(conductance=1.0)
