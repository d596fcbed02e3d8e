"""The two-variable learned L, a(x) J with a > 0: what --poisson neural builds for n = 2."""

import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np
import pytest

import metriplex as mx
from metriplex.app._build import build_model
from metriplex.app.config import RunConfig
from metriplex.structure.scaling import Scaling


@pytest.mark.parametrize("seed", range(4))
def test_planar_poisson_keeps_one_sign_for_any_weights_and_units(seed):
    # Large random weights and a scaling with a factor: a(x) stays positive everywhere, and
    # L is a(x) J, exactly antisymmetric.
    k1, k2, k3 = jr.split(jr.key(seed), 3)
    scaling = Scaling((1e3, -2.0), (0.01, 40.0), factor=3.0)
    L = mx.PlanarPoisson(2, scaling=scaling, key=k1)
    L = jax.tree_util.tree_map(lambda w: 30.0 * jr.normal(k2, w.shape, w.dtype), L)
    assert isinstance(L, mx.PlanarPoisson)
    spread = 5.0 * jr.normal(k3, (500, 2))
    xs = jnp.asarray([[1e3, -2.0]]) + jnp.asarray([[0.01, 40.0]]) * spread
    Ls = jax.vmap(lambda x: L(x, None))(xs)
    a = np.asarray(Ls[:, 0, 1])
    assert np.all(a >= 0) and np.all(np.isfinite(a))
    np.testing.assert_array_equal(np.asarray(Ls[:, 1, 0]), -a)
    np.testing.assert_array_equal(np.asarray(Ls[:, 0, 0]), 0.0)


def test_planar_poisson_is_two_variables_only():
    with pytest.raises(mx.MetriplexError, match="PlanarPoisson is L = a\\(x\\) J for two "
                       "variables; got n=3"):
        mx.PlanarPoisson(3, key=jr.key(0))


def test_neural_poisson_of_two_variables_is_planar_and_saved_as_such(tmp_path):
    data = mx.Trajectories.from_arrays(
        np.linspace(0, 1, 11)[None, :].repeat(3, 0),
        np.random.default_rng(0).normal(size=(3, 11, 2)))
    model = build_model(RunConfig(), data, key=jr.key(0))
    assert isinstance(model.poisson, mx.PlanarPoisson)
    three = mx.Trajectories.from_arrays(
        np.linspace(0, 1, 11)[None, :].repeat(3, 0),
        np.random.default_rng(0).normal(size=(3, 11, 3)))
    assert isinstance(build_model(RunConfig(), three, key=jr.key(0)).poisson,
                      mx.SkewMLPPoisson)
    mx.save(tmp_path / "m.mpx", model, n=2)
    back = mx.load(tmp_path / "m.mpx")
    assert isinstance(back.poisson, mx.PlanarPoisson)
    x = jnp.asarray([0.3, -0.2])
    np.testing.assert_array_equal(np.asarray(back.poisson(x, None)),
                                  np.asarray(model.poisson(x, None)))
