"""Does enforcing the Jacobi identity help? Learn the free rigid body (L and E) four ways.

Truth (docs/physics.md, 'Free rigid body'): E = ½ Σ mᵢ²/Iᵢ with I = (10, 20, 40),
L(m)ᵢⱼ = −εᵢⱼₖ mₖ, S = 0, M = 0.
Data: Crank–Nicolson trajectories (``metriplex.solve``), dt = 2π/100, initial states drawn in a
shell 0.5 ≤ |m| ≤ 1.5. Learned: an MLP energy and

- ``none``: ``SkewMLPPoisson``, loss = CN residual;
- ``exact``: ``SkewMLPPoisson``, + ``JacobiPenalty(ExactJacobi())``;
- ``stochastic``: ``SkewMLPPoisson``, + ``JacobiPenalty(StochasticJacobi(probes=1))``;
- ``casimir3``: ``CasimirPoisson3`` (Jacobi by construction), loss = CN residual.

Reported: the validation CN residual of the returned model (the part of the loss that fits
the data, in standardised units), and on held-out trajectories rolled out from their first
state with Crank–Nicolson on the data grid: the relative L2 rollout error ‖x̂ − x‖/‖x‖ (whole
trajectory, mean over trajectories), the drift of the true Casimir |m|² along the learned
rollout (max relative), the relative Jacobi residual ‖J‖_F / (3‖T‖_F), T = (∂L)L, whose three
cyclic permutations sum to J: 0 for a Poisson bivector, O(1) when the three terms do not cancel
at all (median over held-out states), and the median Frobenius norm |L| (the truth has
|L| = √2|m| ≈ 1.4; on the data L and E are identifiable only up to L → αL, E → E/α, and the
Jacobi penalty, quadratic in L, pulls α down).

    python benchmarks/bench_jacobi_accuracy.py            # 3000 steps, 4 seeds
    python benchmarks/bench_jacobi_accuracy.py --quick    # 200 steps, 1 seed (smoke test)
"""

from __future__ import annotations

import os

os.environ["XLA_FLAGS"] = (
    os.environ.get("XLA_FLAGS", "")
    + " --xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1"
).strip()

import argparse  # noqa: E402
import time  # noqa: E402

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import jax.random as jr  # noqa: E402
import numpy as np  # noqa: E402

import metriplex as mx  # noqa: E402
from metriplex.structure import CasimirPoisson3  # noqa: E402

INERTIA = (10.0, 20.0, 40.0)
MODES = ("none", "exact", "stochastic", "casimir3")


def rigid_body() -> mx.GenericModel:
    inv = jnp.asarray([1.0 / v for v in INERTIA])

    def poisson(m):
        z = jnp.zeros((), m.dtype)
        # L_ij = -eps_ijk m_k
        return jnp.stack(
            [
                jnp.stack([z, -m[2], m[1]]),
                jnp.stack([m[2], z, -m[0]]),
                jnp.stack([-m[1], m[0], z]),
            ]
        )

    return mx.GenericModel(
        energy=mx.Known(lambda m: 0.5 * jnp.sum(inv * m * m)),
        entropy=mx.ZeroPotential(),
        poisson=mx.KnownPoisson(poisson),
        friction=mx.ZeroFriction(3),
    )


def initial_states(count: int, key) -> jax.Array:
    kd, kr = jr.split(key)
    d = jr.normal(kd, (count, 3))
    r = jr.uniform(kr, (count, 1), minval=0.5, maxval=1.5)
    return r * d / jnp.linalg.norm(d, axis=1, keepdims=True)


def make_data(count: int, steps: int, dt: float, key) -> tuple[mx.Trajectories, np.ndarray]:
    ts = jnp.arange(steps + 1) * dt
    out = mx.solve(rigid_body(), initial_states(count, key), ts, scheme=mx.CrankNicolson())
    assert out.ok, "ground-truth rollout failed"
    xs = np.asarray(out.xs)
    data = mx.Trajectories.from_list([(np.asarray(ts), x) for x in xs], names=("m1", "m2", "m3"))
    return data, xs


def build(mode: str, data: mx.Trajectories, width: int, depth: int, key) -> mx.GenericModel:
    ke, kl = jr.split(key)
    scaling = mx.Scaling.from_data(data.x)
    if mode == "casimir3":
        poisson = CasimirPoisson3(width=width, depth=depth, scaling=scaling, key=kl)
    else:
        poisson = mx.SkewMLPPoisson(3, width=width, depth=depth, scaling=scaling, key=kl)
    return mx.GenericModel(
        energy=mx.MLPPotential(3, width=width, depth=depth, data=data.x, key=ke),
        entropy=mx.ZeroPotential(),
        poisson=poisson,
        friction=mx.ZeroFriction(3),
    )


def loss_for(mode: str, weight: float) -> mx.Loss:
    loss = mx.CrankNicolsonResidual().as_loss()
    if mode == "exact":
        loss = loss + weight * mx.JacobiPenalty(mx.ExactJacobi())
    elif mode == "stochastic":
        loss = loss + weight * mx.JacobiPenalty(mx.StochasticJacobi(probes=1))
    return loss


