"""Defaults checked on systems outside the zoo: none of them was used to choose a default.

    .venv/bin/python benchmarks/outside_zoo.py                       # all ten, one by one
    .venv/bin/python benchmarks/outside_zoo.py --cases point-vortices --out rows.json

Each case is trained as `benchmarks/zoo.py` trains a zoo case (`zoo.run_case`: the structure
flags a user who knows the system would give, every other setting at its default), beside an
unconstrained field on the same data (`zoo.black_box`). The table adds the standardised error
of the true model rolled out by Crank-Nicolson at the data's step, which says how much of an
error the step itself makes:

- **double-well-bath** (n = 3): a particle in a double well whose friction heats a bath;
  canonical L, S = s given.
- **lotka-volterra** (n = 2): predator and prey in thousands (offsets ~1e3), time in years;
  L = xy [[0, -1], [1, 0]] non-canonical, learned; no S, no M.
- **point-vortices** (n = 6): three point vortices of strengths 1, 2, -0.7 in the plane;
  L constant and non-canonical (1/Gamma_i blocks), learned; E logarithmic; no S, no M.
- **elastic-pendulum** (n = 4): a spring pendulum in polar coordinates (r, theta, p_r,
  p_theta); canonical L given, position-dependent kinetic energy p_theta^2 / (2 r^2).
- **reaction-heat** (n = 4, added 2026-11-28 after the four above were run): two reactions
  in a solution, A <=> B and B + B <=> C, with mass-action rates (one bimolecular), whose
  released energy heats the solvent: amounts in mol (~1e-2), entropy in J/K (~100, moving by
  ~0.1), seconds; L = 0 and S = s given, E and M learned.
- **conduction-ring** (n = 8, added with reaction-heat): eight cells of different heat
  capacities in a ring, each conducting to its two neighbours with a conductance that grows
  with temperature; minutes, entropies offset by 5; L = 0 and S = sum of the s_i given, E
  and M learned (the zoo's only other L = 0 case has two variables).
- **two-baths**, **cart-pendulum**, **tidal-orbit** (n = 6, 4, 5; in `_outside_more.py`,
  added after the six above were run): two coupled oscillators each heating its own bath, the
  baths conducting (seconds, periods of 10-25 ms); a pendulum on a sliding cart (cart near
  x = 120 m); an orbit in a softened potential (km, s) circularised by radial friction.
- **oscillator-network** (n = 14, in `_outside_more.py`; added 2026-12-07 from a new-user
  check): six hardening oscillators, random all-to-all couplings, two damped into own baths.

Results: docs/zoo.md, *Outside the zoo*.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402

import zoo  # noqa: E402
from metriplex.config import scheme_from_name  # noqa: E402
from metriplex.structure import (CanonicalPoisson, SumOf, ZeroFriction, ZeroPoisson,  # noqa: E402
                                 ZeroPotential)
from metriplex.systems import generate  # noqa: E402
from metriplex.systems._base import BoxSampling, System, analytic_model  # noqa: E402
from metriplex.systems.zoo import ZooCase  # noqa: E402
from metriplex.systems.zoo._case import case_settings  # noqa: E402
from metriplex.systems.zoo._parts import bath_energy, bath_temperature  # noqa: E402
from _outside_more import CartPendulum, OscillatorNetwork, TidalOrbit, TwoBaths  # noqa: E402


# -- a double well whose friction heats a bath ---------------------------------------------------
@dataclasses.dataclass(frozen=True)
class DoubleWellConfig:
    """E = p^2/2 - q^2/2 + q^4/4 + c theta0 (exp((s - s0)/c) - 1), friction gamma."""

    damping: float = 0.05
    heat_capacity: float = 5.0
    theta0: float = 2.0
    s0: float = 10.0
    x0_center: tuple[float, float, float] = (0.0, 0.0, 10.0)
    x0_halfwidth: tuple[float, float, float] = (1.6, 0.8, 0.5)


def _bath_temperature(c: DoubleWellConfig, s):
    return c.theta0 * jnp.exp((s - c.s0) / c.heat_capacity)


def _double_well_energy(c: DoubleWellConfig, x):
    q, p, s = x
    bath = c.heat_capacity * c.theta0 * (jnp.exp((s - c.s0) / c.heat_capacity) - 1.0)
    return p**2 / 2 - q**2 / 2 + q**4 / 4 + bath


def _double_well_friction(c: DoubleWellConfig, x):
    # (gamma / theta) w w^T with w = (0, theta, -p): M grad E = 0, s' = gamma p^2 / theta.
    theta = _bath_temperature(c, x[2])
    w = jnp.stack([jnp.zeros_like(x[1]), theta, -x[1]])
    return (c.damping / theta) * (w[:, None] * w[None, :])


@dataclasses.dataclass(frozen=True)
class DoubleWellBath(BoxSampling, System):
    name = "double-well-bath"
    description = "a double well whose friction heats a bath"
    names = ("q", "p", "s")
    defaults = case_settings(dt=0.1, steps=300, trajectories=30)
    max_substep = 0.005
    config: DoubleWellConfig = DoubleWellConfig()

    def _build_model(self):
        return analytic_model(self.config, energy=_double_well_energy, entropy=SumOf((2,)),
                              poisson=CanonicalPoisson(3, 1), friction=_double_well_friction)


# -- predator and prey ---------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class LotkaVolterraConfig:
    """u = prey / unit, v = predator / unit; E = a (u - log u) + b (v - 2 log v) and
    L = x y [[0, -1], [1, 0]]: prey' = b prey (2 - v), predator' = a predator (u - 1)."""

    a: float = 1.0
    b: float = 0.5
    unit: float = 1.0e3
    x0_center: tuple[float, float] = (2.0e3, 1.0e3)
    x0_halfwidth: tuple[float, float] = (0.8e3, 0.5e3)


def _lotka_volterra_energy(c: LotkaVolterraConfig, x):
    u, v = x[0] / c.unit, x[1] / c.unit
    return c.a * (u - jnp.log(u)) + c.b * (v - 2.0 * jnp.log(v))


def _lotka_volterra_poisson(c: LotkaVolterraConfig, x):
    return jnp.array([[0.0, -1.0], [1.0, 0.0]], x.dtype) * (x[0] * x[1])


@dataclasses.dataclass(frozen=True)
class LotkaVolterra(BoxSampling, System):
    name = "lotka-volterra"
    description = "predator and prey (thousands, years): non-canonical L"
    names = ("prey", "predator")
    defaults = case_settings(dt=0.02, steps=400, trajectories=20)
    max_substep = 0.001
    config: LotkaVolterraConfig = LotkaVolterraConfig()

    def _build_model(self):
        return analytic_model(self.config, energy=_lotka_volterra_energy,
                              entropy=ZeroPotential(), poisson=_lotka_volterra_poisson,
                              friction=ZeroFriction(2))


# -- three point vortices ------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class VorticesConfig:
    """Strengths Gamma_i; state (x1, y1, x2, y2, x3, y3)."""

    strengths: tuple[float, float, float] = (1.0, 2.0, -0.7)
    x0_center: tuple[float, ...] = (1.0, 0.0, -0.5, 0.8, -0.4, -1.0)
    x0_halfwidth: tuple[float, ...] = (0.15,) * 6


def _vortex_energy(c: VorticesConfig, x):
    g, xs, ys = c.strengths, x[0::2], x[1::2]
    return -sum(g[i] * g[j] * jnp.log((xs[i] - xs[j])**2 + (ys[i] - ys[j])**2)
                for i in range(3) for j in range(i + 1, 3)) / (4.0 * jnp.pi)


def _vortex_poisson(c: VorticesConfig, x):
    block = jnp.array([[0.0, 1.0], [-1.0, 0.0]], x.dtype)
    return jax.scipy.linalg.block_diag(*(block / g for g in c.strengths))


@dataclasses.dataclass(frozen=True)
class PointVortices(BoxSampling, System):
    name = "point-vortices"
    description = "three point vortices in the plane: constant non-canonical L"
    names = ("x1", "y1", "x2", "y2", "x3", "y3")
    defaults = case_settings(dt=0.05, steps=200, trajectories=25)
    max_substep = 0.002
    config: VorticesConfig = VorticesConfig()

    def _build_model(self):
        return analytic_model(self.config, energy=_vortex_energy, entropy=ZeroPotential(),
                              poisson=_vortex_poisson, friction=ZeroFriction(6))


# -- a spring pendulum ---------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class ElasticPendulumConfig:
    """Unit mass; spring constant k, rest length l0, gravity g."""

    stiffness: float = 40.0
    gravity: float = 9.81
    rest_length: float = 1.0
    x0_center: tuple[float, float, float, float] = (1.0, 0.0, 0.0, 0.0)
    x0_halfwidth: tuple[float, float, float, float] = (0.1, 0.5, 1.0, 1.0)


def _elastic_pendulum_energy(c: ElasticPendulumConfig, x):
    r, theta, p_r, p_theta = x
    return (p_r**2 / 2 + p_theta**2 / (2 * r**2) + c.stiffness * (r - c.rest_length)**2 / 2
            - c.gravity * r * jnp.cos(theta))


@dataclasses.dataclass(frozen=True)
class ElasticPendulum(BoxSampling, System):
    name = "elastic-pendulum"
    description = "a spring pendulum in polar coordinates: position-dependent kinetic energy"
    names = ("r", "theta", "p_r", "p_theta")
    defaults = case_settings(dt=0.02, steps=250, trajectories=30)
    max_substep = 0.001
    config: ElasticPendulumConfig = ElasticPendulumConfig()

    def _build_model(self):
        return analytic_model(self.config, energy=_elastic_pendulum_energy,
                              entropy=ZeroPotential(), poisson=CanonicalPoisson(4, 2),
                              friction=ZeroFriction(4))


# -- two reactions that heat their solvent -------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class ReactionConfig:
    """Amounts N = (N_A, N_B, N_C) in mol and the solvent's entropy s in J/K.

    E = sum_i N_i (e_i + a (log(N_i / n0) - 1)) + c theta0 (exp((s - s0) / c) - 1), so the
    chemical potentials are mu_i = e_i + a log(N_i / n0) and the temperature theta =
    theta0 exp((s - s0) / c); S = s. Reaction r of stoichiometry nu_r (A <=> B: (-1, 1, 0);
    B + B <=> C: (0, -2, 1)) has the affinity A_r = -nu_r . mu and the mass-action rate
    r_r = kappa_r (exp(X_r / a) - exp(Y_r / a)), X_r and Y_r the sums of n mu over its
    reactants and products (so A_r = X_r - Y_r and r_r A_r >= 0). GENERIC with L = 0 and
    M = sum_r (Lambda_r / theta) w_r w_r^T, w_r = (theta nu_r, A_r), Lambda_r = r_r / A_r:
    N' = sum_r r_r nu_r, s' = sum_r r_r A_r / theta.
    """

    a: float = 2500.0
    energies: tuple[float, float, float] = (0.0, -1250.0, -3750.0)
    n0: float = 0.01
    rates: tuple[float, float] = (5e-4, 3e-4)
    heat_capacity: float = 50.0
    theta0: float = 300.0
    s0: float = 100.0
    x0_center: tuple[float, float, float, float] = (0.02, 0.01, 0.006, 100.0)
    x0_halfwidth: tuple[float, float, float, float] = (0.01, 0.008, 0.005, 0.5)


_STOICHIOMETRY = ((-1.0, 1.0, 0.0), (0.0, -2.0, 1.0))


def _reaction_potentials(c: ReactionConfig, x):
    return jnp.asarray(c.energies, x.dtype) + c.a * jnp.log(x[:3] / c.n0)


def _reaction_energy(c: ReactionConfig, x):
    mu = _reaction_potentials(c, x)
    chemical = jnp.sum(x[:3] * (mu - c.a))
    return chemical + bath_energy(x[3] - c.s0, c.heat_capacity, c.theta0)


def _exp_ratio(y):
    """(exp(y) - 1) / y, 1 at y = 0 (and its derivative there too)."""
    small = jnp.abs(y) < 1e-6
    safe = jnp.where(small, 1.0, y)
    return jnp.where(small, 1.0 + y / 2.0, jnp.expm1(safe) / safe)


def _reaction_friction(c: ReactionConfig, x):
    mu = _reaction_potentials(c, x)
    theta = bath_temperature(x[3] - c.s0, c.heat_capacity, c.theta0)
    M = jnp.zeros((4, 4), x.dtype)
    for nu, kappa in zip(_STOICHIOMETRY, c.rates):
        nu = jnp.asarray(nu, x.dtype)
        Y = jnp.sum(jnp.maximum(nu, 0.0) * mu)  # products
        A = -jnp.dot(nu, mu)  # affinity, X - Y
        lam = kappa * jnp.exp(Y / c.a) * _exp_ratio(A / c.a) / c.a  # r / A >= 0
        w = jnp.concatenate([theta * nu, A[None]])
        M = M + (lam / theta) * jnp.outer(w, w)
    return M


@dataclasses.dataclass(frozen=True)
class ReactionHeat(BoxSampling, System):
    name = "reaction-heat"
    description = "two reactions (one bimolecular) whose released energy heats the solvent"
    names = ("N_A", "N_B", "N_C", "s")
    defaults = case_settings(dt=2.0, steps=150, trajectories=30)
    max_substep = 0.05
    config: ReactionConfig = ReactionConfig()

    def _build_model(self):
        return analytic_model(self.config, energy=_reaction_energy, entropy=SumOf((3,)),
                              poisson=ZeroPoisson(4), friction=_reaction_friction)


# -- a ring of heat-conducting cells ------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class RingConfig:
    """Cells i = 0..7 of heat capacity c_i in a ring; E = sum_i c_i theta0 (exp((s_i - s0) /
    c_i) - 1), so theta_i = theta0 exp((s_i - s0) / c_i); S = sum_i s_i. Neighbours i, j
    exchange the heat flux kappa_ij (theta_j - theta_i) with kappa_ij = kappa sqrt(theta_i
    theta_j) / theta0: M = sum_edges kappa_ij theta_i theta_j u u^T with u = e_i / theta_i -
    e_j / theta_j, so s_i' = sum_j kappa_ij (theta_j - theta_i) / theta_i."""

    heat_capacities: tuple[float, ...] = (1.0, 1.5, 0.8, 2.0, 1.2, 0.6, 1.8, 1.0)
    conductance: float = 0.05
    theta0: float = 300.0
    s0: float = 5.0
    x0_center: tuple[float, ...] = (5.0,) * 8
    x0_halfwidth: tuple[float, ...] = (0.1,) * 8


