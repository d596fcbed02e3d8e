"""Default settings on a stand-in for a published viscoelastic shear-flow dataset.

A peer project published a dataset of a viscoelastic (Oldroyd-B) fluid in plane Couette
flow: each trajectory is one fluid particle, a node of one flow simulation across the gap,
with five dimensionless variables (x, y, v, e, tau): its position along and across the flow
(y is constant along each trajectory), its velocity, its internal energy and the shear
component of its conformation tensor. Trajectories are split at random, 80 % to train and
20 % to test; the peer's network reaches a rel. L2 of about 0.0079 on the test trajectories.
The dataset is not shipped here, and its simulation parameters are not ours to copy: this
script builds a stand-in of the same shape from equations of our own choosing (below), and
trains on it as a user with that file and no knowledge of its structure would,
``metriplex train DATA --out RUN`` with no flag at all.

The stand-in: start-up plane Couette flow of an Oldroyd-B fluid, dimensionless, the lower
wall at rest and the upper one accelerated to speed 1 (``U(t) = tanh(t / T_RAMP)``).
Across the gap y in (0, 1):

    Re dv/dt   = d/dy (beta dv/dy + G tau),      G = (1 - beta) / Wi
    dtau/dt    = dv/dy - tau / Wi                 (c_xy of the conformation; c_yy = 1)
    de/dt      = (beta dv/dy + G tau) dv/dy       (the stress power: viscous heat plus
                                                   stored elastic energy)
    dx/dt      = v,   dy/dt = 0

solved by second-order finite differences on N interior nodes (``NODES``) and fine RK4
substeps; each node is one trajectory. With Re = 1, Wi = 1 and beta = 0.1 the elastic shear
waves (speed sqrt(G / Re) ~ 0.95) cross the gap a few times before the viscosity damps them,
so v overshoots and oscillates: more than a relaxation to the steady profile. The node's
state is not a closed system (its neighbours drive it): a model of it learns the map that the
one flow induces, as the peer's network does.

The table: plain rel. L2 over the whole horizon (as ``metriplex evaluate`` reports it), the
same up to a tenth of it, standardised rel. L2, failed rollouts, an unconstrained field
trained on the same data (``zoo.black_box``) and the trivial prediction x(t) = x(0).

```bash
python benchmarks/published_viscoelastic.py
python benchmarks/published_viscoelastic.py --set residual_metric=diagonal
```
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false")

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))

from published_pendulum import constant_prediction_error  # noqa: E402
from zoo import (  # noqa: E402
    _fmt,
    black_box,
    constant_drift,
    parse_overrides,
    train_and_test,
)

from metriplex.app.runs import trained_scheme  # noqa: E402
from metriplex.config import RunConfig  # noqa: E402
from metriplex.data import Trajectories  # noqa: E402

NAMES = ("x", "y", "v", "e", "tau")
PUBLISHED = 0.0079  # the peer's network on the real dataset (rel. L2 on its test trajectories)


@dataclasses.dataclass(frozen=True)
class Couette:
    """The flow's parameters: Reynolds and Weissenberg numbers, the solvent's share of the
    viscosity, the lid's ramp time; the grid and the sampling."""

    reynolds: float = 1.0
    weissenberg: float = 1.0
    beta: float = 0.1
    ramp: float = 0.1
    nodes: int = 100
    snapshots: int = 150
    dt: float = 1.0 / 30.0
    substeps: int = 100

    @property
    def y(self) -> np.ndarray:
        return np.arange(1, self.nodes + 1) / (self.nodes + 1)

    def rates(self, t: float, v: np.ndarray, tau: np.ndarray):
        """(dv/dt, dtau/dt, de/dt) at the nodes; the walls' velocities are 0 and U(t)."""
        h = 1.0 / (self.nodes + 1)
        g = (1.0 - self.beta) / self.weissenberg
        lid = np.tanh(t / self.ramp)
        walls = np.concatenate([[0.0], v, [lid]])
        # the shear rate and stress on the faces between nodes (and walls), then at the nodes
        rate_faces = np.diff(walls) / h  # N + 1 faces
        tau_faces = np.concatenate([[tau[0]], 0.5 * (tau[1:] + tau[:-1]), [tau[-1]]])
        stress_faces = self.beta * rate_faces + g * tau_faces
        dv = np.diff(stress_faces) / h / self.reynolds
        rate = 0.5 * (rate_faces[1:] + rate_faces[:-1])
        dtau = rate - tau / self.weissenberg
        de = (self.beta * rate + g * tau) * rate
        return dv, dtau, de

    def simulate(self) -> np.ndarray:
        """States ``(nodes, snapshots, 5)``: (x, y, v, e, tau) of every node at every sample."""
        n, h = self.nodes, self.dt / self.substeps
        state = np.zeros((4, n))  # x, v, e, tau
        out = np.empty((n, self.snapshots, 5))

        def f(t, s):
            dv, dtau, de = self.rates(t, s[1], s[3])
            return np.stack([s[1], dv, de, dtau])

        t = 0.0
        for k in range(self.snapshots):
            out[:, k] = np.stack([state[0], self.y, state[1], state[2], state[3]], axis=1)
            for _ in range(self.substeps):
                k1 = f(t, state)
                k2 = f(t + h / 2, state + h / 2 * k1)
                k3 = f(t + h / 2, state + h / 2 * k2)
                k4 = f(t + h, state + h * k3)
                state = state + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
                t += h
        return out

    def data(self) -> Trajectories:
        xs = self.simulate()
        ts = np.arange(self.snapshots) * self.dt
        return Trajectories.from_list([(ts, x) for x in xs], names=NAMES)