@eqx.filter_jit
def relative_jacobi(model: mx.GenericModel, xs: jax.Array) -> jax.Array:
    def one(x):
        L = model.poisson_matrix(x)
        dL = jax.jacfwd(model.poisson_matrix)(x)  # dL[i, j, k] = d_k L_ij
        T = jnp.einsum("ijk,kl->ijl", dL, L)
        J = T + jnp.transpose(T, (1, 2, 0)) + jnp.transpose(T, (2, 0, 1))
        rel = jnp.sqrt(jnp.sum(J**2)) / (3.0 * jnp.sqrt(jnp.sum(T**2)))
        return rel, jnp.sqrt(jnp.sum(L**2))

    return jax.vmap(one)(xs)


def evaluate(model: mx.GenericModel, test_xs: np.ndarray, dt: float) -> dict[str, float]:
    ts = jnp.arange(test_xs.shape[1]) * dt
    out = mx.solve(model, jnp.asarray(test_xs[:, 0]), ts, scheme=mx.CrankNicolson())
    pred = np.asarray(out.xs)
    failed = int(np.sum(np.asarray(out.failed_step) >= 0))
    err = np.linalg.norm(pred - test_xs, axis=(1, 2)) / np.linalg.norm(test_xs, axis=(1, 2))
    c = np.sum(pred**2, axis=-1)
    drift = np.max(np.abs(c - c[:, :1]) / c[:, :1], axis=1)
    states = jnp.asarray(test_xs[:, :: max(1, test_xs.shape[1] // 20)].reshape(-1, 3))
    rel_j, norm_l = (np.asarray(v) for v in relative_jacobi(model, states))
    return {
        "rollout": float(np.mean(err)),
        "casimir_drift": float(np.mean(drift)),
        "rel_jacobi": float(np.median(rel_j)),
        "norm_L": float(np.median(norm_l)),
        "failed": failed,
    }


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="200 steps, 1 seed, fewer trajectories")
    ap.add_argument("--steps", type=int, default=None)
    ap.add_argument("--seeds", type=int, default=None)
    ap.add_argument("--trajectories", type=int, default=None)
    ap.add_argument("--length", type=int, default=200, help="time steps per trajectory")
    ap.add_argument("--width", type=int, default=64)
    ap.add_argument("--depth", type=int, default=2)
    ap.add_argument("--batch", type=int, default=256)
    ap.add_argument("--jacobi-weight", type=float, default=1.0)
    ap.add_argument("--lr", type=float, default=1e-3)
    ap.add_argument("--modes", nargs="*", default=list(MODES), choices=MODES)
    args = ap.parse_args(argv)
    steps = args.steps or (200 if args.quick else 3000)
    seeds = args.seeds or (1 if args.quick else 4)
    count = args.trajectories or (6 if args.quick else 20)
    dt = 2.0 * np.pi / 100.0

    data_key, test_key = jr.split(jr.key(1234))
    data, _ = make_data(count, args.length, dt, data_key)
    _, test_xs = make_data(5, args.length, dt, test_key)
    truth = evaluate(rigid_body(), test_xs, dt)
    print(
        f"rigid body, I = {INERTIA}; {count} training trajectories x {args.length} steps, "
        f"dt = 2pi/100; 5 held-out trajectories; {steps} Adam steps, batch {args.batch}, "
        f"width {args.width} x {args.depth}, Jacobi weight {args.jacobi_weight}; float64"
    )
    print(f"truth: rel. Jacobi {truth['rel_jacobi']:.1e}, rollout error {truth['rollout']:.1e}")
    header = (
        f"{'mode':>11} {'seed':>4} {'valid CN':>9} {'rollout err':>11} {'|m|^2 drift':>11} "
        f"{'rel Jacobi':>10} {'|L|':>8} {'failed':>6} {'train s':>7}"
    )
    print(header)
    print("-" * len(header))
    summary: dict[str, list[dict[str, float]]] = {m: [] for m in args.modes}
    for seed in range(seeds):
        for mode in args.modes:
            mkey, fkey = jr.split(jr.key(seed))
            model = build(mode, data, args.width, args.depth, mkey)
            t0 = time.perf_counter()
            model, history = mx.fit(
                model,
                data,
                loss=loss_for(mode, args.jacobi_weight),
                learning_rate=args.lr,
                steps=steps,
                batch_size=args.batch,
                eval_every=max(steps // 10, 1),
                progress=False,
                key=fkey,
            )
            train_s = time.perf_counter() - t0
            r = evaluate(model, test_xs, dt)
            r["valid"] = float(history.valid["residual"][history.step.index(history.best_step)])
            summary[mode].append(r)
            print(
                f"{mode:>11} {seed:>4} {r['valid']:9.2e} {r['rollout']:11.2e} "
                f"{r['casimir_drift']:11.2e} "
                f"{r['rel_jacobi']:10.2e} {r['norm_L']:8.2e} {r['failed']:>6} {train_s:7.1f}",
                flush=True,
            )
    if seeds > 1:
        print("mean over seeds:")
        for mode, rs in summary.items():
            print(
                f"{mode:>11} {'mean':>4} {np.mean([r['valid'] for r in rs]):9.2e} "
                f"{np.mean([r['rollout'] for r in rs]):11.2e} "
                f"{np.mean([r['casimir_drift'] for r in rs]):11.2e} "
                f"{np.mean([r['rel_jacobi'] for r in rs]):10.2e} "
                f"{np.mean([r['norm_L'] for r in rs]):8.2e} "
                f"{sum(r['failed'] for r in rs):>6}"
            )


if __name__ == "__main__":
    main()
