"""Zoo systems (part A): exact GENERIC structure, explicit equations, generated data, cases.

oscillator-bath, double-pendulum-friction, charged-particle, thermoelastic-chain, rlc-circuit.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from helpers import assert_exactly_generic
from metriplex import MetriplexError
from metriplex.systems import generate
from metriplex.systems.zoo import ZooCase
from metriplex.systems.zoo import charged_particle as cp
from metriplex.systems.zoo import double_pendulum_friction as dpf
from metriplex.systems.zoo import oscillator_bath as ob
from metriplex.systems.zoo import rlc_circuit as rlc
from metriplex.systems.zoo import thermoelastic_chain as tc

MODULES = {m.CASE.name: m for m in (ob, dpf, cp, tc, rlc)}
NAMES = list(MODULES)


def batched(fn):
    """``fn`` mapped over a leading axis, compiled once (eager vmap compiles op by op)."""
    return jax.jit(jax.vmap(fn))


def case(name: str) -> ZooCase:
    return MODULES[name].CASE


@functools.cache
def data(name: str) -> np.ndarray:
    """Two generated trajectories of 40 steps at the case's dt, shape (2, 41, n)."""
    c = case(name)
    out = generate(c.system, trajectories=2, steps=40, dt=c.dt, seed=0)
    assert out.names == c.system.names
    return out.x.reshape(2, 41, c.system.n)


@functools.cache
def states(name: str) -> jnp.ndarray:
    """48 states: 24 sampled initial states and 24 along the generated trajectories."""
    s = case(name).system
    along = data(name).reshape(-1, s.n)
    along = along[np.linspace(0, len(along) - 1, 24).astype(int)]
    return jnp.asarray(np.concatenate([s.sample_initial(24, seed=1), along]))


# -- structure ----------------------------------------------------------------------------------
@pytest.mark.parametrize("name", NAMES)
def test_generic_structure(name):
    model = case(name).system.model
    t = batched(model.terms)(states(name))
    production = assert_exactly_generic(t.poisson, t.friction, t.grad_energy, t.grad_entropy)
    assert np.max(production) > 0.0  # dissipation is switched on


@pytest.mark.parametrize("name", NAMES)
def test_jacobi_identity(name):
    model = case(name).system.model
    x = states(name)[::3]
    residual = np.asarray(batched(model.jacobi_tensor)(x))
    L = np.asarray(batched(model.poisson_matrix)(x))
    dL = np.asarray(batched(jax.jacfwd(model.poisson_matrix))(x))
    n = x.shape[1]
    # Each of the three terms is a sum of n products L * dL.
    scale = n * np.max(np.abs(L), axis=(1, 2)) * np.max(np.abs(dL), axis=(1, 2, 3))
    assert np.all(np.max(np.abs(residual), axis=(1, 2, 3)) <= 1e-10 * scale)
    if name == "charged-particle":
        assert np.all(scale > 0.0)  # a genuinely state-dependent bivector


def test_mirror_field_is_divergence_and_curl_free():
    c = cp.ChargedParticleConfig()
    x = states("charged-particle")
    J = np.asarray(batched(jax.jacfwd(lambda y: cp.magnetic_field(c, y)))(x))[:, :, :3]
    scale = np.max(np.abs(J))
    assert np.max(np.abs(np.trace(J, axis1=1, axis2=2))) <= 1e-14 * scale
    np.testing.assert_allclose(J, np.swapaxes(J, 1, 2), rtol=0.0, atol=1e-14 * scale)


# -- explicit equations ---------------------------------------------------------------------------
def _oscillator(c: ob.OscillatorBathConfig, x: np.ndarray) -> np.ndarray:
    q, p, s = x.T
    v = p / c.mass
    theta = c.theta0 * np.exp(s / c.heat_capacity)
    return np.stack(
        [v, -c.stiffness * q - c.quartic * q**3 - c.damping * v, c.damping * v**2 / theta], 1
    )