def _ring_temperatures(c: RingConfig, x):
    return bath_temperature(x - c.s0, jnp.asarray(c.heat_capacities, x.dtype), c.theta0)


def _ring_energy(c: RingConfig, x):
    return jnp.sum(bath_energy(x - c.s0, jnp.asarray(c.heat_capacities, x.dtype), c.theta0))


def _ring_friction(c: RingConfig, x):
    theta = _ring_temperatures(c, x)
    n = len(c.heat_capacities)
    M = jnp.zeros((n, n), x.dtype)
    for i in range(n):
        j = (i + 1) % n
        kappa = c.conductance * jnp.sqrt(theta[i] * theta[j]) / c.theta0
        u = jnp.zeros(n, x.dtype).at[i].set(1.0 / theta[i]).at[j].set(-1.0 / theta[j])
        M = M + kappa * theta[i] * theta[j] * jnp.outer(u, u)
    return M


@dataclasses.dataclass(frozen=True)
class ConductionRing(BoxSampling, System):
    name = "conduction-ring"
    description = "eight heat-conducting cells in a ring (minutes): L = 0, n = 8"
    names = tuple(f"s{i}" for i in range(8))
    defaults = case_settings(dt=1.0, steps=150, trajectories=30)
    max_substep = 0.05
    config: RingConfig = RingConfig()

    def _build_model(self):
        return analytic_model(self.config, energy=_ring_energy, entropy=SumOf(tuple(range(8))),
                              poisson=ZeroPoisson(8), friction=_ring_friction)


