"""The wall around the training data (``--confine``): zero where the data are, quartic (coercive)
outside, saved with the model (files without a power keep the quadratic wall they were trained
with), and what it is for: with M grad E = 0 exact, a rollout of a learned model
stays bounded whatever the networks learned."""

import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np
import pytest

import metriplex as mx
from metriplex import MetriplexError
from metriplex.structure import Confinement, MLPPotential, ProjectedCholeskyFriction


def _data(rng: np.random.Generator) -> np.ndarray:
    x = rng.normal(size=(200, 3)) * np.array([1.0, 10.0, 1.0]) + np.array([0.0, 1e3, 0.0])
    x[:, 2] = 7.0  # constant in the data: left free
    return x


def test_the_wall_is_zero_on_the_data_and_quartic_outside():
    x = _data(np.random.default_rng(0))
    wall = Confinement.around(x, margin=0.0)
    assert wall.indices == (0, 1)
    inside = jnp.asarray(x)
    assert float(jnp.max(jax.vmap(wall)(inside))) == 0.0
    assert float(jnp.max(jnp.abs(jax.vmap(jax.grad(wall))(inside)))) == 0.0
    # One and two standard deviations above the largest x1: 1 and 16 (a spread of 10 per unit).
    edge = jnp.array([0.0, float(x[:, 1].max()), 7.0])
    one = edge.at[1].add(x[:, 1].std())
    two = edge.at[1].add(2 * x[:, 1].std())
    assert float(wall(one)) == pytest.approx(1.0, rel=1e-12)
    assert float(wall(two)) == pytest.approx(16.0, rel=1e-12)
    below = jnp.array([float(x[:, 0].min()) - 3 * x[:, 0].std(), 1e3, 7.0])
    assert float(wall(below)) == pytest.approx(81.0, rel=1e-12)
    # Its Hessian is continuous across the box's face (the Newton steps of implicit schemes
    # use it): zero on the face, as inside.
    hessian = jax.jit(jax.hessian(wall))
    assert float(jnp.max(jnp.abs(hessian(edge)))) == 0.0
    assert float(jnp.max(jnp.abs(hessian(edge.at[1].add(1e-6 * x[:, 1].std()))))) < 1e-9
    # The constant variable is free: moving it costs nothing.
    assert float(wall(edge.at[2].set(1e6))) == 0.0
    # By default the wall begins one standard deviation beyond the data.
    wide = Confinement.around(x)
    assert float(wide(one)) == 0.0
    assert float(wide(two)) == pytest.approx(1.0, rel=1e-12)


def test_a_confined_energy_grows_in_every_direction_whatever_the_weights():
    x = _data(np.random.default_rng(1))
    key = jr.key(0)
    E = MLPPotential(3, data=x, confinement=Confinement.around(x), key=key)
    # Weights far larger than training leaves them: the network alone falls linearly somewhere.
    E = jax.tree_util.tree_map(lambda a: 30.0 * a if isinstance(a, jax.Array) else a, E)
    center = jnp.asarray(x.mean(axis=0))
    directions = jr.normal(jr.key(1), (64, 3)).at[:, 2].set(0.0)
    directions = directions / jnp.linalg.norm(directions, axis=1, keepdims=True)
    scale = jnp.asarray(x.std(axis=0)).at[2].set(1.0)
    far = jax.vmap(lambda d: E(center + 1e4 * d * scale))(directions)
    assert float(jnp.min(far)) > float(jnp.max(jax.vmap(E)(jnp.asarray(x)))) + 1e6


def test_the_wall_travels_with_the_model_file(tmp_path):
    x = _data(np.random.default_rng(2))
    wall = Confinement.around(x)
    model = mx.GenericModel(
        MLPPotential(3, data=x, confinement=wall, key=jr.key(0)),
        mx.SumOf([2]), mx.ZeroPoisson(3), mx.ZeroFriction(3))
    mx.save(tmp_path / "m.mpx", model, n=3)
    back = mx.load(tmp_path / "m.mpx")
    assert back.energy.confinement == wall
    probe = jnp.array([3.0, 2e3, 7.0])
    assert float(back.energy(probe)) == float(model.energy(probe))


def test_a_wall_recorded_without_its_power_is_the_quadratic_one_it_was_trained_with():
    x = _data(np.random.default_rng(2))
    spec = Confinement.around(x).to_json()
    assert spec.pop("power") == 4
    old = Confinement.from_json(spec)  # as written before the power was recorded
    assert old.power == 2
    probe = jnp.array([0.0, float(x[:, 1].max() + 3 * x[:, 1].std()), 7.0])  # 2 sd beyond
    assert float(old(probe)) == pytest.approx(4.0, rel=1e-12)
    assert Confinement.from_json(old.to_json()) == old


def test_a_confined_model_with_exact_degeneracy_cannot_run_away():
    # A random model on the standard-normal box, weights tripled so that its field is strong, a
    # learned friction made exactly degenerate: E is conserved, so with the wall the state stays
    # in the bounded set {E = E(x0)}; without it the same model runs away.
    n = 4
    x = np.random.default_rng(3).normal(size=(500, n))
    ts = jnp.broadcast_to(0.01 * jnp.arange(4001.0), (8, 4001))

    def rollout(wall):
        keys = jr.split(jr.key(4), 3)
        E = MLPPotential(n, data=x, confinement=wall, key=keys[0])
        S = MLPPotential(n, data=x, key=keys[1])
        M = ProjectedCholeskyFriction(n, width=16, depth=1, key=keys[2])
        model = mx.GenericModel(E, S, mx.CanonicalPoisson(n, 1), M)
        model = jax.tree_util.tree_map(lambda a: 3.0 * a if isinstance(a, jax.Array) else a,
                                       model)
        return model, mx.solve(model, jnp.asarray(x[:8]), ts, scheme=mx.RK4()).xs

    _, free = rollout(None)
    assert not bool(jnp.all(jnp.isfinite(free)))
    model, xs = rollout(Confinement.around(x))
    assert bool(jnp.all(jnp.isfinite(xs)))
    assert float(jnp.max(jnp.abs(xs))) < 20.0
    energies = jax.vmap(jax.vmap(model.energy))(xs)
    drift = jnp.max(jnp.abs(energies - energies[:, :1]))
    assert float(drift) < 1e-3 * float(jnp.max(jnp.abs(energies)))  # RK4 at dt = 0.01


@pytest.mark.parametrize("args,match", [
    (((0, 1), (0.0,), (1.0, 2.0), (1.0, 1.0)), "one bound and one scale per variable"),
    (((0,), (2.0,), (1.0,), (1.0,)), "low <= high and scales > 0"),
    (((0,), (0.0,), (1.0,), (0.0,)), "low <= high and scales > 0"),
    (((0,), (0.0,), (1.0,), (1.0,), 1), r"power must be an integer >= 2; got 1\. Leave it out"),
    (((0,), (0.0,), (1.0,), (1.0,), 2.5), "power must be an integer >= 2"),
])
def test_a_malformed_wall_is_refused(args, match):
    with pytest.raises(MetriplexError, match=match):
        Confinement(*args)


def test_a_negative_margin_is_refused():
    with pytest.raises(MetriplexError, match="margin must be finite and >= 0; got -1"):
        Confinement.around(np.zeros((3, 2)), margin=-1.0)
