"""Write examples/ragged_oscillator.csv: ragged, unevenly sampled trajectories of a damped
oscillator with a heat bath, in the long-table CSV layout (trajectory, t, q, p, s).

E = (q^2 + p^2)/2 + s, S = s, L canonical on (q, p), friction turns kinetic energy into s.
"""

from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import metriplex as mx  # noqa: E402


def oscillator(kappa=0.3):
    def friction(x):
        w = jnp.array([0.0, 1.0, -x[1]])
        return kappa * jnp.outer(w, w)

    return mx.GenericModel(mx.Known(lambda x: 0.5 * (x[0] ** 2 + x[1] ** 2) + x[2]),
                           mx.SumOf((2,)), mx.CanonicalPoisson(3, 1), mx.KnownFriction(friction))


def main(path=Path(__file__).with_name("ragged_oscillator.csv"), seed=0):
    rng = np.random.default_rng(seed)
    model = oscillator()
    pieces = []
    for _ in range(30):
        T = int(rng.integers(30, 80))  # ragged lengths
        ts = np.cumsum(np.r_[0.0, rng.uniform(0.05, 0.15, T - 1)])  # uneven sampling
        x0 = rng.uniform(-1.0, 1.0, 3)
        fine = np.linspace(0.0, ts[-1], 20 * T)
        grid = np.unique(np.r_[fine, ts])
        xs = np.asarray(mx.simulate(model, jnp.asarray(x0), jnp.asarray(grid)))
        pieces.append((ts, xs[np.searchsorted(grid, ts)]))
    mx.write(path, mx.Trajectories.from_list(pieces, ("q", "p", "s")))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