def _double_pendulum(c: dpf.DoublePendulumFrictionConfig, x: np.ndarray) -> np.ndarray:
    (m1, m2), (l1, l2), g = c.masses, c.lengths, c.gravity
    g1, g2 = c.friction
    out = []
    for f1, f2, p1, p2, s in x:
        mass = np.array([[(m1 + m2) * l1**2, m2 * l1 * l2 * np.cos(f1 - f2)],
                         [m2 * l1 * l2 * np.cos(f1 - f2), m2 * l2**2]])
        w1, w2 = np.linalg.solve(mass, [p1, p2])
        # d/dphi_i of p^T M^-1 p / 2 at fixed p is -w^T (dM/dphi_i) w / 2.
        coupling = m2 * l1 * l2 * w1 * w2 * np.sin(f1 - f2)
        tau1, tau2 = g1 * w1 - g2 * (w2 - w1), g2 * (w2 - w1)  # friction torques
        theta = c.theta0 * np.exp(s / c.heat_capacity)
        out.append([w1, w2, -(m1 + m2) * g * l1 * np.sin(f1) - coupling - tau1,
                    -m2 * g * l2 * np.sin(f2) + coupling - tau2,
                    (g1 * w1**2 + g2 * (w2 - w1) ** 2) / theta])
    return np.asarray(out)


def _charged(c: cp.ChargedParticleConfig, x: np.ndarray) -> np.ndarray:
    xi = x[:, :3] - np.array([0.0, 0.0, c.z0])
    v = x[:, 3:6] / c.mass
    X, Y, Z = xi.T
    B = c.b0 * np.stack(
        [-X * Z, -Y * Z, c.mirror_length**2 + Z**2 - (X**2 + Y**2) / 2], 1
    ) / c.mirror_length**2
    theta = c.theta0 * np.exp(x[:, 6] / c.heat_capacity)
    dp = c.charge * np.cross(v, B) - c.stiffness * xi - c.drag * v
    ds = c.drag * np.sum(v**2, 1) / theta
    return np.concatenate([v, dp, ds[:, None]], 1)


def _chain(c: tc.ThermoelasticChainConfig, x: np.ndarray) -> np.ndarray:
    N = c.particles
    q, p, s = x[:, :N], x[:, N : 2 * N], x[:, 2 * N :]
    v = p / c.mass
    theta = c.theta0 * np.exp(s / c.heat_capacity)
    walls = np.zeros((len(x), 1))
    r = np.diff(np.concatenate([walls, q, walls], 1), axis=1)  # r[:, j] = q_j - q_{j-1}
    tension = c.stiffness * r + c.quartic * r**3
    dp = tension[:, 1:] - tension[:, :-1] - c.friction * v
    heat = c.friction * v**2
    heat[:, :-1] += c.conductivity * (theta[:, 1:] - theta[:, :-1])
    heat[:, 1:] += c.conductivity * (theta[:, :-1] - theta[:, 1:])
    return np.concatenate([v, dp, heat / theta], 1)


def _rlc(c: rlc.RLCCircuitConfig, x: np.ndarray) -> np.ndarray:
    Q, Phi, s = x.T
    current = Phi / c.inductance
    theta = c.theta0 * np.exp(s / c.heat_capacity)
    voltage = Q / c.capacitance + c.nonlinearity * Q**3
    return np.stack(
        [current, -voltage - c.resistance * current, c.resistance * current**2 / theta], 1
    )


EXPLICIT = {
    "oscillator-bath": _oscillator,
    "double-pendulum-friction": _double_pendulum,
    "charged-particle": _charged,
    "thermoelastic-chain": _chain,
    "rlc-circuit": _rlc,
}


@pytest.mark.parametrize("name", NAMES)
def test_vector_field_is_the_explicit_equations(name):
    s = case(name).system
    x = states(name)
    f = np.asarray(batched(s.model.vector_field)(x))
    expected = EXPLICIT[name](s.config, np.asarray(x))
    scale = np.max(np.abs(expected), axis=0, keepdims=True)
    np.testing.assert_allclose(f / scale, expected / scale, rtol=0.0, atol=1e-12)


