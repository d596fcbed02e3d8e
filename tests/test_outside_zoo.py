"""The systems of benchmarks/outside_zoo.py (defaults checked outside the zoo): exactly GENERIC,
and the equations their docstrings state."""

from __future__ import annotations

import sys
from pathlib import Path

import jax
import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "benchmarks"))

import outside_zoo  # noqa: E402
from helpers import assert_exactly_generic  # noqa: E402

NAMES = sorted(outside_zoo.CASES)


def _states(name: str) -> np.ndarray:
    return outside_zoo.CASES[name].system.sample_initial(16, seed=3)


@pytest.mark.parametrize("name", NAMES)
def test_each_system_is_exactly_generic(name):
    system = outside_zoo.CASES[name].system
    model = system.model
    x = _states(name)
    t = jax.jit(jax.vmap(model.terms))(x)
    assert_exactly_generic(t.poisson, t.friction, t.grad_energy, t.grad_entropy)
    L = np.asarray(t.poisson)
    jacobi = np.asarray(jax.jit(jax.vmap(model.jacobi_tensor))(x))
    dL = np.asarray(jax.jit(jax.vmap(jax.jacfwd(model.poisson_matrix)))(x))
    scale = x.shape[1] * np.max(np.abs(L)) * max(np.max(np.abs(dL)), 1.0)
    assert np.max(np.abs(jacobi)) <= 1e-10 * scale


def _field(name: str, x: np.ndarray) -> np.ndarray:
    model = outside_zoo.CASES[name].system.model
    return np.asarray(jax.jit(jax.vmap(model.vector_field))(x))


