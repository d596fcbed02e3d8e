"""Three more systems outside the zoo (registered in ``outside_zoo.CASES``), written after the
six of ``outside_zoo.py`` were run and used for nothing else:

- **two-baths** (n = 6): two unit-mass oscillators of different stiffnesses, coupled by a
  spring with a quartic part, each damped by a viscous friction (its coefficient falling with
  the temperature, as a liquid's viscosity does) that heats its own bath; the two baths
  conduct heat to each other. Seconds, millimetre displacements, periods of 10-25 ms.
- **cart-pendulum** (n = 4): a pendulum hanging from a cart that slides freely on a
  horizontal track, with its position-dependent mass matrix; conservative; the cart near
  x = 120 m on the track (an offset).
- **tidal-orbit** (n = 5): a planar orbit in a softened central potential (km, s,
  mu = 3.986e5 km^3/s^2), whose radial velocity is damped by a friction that heats one body:
  the orbit circularises at constant angular momentum.
- **oscillator-network** (n = 14; added 2026-12-07 from new-user check 17, whose defaults
  gave 0.28 on it): six hardening oscillators with all-to-all random couplings, two of them
  damped, each heating its own bath; no cell structure.

Each parameter, step, number of steps and of trajectories was chosen from the true
trajectories only (periods, relaxation times, boundedness), before any training.
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp

from metriplex.structure import CanonicalPoisson, SumOf, ZeroFriction, ZeroPotential
from metriplex.systems._base import BoxSampling, System, analytic_model
from metriplex.systems.zoo._case import case_settings
from metriplex.systems.zoo._parts import bath_energy, bath_temperature


# -- two oscillators, two baths ------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class TwoBathsConfig:
    """State (q1, q2, p1, p2, s1, s2): displacements (m), momenta (kg m/s; unit masses) and the
    two baths' entropies (J/K); seconds.

    E = sum_i (p_i^2 / 2 + k_i q_i^2 / 2) + kc d^2 / 2 + a d^4 / 4 + sum_i c_i theta0 (exp((s_i
    - s0) / c_i) - 1), d = q1 - q2, so theta_i = theta0 exp((s_i - s0) / c_i); S = s1 + s2;
    L canonical in (q, p). M = sum_i (g_i / theta_i) w_i w_i^T + kappa theta1 theta2 u u^T with
    w_i = theta_i e_{p_i} - p_i e_{s_i}, u = e_{s1} / theta1 - e_{s2} / theta2 and the friction
    coefficient g_i = gamma_i theta0 / theta_i:
    q_i' = p_i, p_i' = -k_i q_i -+ (kc d + a d^3) - g_i p_i,
    s1' = g_1 p1^2 / theta1 + kappa (theta2 - theta1) / theta1, and s2' likewise.
    """

    stiffness: tuple[float, float] = (6.3e4, 1.2e5)  # N/m: 251 and 346 rad/s alone
    coupling: float = 2.0e4  # N/m
    coupling_quartic: float = 2.0e9  # N/m^3
    friction: tuple[float, float] = (10.0, 5.0)  # 1/s at theta0
    heat_capacities: tuple[float, float] = (3.0e-3, 5.0e-3)  # J/K
    conductance: float = 2.0e-2  # W/K
    theta0: float = 300.0
    s0: float = 1.0
    x0_center: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, 1.0, 1.0)
    x0_halfwidth: tuple[float, ...] = (2.0e-3, 2.0e-3, 0.5, 0.5, 3.0e-4, 5.0e-4)


def _two_baths_temperatures(c: TwoBathsConfig, x):
    return bath_temperature(x[4:6] - c.s0, jnp.asarray(c.heat_capacities, x.dtype), c.theta0)


def _two_baths_energy(c: TwoBathsConfig, x):
    q, p = x[0:2], x[2:4]
    k = jnp.asarray(c.stiffness, x.dtype)
    d = q[0] - q[1]
    baths = bath_energy(x[4:6] - c.s0, jnp.asarray(c.heat_capacities, x.dtype), c.theta0)
    return (jnp.sum(p**2 + k * q**2) / 2 + c.coupling * d**2 / 2 + c.coupling_quartic * d**4 / 4
            + jnp.sum(baths))


def _two_baths_friction(c: TwoBathsConfig, x):
    theta = _two_baths_temperatures(c, x)
    M = jnp.zeros((6, 6), x.dtype)
    for i in range(2):
        g = c.friction[i] * c.theta0 / theta[i]
        w = jnp.zeros(6, x.dtype).at[2 + i].set(theta[i]).at[4 + i].set(-x[2 + i])
        M = M + (g / theta[i]) * jnp.outer(w, w)
    u = jnp.zeros(6, x.dtype).at[4].set(1.0 / theta[0]).at[5].set(-1.0 / theta[1])
    return M + c.conductance * theta[0] * theta[1] * jnp.outer(u, u)


@dataclasses.dataclass(frozen=True)
class TwoBaths(BoxSampling, System):
    name = "two-baths"
    description = "two coupled oscillators, each heating its own bath; the baths conduct"
    names = ("q1", "q2", "p1", "p2", "s1", "s2")
    defaults = case_settings(dt=4.0e-4, steps=300, trajectories=30)
    max_substep = 2.0e-5
    config: TwoBathsConfig = TwoBathsConfig()

    def _build_model(self):
        return analytic_model(self.config, energy=_two_baths_energy, entropy=SumOf((4, 5)),
                              poisson=CanonicalPoisson(6, 2), friction=_two_baths_friction)


# -- a pendulum on a sliding cart ----------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class CartPendulumConfig:
    """State (x, phi, p_x, p_phi): the cart's position on its track (m), the pendulum's angle
    from the downward vertical, and their conjugate momenta; SI units.

    Mass matrix A(phi) = [[m_c + m, m l cos phi], [m l cos phi, m l^2]];
    E = p^T A(phi)^{-1} p / 2 + m g l (1 - cos phi); L canonical; no S, no M:
    (x', phi') = A^{-1} p, p_x' = 0, p_phi' = -m l sin(phi) (x' phi' + g).
    """

    cart_mass: float = 2.0
    bob_mass: float = 1.0
    length: float = 0.5
    gravity: float = 9.81
    x0_center: tuple[float, float, float, float] = (120.0, 0.0, 0.0, 0.0)
    x0_halfwidth: tuple[float, float, float, float] = (0.5, 1.2, 0.5, 0.4)


def _cart_mass_matrix(c: CartPendulumConfig, x):
    """The entries (a, b, d) of the mass matrix [[a, b], [b, d]] and its determinant."""
    a = jnp.asarray(c.cart_mass + c.bob_mass, x.dtype)
    b = c.bob_mass * c.length * jnp.cos(x[1])
    d = jnp.asarray(c.bob_mass * c.length**2, x.dtype)
    return a, b, d, a * d - b**2


def _cart_pendulum_energy(c: CartPendulumConfig, x):
    a, b, d, det = _cart_mass_matrix(c, x)
    px, pphi = x[2], x[3]
    kinetic = (d * px**2 - 2.0 * b * px * pphi + a * pphi**2) / (2.0 * det)
    return kinetic + c.bob_mass * c.gravity * c.length * (1.0 - jnp.cos(x[1]))


@dataclasses.dataclass(frozen=True)
class CartPendulum(BoxSampling, System):
    name = "cart-pendulum"
    description = "a pendulum on a freely sliding cart: position-dependent mass matrix"
    names = ("x", "phi", "p_x", "p_phi")
    defaults = case_settings(dt=0.025, steps=240, trajectories=30)
    max_substep = 0.001
    config: CartPendulumConfig = CartPendulumConfig()

    def _build_model(self):
        return analytic_model(self.config, energy=_cart_pendulum_energy,
                              entropy=ZeroPotential(), poisson=CanonicalPoisson(4, 2),
                              friction=ZeroFriction(4))


# -- an orbit circularised by tidal friction -----------------------------------------------------
@dataclasses.dataclass(frozen=True)
class TidalOrbitConfig:
    """State (q1, q2, p1, p2, s): position (km), momentum per unit mass (km/s) and the body's
    entropy per unit mass; seconds.

    E = |p|^2 / 2 - mu / sqrt(|q|^2 + eps^2) + c theta0 (exp((s - s0) / c) - 1), theta =
    theta0 exp((s - s0) / c); S = s; L canonical in (q, p). Friction on the radial velocity
    v_r = p . q / |q|: M = (gamma / theta) w w^T, w = (0, 0, theta q / |q|, -v_r), so
    q' = p, p' = -mu q / (|q|^2 + eps^2)^(3/2) - gamma v_r q / |q|, s' = gamma v_r^2 / theta:
    the angular momentum q1 p2 - q2 p1 is conserved and the orbit circularises.
    """

    mu: float = 3.986e5  # km^3/s^2
    softening: float = 2.0e3  # km
    friction: float = 1.0e-4  # 1/s
    heat_capacity: float = 0.05
    theta0: float = 300.0
    s0: float = 0.0
    x0_center: tuple[float, ...] = (1.0e4, 0.0, 0.0, 6.0, 0.0)
    x0_halfwidth: tuple[float, ...] = (1.5e3, 1.5e3, 1.2, 0.8, 5.0e-3)


def _tidal_orbit_energy(c: TidalOrbitConfig, x):
    q, p = x[0:2], x[2:4]
    potential = -c.mu / jnp.sqrt(jnp.sum(q**2) + c.softening**2)
    return jnp.sum(p**2) / 2 + potential + bath_energy(x[4] - c.s0, c.heat_capacity, c.theta0)


def _tidal_orbit_friction(c: TidalOrbitConfig, x):
    q, p = x[0:2], x[2:4]
    theta = bath_temperature(x[4] - c.s0, c.heat_capacity, c.theta0)
    rhat = q / jnp.sqrt(jnp.sum(q**2))
    w = jnp.concatenate([jnp.zeros(2, x.dtype), theta * rhat, -jnp.dot(p, rhat)[None]])
    return (c.friction / theta) * jnp.outer(w, w)


@dataclasses.dataclass(frozen=True)
class TidalOrbit(BoxSampling, System):
    name = "tidal-orbit"
    description = "an orbit (km, s) in a softened potential circularised by radial friction"
    names = ("q1", "q2", "p1", "p2", "s")
    defaults = case_settings(dt=100.0, steps=250, trajectories=30)
    max_substep = 5.0
    config: TidalOrbitConfig = TidalOrbitConfig()

    def _build_model(self):
        return analytic_model(self.config, energy=_tidal_orbit_energy, entropy=SumOf((4,)),
                              poisson=CanonicalPoisson(5, 2), friction=_tidal_orbit_friction)


# -- six coupled oscillators, two baths -----------------------------------------------------------
def _network_couplings(n: int = 6, scale: float = 0.15, seed: int = 123) -> tuple[float, ...]:
    """A fixed random symmetric coupling matrix (zero diagonal), flattened row by row."""
    import numpy as np

    k = np.abs(np.random.default_rng(seed).normal(0.0, scale, (n, n)))
    k = np.triu(k, 1)
    return tuple(float(v) for v in (k + k.T).ravel())


@dataclasses.dataclass(frozen=True)
class OscillatorNetworkConfig:
    """State (q1..q6, p1..p6, s1, s2), unit masses; oscillators 1 and 2 are damped, each
    heating its own bath.

    E = sum_i (p_i^2 + w_i^2 q_i^2) / 2 + q_i^4 / 4 + sum_{i<j} K_ij (q_i - q_j)^2 / 2
    + sum_b c theta0 (exp(s_b / c) - 1), so theta_b = theta0 exp(s_b / c); S = s1 + s2;
    L canonical in (q, p); M = sum_b (g_b / theta_b) w_b w_b^T, w_b = theta_b e_{p_b} -
    p_b e_{s_b}: p_b' gains -g_b p_b and s_b' = g_b p_b^2 / theta_b.
    """

    frequencies_squared: tuple[float, ...] = (1.0, 1.06, 1.12, 1.18, 1.24, 1.3)
    couplings: tuple[float, ...] = _network_couplings()
    damping: tuple[float, float] = (0.3, 0.25)
    heat_capacity: float = 1.0
    theta0: float = 1.0
    x0_center: tuple[float, ...] = (0.0,) * 14
    x0_halfwidth: tuple[float, ...] = (1.0,) * 12 + (0.2, 0.2)


def _network_energy(c: OscillatorNetworkConfig, x):
    q, p, s = x[0:6], x[6:12], x[12:14]
    w2 = jnp.asarray(c.frequencies_squared, x.dtype)
    K = jnp.asarray(c.couplings, x.dtype).reshape(6, 6)
    d = q[:, None] - q[None, :]
    return (jnp.sum(p**2 + w2 * q**2) / 2 + jnp.sum(q**4) / 4 + jnp.sum(K * d**2) / 4
            + jnp.sum(bath_energy(s, c.heat_capacity, c.theta0)))


def _network_friction(c: OscillatorNetworkConfig, x):
    theta = bath_temperature(x[12:14], c.heat_capacity, c.theta0)
    M = jnp.zeros((14, 14), x.dtype)
    for b in range(2):
        w = jnp.zeros(14, x.dtype).at[6 + b].set(theta[b]).at[12 + b].set(-x[6 + b])
        M = M + (c.damping[b] / theta[b]) * jnp.outer(w, w)
    return M


@dataclasses.dataclass(frozen=True)
class OscillatorNetwork(BoxSampling, System):
    name = "oscillator-network"
    description = ("Six hardening oscillators, random all-to-all couplings; two damped, each "
                   "heating its own bath: canonical L in (q, p), S = s1 + s2.")
    names = tuple(f"q{i}" for i in range(1, 7)) + tuple(f"p{i}" for i in range(1, 7)) + (
        "s1", "s2")
    defaults = case_settings(dt=0.05, steps=200, trajectories=40)
    max_substep = 0.005
    config: OscillatorNetworkConfig = OscillatorNetworkConfig()

    def _build_model(self):
        return analytic_model(self.config, energy=_network_energy, entropy=SumOf((12, 13)),
                              poisson=CanonicalPoisson(14, 6), friction=_network_friction)