CASES = {c.name: c for c in (
    ZooCase.of(DoubleWellBath(), {"poisson": "canonical:1", "entropy": "sum:2"}),
    ZooCase.of(LotkaVolterra(), {"entropy": "zero", "friction": "zero"}, time_unit="yr"),
    ZooCase.of(PointVortices(), {"entropy": "zero", "friction": "zero"}),
    ZooCase.of(ElasticPendulum(), {"poisson": "canonical:2", "entropy": "zero",
                                   "friction": "zero"}),
    ZooCase.of(ReactionHeat(), {"poisson": "zero", "entropy": "sum:3"}, time_unit="s"),
    ZooCase.of(ConductionRing(), {"poisson": "zero", "entropy": "sum:0,1,2,3,4,5,6,7"},
               time_unit="min"),
    ZooCase.of(TwoBaths(), {"poisson": "canonical:2", "entropy": "sum:4,5"}),
    ZooCase.of(CartPendulum(), {"poisson": "canonical:2", "entropy": "zero", "friction": "zero"}),
    ZooCase.of(TidalOrbit(), {"poisson": "canonical:2", "entropy": "sum:4"}),
    ZooCase.of(OscillatorNetwork(), {"poisson": "canonical:6", "entropy": "sum:12,13"}),
)}


def truth_error(case: ZooCase, seed: int = 0) -> float:
    """The standardised rel. L2 of the true model rolled out by Crank-Nicolson at the case's
    step, on the test data that ``zoo.run_case`` draws."""
    test = generate(case.system, trajectories=case.test_trajectories, steps=case.horizon_steps,
                    dt=case.dt, seed=1000 + seed)
    return zoo.standardised_error(case.system.model, test, scheme_from_name("cn"))[0]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", default=",".join(CASES), help="comma list of " + ", ".join(CASES))
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default=None, help="write the rows to this JSON file")
    ap.add_argument("--verdict", action="store_true",
                    help="also give each trained model evaluate's verdict on the test data")
    ap.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE",
                    help="override a training setting (RunConfig field), e.g. scheme=hermite")
    args = ap.parse_args(argv)
    overrides = zoo.parse_overrides(args.set)
    jax.config.update("jax_enable_x64", True)  # ground truth in float64; training in float32
    names = [c.strip() for c in args.cases.split(",") if c.strip()]
    unknown = sorted(set(names) - set(CASES))
    if unknown:
        ap.error(f"--cases: unknown {unknown}; choose from {', '.join(CASES)}")
    rows = []
    print("| system | n | flags | standardised rel. L2 | failed | black box | true field, CN | "
          "train s |\n|---|---|---|---|---|---|---|---|")
    for name in names:
        case = CASES[name]
        row = zoo.run_case(case, overrides, Path(tempfile.mkdtemp()), seed=args.seed,
                           with_black_box=True, with_verdict=args.verdict)
        row["truth_cn_standardised"] = truth_error(case, args.seed)
        rows.append(row)
        box = row["black_box"]
        print(f"| {name} | {row['n']} | `{row['flags']}` | {row['rel_l2_standardised']:.3g} | "
              f"{row['failed']}/{row['test_trajectories']} | {box['standardised']:.3g} "
              f"({box['failed']} failed) | {row['truth_cn_standardised']:.3g} | "
              f"{row['train_seconds']:.0f} |", flush=True)
        if row["verdict"] is not None:
            v = row["verdict"]
            print(f"  verdict: {v['outcome']}: {v['statement']}", flush=True)
    if args.out:
        Path(args.out).write_text(json.dumps(rows, indent=1, default=str))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