def test_the_stated_equations():
    x = _states("double-well-bath")
    c = outside_zoo.DoubleWellConfig()
    q, p, s = x.T
    theta = c.theta0 * np.exp((s - c.s0) / c.heat_capacity)
    expected = np.stack([p, q - q**3 - c.damping * p, c.damping * p**2 / theta], axis=1)
    np.testing.assert_allclose(_field("double-well-bath", x), expected, rtol=1e-12, atol=1e-12)

    x = _states("lotka-volterra")
    c = outside_zoo.LotkaVolterraConfig()
    u, v = x[:, 0] / c.unit, x[:, 1] / c.unit
    expected = np.stack([c.b * x[:, 0] * (2.0 - v), c.a * x[:, 1] * (u - 1.0)], axis=1)
    np.testing.assert_allclose(_field("lotka-volterra", x), expected, rtol=1e-12)

    x = _states("elastic-pendulum")
    c = outside_zoo.ElasticPendulumConfig()
    r, th, pr, pth = x.T
    expected = np.stack([pr, pth / r**2,
                         pth**2 / r**3 - c.stiffness * (r - c.rest_length) + c.gravity * np.cos(th),
                         -c.gravity * r * np.sin(th)], axis=1)
    np.testing.assert_allclose(_field("elastic-pendulum", x), expected, rtol=1e-12, atol=1e-12)

    # Point vortices: Gamma_i x_i' = dH/dy_i, Gamma_i y_i' = -dH/dx_i, with
    # H = -sum_{i<j} Gamma_i Gamma_j log(r_ij^2) / (4 pi): x_i' = -sum_j Gamma_j (y_i - y_j) /
    # (2 pi r_ij^2), y_i' = sum_j Gamma_j (x_i - x_j) / (2 pi r_ij^2).
    x = _states("point-vortices")
    g = np.asarray(outside_zoo.VorticesConfig().strengths)
    xs, ys = x[:, 0::2], x[:, 1::2]
    dx, dy = xs[:, :, None] - xs[:, None, :], ys[:, :, None] - ys[:, None, :]
    r2 = dx**2 + dy**2 + np.eye(3)  # the diagonal (i = j) is masked by dx = dy = 0
    u = -np.sum(g[None, None, :] * dy / (2 * np.pi * r2), axis=2)
    w = np.sum(g[None, None, :] * dx / (2 * np.pi * r2), axis=2)
    expected = np.stack([u, w], axis=2).reshape(len(x), 6)
    np.testing.assert_allclose(_field("point-vortices", x), expected, rtol=1e-10, atol=1e-12)

    # Two reactions that heat the solvent: mass action with the chemical potentials
    # mu_i = e_i + a log(N_i / n0), the released energy into s at the temperature theta.
    x = _states("reaction-heat")
    c = outside_zoo.ReactionConfig()
    mu = np.asarray(c.energies) + c.a * np.log(x[:, :3] / c.n0)
    theta = c.theta0 * np.exp((x[:, 3] - c.s0) / c.heat_capacity)
    r1 = c.rates[0] * (np.exp(mu[:, 0] / c.a) - np.exp(mu[:, 1] / c.a))
    r2 = c.rates[1] * (np.exp(2 * mu[:, 1] / c.a) - np.exp(mu[:, 2] / c.a))
    a1, a2 = mu[:, 0] - mu[:, 1], 2 * mu[:, 1] - mu[:, 2]
    expected = np.stack([-r1, r1 - 2 * r2, r2, (r1 * a1 + r2 * a2) / theta], axis=1)
    np.testing.assert_allclose(_field("reaction-heat", x), expected, rtol=1e-9, atol=1e-15)

    # A ring of cells: Fourier conduction between neighbours, s_i' = sum_j k_ij (T_j - T_i) / T_i
    # with k_ij = kappa sqrt(T_i T_j) / theta0.
    x = _states("conduction-ring")
    c = outside_zoo.RingConfig()
    T = c.theta0 * np.exp((x - c.s0) / np.asarray(c.heat_capacities))
    expected = np.zeros_like(x)
    for i in range(8):
        for j in ((i - 1) % 8, (i + 1) % 8):
            k = c.conductance * np.sqrt(T[:, i] * T[:, j]) / c.theta0
            expected[:, i] += k * (T[:, j] - T[:, i]) / T[:, i]
    np.testing.assert_allclose(_field("conduction-ring", x), expected, rtol=1e-9, atol=1e-14)

    # Two oscillators, two baths: p_i' = -k_i q_i -+ (kc d + a d^3) - g_i p_i with
    # g_i = gamma_i theta0 / theta_i; each bath gets its friction's heat and conducts to the other.
    x = _states("two-baths")
    c = outside_zoo.CASES["two-baths"].system.config
    q1, q2, p1, p2, s1, s2 = x.T
    t1 = c.theta0 * np.exp((s1 - c.s0) / c.heat_capacities[0])
    t2 = c.theta0 * np.exp((s2 - c.s0) / c.heat_capacities[1])
    g1, g2 = c.friction[0] * c.theta0 / t1, c.friction[1] * c.theta0 / t2
    d = q1 - q2
    f = c.coupling * d + c.coupling_quartic * d**3
    expected = np.stack([p1, p2, -c.stiffness[0] * q1 - f - g1 * p1,
                         -c.stiffness[1] * q2 + f - g2 * p2,
                         g1 * p1**2 / t1 + c.conductance * (t2 - t1) / t1,
                         g2 * p2**2 / t2 + c.conductance * (t1 - t2) / t2], axis=1)
    np.testing.assert_allclose(_field("two-baths", x), expected, rtol=1e-10, atol=1e-14)

    # A pendulum on a sliding cart, from its Lagrangian: the velocities solve A(phi) v = p, the
    # cart's momentum is conserved and p_phi' = dL/dphi = -m l sin(phi) (x' phi' + g).
    x = _states("cart-pendulum")
    c = outside_zoo.CASES["cart-pendulum"].system.config
    phi, m, ell = x[:, 1], c.bob_mass, c.length
    A = np.zeros((len(x), 2, 2))
    A[:, 0, 0], A[:, 1, 1] = c.cart_mass + m, m * ell**2
    A[:, 0, 1] = A[:, 1, 0] = m * ell * np.cos(phi)
    v = np.linalg.solve(A, x[:, 2:4, None])[:, :, 0]
    expected = np.stack([v[:, 0], v[:, 1], np.zeros(len(x)),
                         -m * ell * np.sin(phi) * (v[:, 0] * v[:, 1] + c.gravity)], axis=1)
    np.testing.assert_allclose(_field("cart-pendulum", x), expected, rtol=1e-10, atol=1e-13)

    # An orbit circularised by radial friction: p' = -mu q / (r^2 + eps^2)^(3/2) - gamma v_r q / r
    # with v_r = p . q / r, and s' = gamma v_r^2 / theta.
    x = _states("tidal-orbit")
    c = outside_zoo.CASES["tidal-orbit"].system.config
    q, p = x[:, 0:2], x[:, 2:4]
    r = np.linalg.norm(q, axis=1, keepdims=True)
    vr = np.sum(p * q, axis=1, keepdims=True) / r
    theta = c.theta0 * np.exp((x[:, 4] - c.s0) / c.heat_capacity)
    pdot = -c.mu * q / (r**2 + c.softening**2) ** 1.5 - c.friction * vr * q / r
    expected = np.concatenate([p, pdot, (c.friction * vr[:, 0]**2 / theta)[:, None]], axis=1)
    np.testing.assert_allclose(_field("tidal-orbit", x), expected, rtol=1e-10, atol=1e-15)