def split(count: int, seed: int = 0) -> tuple[list[int], list[int]]:
    """80 % of the trajectories to train, 20 % to test, at random (as the peer splits)."""
    order = np.random.default_rng(seed).permutation(count)
    cut = int(0.8 * count)
    return sorted(order[:cut].tolist()), sorted(order[cut:].tolist())


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--set", nargs="*", default=[], metavar="KEY=VALUE",
                   help="override a training setting (RunConfig field)")
    p.add_argument("--seed", type=int, default=0, help="the split's and the training's seed")
    args = p.parse_args(argv)
    overrides = parse_overrides(args.set)
    flow = Couette()
    data = flow.data()
    train_ids, test_ids = split(flow.nodes, args.seed)
    train, test = data.select(train_ids), data.select(test_ids)
    horizon = flow.dt * (flow.snapshots - 1)
    short = horizon / 10
    config = dataclasses.replace(RunConfig(seed=args.seed), **overrides)
    print(f"published-viscoelastic stand-in: {flow}, {len(train_ids)} trajectories to train, "
          f"{len(test_ids)} to test; no structure flags; overrides {overrides or 'none'}; "
          f"load {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores", flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        run = train_and_test(train, test, config, Path(tmp) / "run", horizon=short)
        history, report, rollout = run["history"], run["report"], run["rollout"]
        standardised, seconds = run["standardised"], run["seconds"]
        box = black_box(train, test, dataclasses.replace(
            config, scheme=trained_scheme(run["header"])), horizon=short)
        print(f"  done in {time.perf_counter() - t0:.0f} s", flush=True)
    print(f"\n| model | rel. L2 | to t = {short:.3g} | standardised | failed | steps (kept) "
          "| train s |")
    print("|---|---|---|---|---|---|---|")
    print(f"| GENERIC, defaults | {_fmt(report['rollout_error_mean'])} | "
          f"{_fmt(report['rollout_error_to_horizon_mean'])} | {_fmt(standardised)} | "
          f"{int(report['rollout_failures'])}/{len(test_ids)} | "
          f"{history.step[-1] if history.step else 0} ({history.best_step}) | {seconds:.0f} |")
    print(f"| black box | {_fmt(box['rel_l2'])} | {_fmt(box['to_horizon'])} | "
          f"{_fmt(box['standardised'])} | {box['failed']}/{len(test_ids)} | {box['steps']} | "
          f"{box['seconds']:.0f} |")
    print(f"| x(t) = x(0) | {_fmt(constant_prediction_error(test))} | | | | | |")
    drift = constant_drift(test, rollout)  # y: constant along every trajectory
    print(f"\nLargest change of y along a test rollout: {drift:.3g} standard deviations (y is "
          "constant in the data).")
    print(f"The peer's published network: {PUBLISHED} on the real dataset.")
    return 0


if __name__ == "__main__":
    sys.exit(main())