# -- generated data -------------------------------------------------------------------------------
@pytest.mark.parametrize("name", NAMES)
def test_generated_energy_conserved_entropy_nondecreasing(name):
    model = case(name).system.model
    xs = jnp.asarray(data(name))
    E = np.asarray(batched(batched(model.energy))(xs))
    S = np.asarray(batched(batched(model.entropy))(xs))
    assert np.max(np.abs(E - E[:, :1]) / np.abs(E[:, :1])) <= 1e-8
    assert np.min(np.diff(S, axis=1)) >= -1e-13 * np.max(np.abs(S))
    assert np.all(S[:, -1] > S[:, 0])


# -- cases, parameters ----------------------------------------------------------------------------
@pytest.mark.parametrize("name", NAMES)
def test_case_matches_the_system(name):
    c = case(name)
    s = c.system
    model = s.model
    assert c.name == s.name == name and len(s.names) == s.n and s.description
    assert (s.defaults.dt, s.defaults.steps, s.defaults.trajectories) == (
        c.dt, c.steps, c.trajectories)
    assert 20 <= c.trajectories <= 50 and 100 <= c.steps <= 300 and c.test_trajectories == 10
    assert c.held_out == (name in {"double-pendulum-friction", "rlc-circuit"})
    entropy = c.flags["entropy"]
    assert entropy.startswith("sum:")
    assert tuple(int(i) for i in entropy[4:].split(",")) == model.entropy.indices
    if "poisson" in c.flags:
        assert c.flags["poisson"] == f"canonical:{model.poisson.pairs}"
    x0 = s.sample_initial(3, seed=5)
    assert x0.shape == (3, s.n) and x0.dtype == np.float64
    np.testing.assert_array_equal(x0, s.sample_initial(3, seed=5))


@pytest.mark.parametrize(
    ("name", "params", "match"),
    [
        ("oscillator-bath", {"damping": -1.0}, r"non-negative quartic and damping; .*damping=-1"),
        ("double-pendulum-friction", {"masses": (1.0, 0.0)},
         r"positive masses and lengths; got masses=\(1.0, 0.0\)"),
        ("charged-particle", {"mirror_length": 0.0},
         r"parameters \['mirror_length'\] must be positive; got mirror_length=0.0"),
        ("thermoelastic-chain", {"particles": 1},
         r"particles must be an integer >= 2; got 1\. Example: particles=10"),
        ("rlc-circuit", {"inductance": -1e-3}, r"positive capacitance, inductance.*"
         r"inductance=-0.001"),
    ],
)
def test_config_validation(name, params, match):
    with pytest.raises(MetriplexError, match=match):
        case(name).system.with_params(**params)


def test_chain_size_is_a_parameter():
    s = tc.ThermoelasticChain().with_params(particles=3)
    assert s.n == 9 and s.names[:4] == ("q1", "q2", "q3", "p1")
    assert s.model.entropy.indices == (6, 7, 8)
    x = jnp.asarray(s.sample_initial(4, seed=0))
    f = np.asarray(batched(s.model.vector_field)(x))
    np.testing.assert_allclose(f, _chain(s.config, np.asarray(x)), rtol=1e-12, atol=1e-14)


def test_the_command_line_parses_parameters_and_the_systems_take_typed_values():
    from metriplex.app._option import system_params

    dpf = case("double-pendulum-friction").system
    assert system_params(["masses=1,2", "gravity=9.5", "nope=01"], dpf.config) == {
        "masses": (1.0, 2.0), "gravity": 9.5, "nope": "01"}  # an unknown name: as written
    chain = tc.ThermoelasticChain()
    assert system_params(["particles=3", "particles=2.5", "particles=x"], chain.config) == {
        "particles": "x"}  # the last of each name
    assert system_params(["particles=1e1"], chain.config) == {"particles": 10}
    # Text is parsed once, by the command line: the core takes numbers, not "1,2".
    with pytest.raises(MetriplexError, match=r"masses' must be a sequence of 2 numbers \(--param: "
                                             r"comma-separated\); got '1,2' \(str, not numbers\)"):
        dpf.with_params(masses="1,2")
    for bad, why in ((2.5, "not a whole number"), (np.float32(3.7), "not a whole number"),
                     (True, "bool, not numbers"), ("3", "str, not numbers")):
        with pytest.raises(MetriplexError, match=rf"particles' must be an integer; .*\({why}\)"):
            chain.with_params(particles=bad)
    assert chain.with_params(particles=np.int64(4)).config.particles == 4
