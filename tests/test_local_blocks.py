"""Local blocks for states made of cells (``--energy local:CELLS``, ``--friction local:CELLS``):
the lattice's bonds, an energy that is a sum over bonds, a friction that is symmetric, PSD,
exactly degenerate and local, the model-file round trip and the command-line spelling."""

from dataclasses import replace

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np
import pytest

import metriplex as mx
from metriplex.app.config import RunConfig, validate
from metriplex.app.runs import train_run
from metriplex.app._thermal import confine_on, exact_blocks, reversible_first_on
from metriplex.structure import Lattice, LocalFriction, LocalPotential, Scaling
from metriplex.structure._registry import REGISTRY
from metriplex.systems import generate, get_system

CELLS, FIELDS = 4, 3
N = CELLS * FIELDS
SCALING = Scaling(tuple(np.linspace(-1.0, 2.0, N)), tuple(np.linspace(0.5, 3.0, N)), 0.7)


def _states(count, seed):
    z = jr.normal(jr.key(seed), (count, N))
    return jnp.asarray(SCALING.shift)[None, :] + jnp.asarray(SCALING.scale)[None, :] * z


def _cell(i):
    return [i + f * CELLS for f in range(FIELDS)]


@pytest.mark.parametrize("periodic", [False, True], ids=["open", "ring"])
def test_the_lattice_bonds_neighbouring_cells(periodic):
    lat = Lattice(CELLS, N, periodic)
    S = lat.selection()
    assert S.shape == (lat.bonds, 2 * FIELDS, N) and lat.bonds == CELLS + (not periodic)
    # every row selects at most one variable, and each bond reads two neighbouring cells
    assert np.all(S.sum(axis=2) <= 1)
    for b in range(lat.bonds):
        read = set(np.nonzero(S[b].sum(axis=0))[0])
        cells = {i for i in range(CELLS) if read & set(_cell(i))}
        assert read == {v for i in cells for v in _cell(i)}
        gaps = {(j - i) % CELLS for i in cells for j in cells if i != j}
        assert len(cells) in (1, 2) and gaps <= {1, CELLS - 1}
    # every cell is in two bonds (an open chain's ends: one to a neighbour, one outside)
    per_cell = [sum(bool(S[b][:, _cell(i)].any()) for b in range(lat.bonds)) for i in range(CELLS)]
    assert per_cell == [2] * CELLS


def test_the_lattice_refuses_what_does_not_fit():
    with pytest.raises(mx.MetriplexError, match="multiple of 5.*n=12.*allows: 2, 3, 4, 6"):
        Lattice(5, 12)
    # A chain of nine masses heating one shared bath (n = 19, a new-user check) is no lattice:
    # no one-variable "cells" proposed (trained with them, 0.789 against the defaults' 0.103).
    with pytest.raises(mx.MetriplexError, match=r"n=19\. A state with variables of its own "
                       r"beside the cells \(one bath") as refused:
        Lattice(9, 19)
    assert "local:19" not in str(refused.value)
    with pytest.raises(mx.MetriplexError, match="cells"):
        Lattice(1, 12)


def test_the_local_energy_is_a_sum_of_bond_terms():
    E = LocalPotential(Lattice(CELLS, N), width=8, data=_states(50, 0), key=jr.key(1))
    x = _states(1, 2)[0]
    H = jax.jit(jax.hessian(E))(x)  # one compiled program: eager, each operation compiles
    # cells 0 and 2 share no bond: no term couples their variables
    assert float(jnp.max(jnp.abs(H[np.ix_(_cell(0), _cell(2))]))) == 0.0
    assert float(jnp.max(jnp.abs(H[np.ix_(_cell(0), _cell(1))]))) > 0.0
    ring = LocalPotential(Lattice(CELLS, N, periodic=True), width=8, key=jr.key(1))
    assert float(jnp.max(jnp.abs(jax.jit(jax.hessian(ring))(x)[np.ix_(_cell(0), _cell(3))]))) > 0.0


@pytest.mark.parametrize("shared", [False, True], ids=["own", "shared"])
@pytest.mark.parametrize("scaling", [None, SCALING], ids=["identity", "scaled"])
@pytest.mark.parametrize("periodic", [False, True], ids=["open", "ring"])
def test_the_local_friction_is_symmetric_psd_degenerate_and_local(scaling, periodic, shared):
    M = LocalFriction(Lattice(CELLS, N, periodic, shared), width=8, scaling=scaling,
                      key=jr.key(3))
    xs, gs = _states(100, 4), jr.normal(jr.key(5), (100, N))
    F = eqx.filter_jit(jax.vmap(M))(xs, gs)
    top = float(jnp.max(jnp.abs(F)))
    assert bool(jnp.all(jnp.isfinite(F))) and top > 1e-8
    assert float(jnp.max(jnp.abs(F - jnp.swapaxes(F, 1, 2)))) <= 1e-15 * top
    assert float(jnp.max(jnp.abs(jnp.einsum("bij,bj->bi", F, gs)))) < 1e-13 * top
    eig = jnp.linalg.eigvalsh(F)
    assert float(jnp.min(eig)) > -1e-13 * float(jnp.max(eig))
    far = F[:, _cell(0)][:, :, _cell(2)]
    assert float(jnp.max(jnp.abs(far))) == 0.0
    ends = float(jnp.max(jnp.abs(F[:, _cell(0)][:, :, _cell(CELLS - 1)])))
    assert (ends > 0.0) == periodic


def test_a_shared_ring_is_the_same_however_its_cells_are_numbered():
    lat = Lattice(CELLS, N, periodic=True, shared=True)
    E = LocalPotential(lat, width=8, key=jr.key(11))
    M = LocalFriction(lat, width=8, key=jr.key(12))
    x, g = _states(1, 13)[0], jr.normal(jr.key(14), (N,))
    # moving every cell one place along the ring permutes the variables
    perm = np.concatenate([np.roll(np.arange(CELLS), 1) + f * CELLS for f in range(FIELDS)])
    np.testing.assert_allclose(E(x[perm]), E(x), rtol=1e-13)
    np.testing.assert_allclose(M(x[perm], g[perm]), M(x, g)[np.ix_(perm, perm)],
                               rtol=1e-12, atol=1e-15)
    # one network, not one per bond; an open chain's also reads the two outside flags
    assert E.nets.hidden.layers[0].weight.shape == (8, 2 * FIELDS)
    open_chain = LocalPotential(Lattice(CELLS, N, shared=True), width=8, key=jr.key(11))
    assert open_chain.nets.hidden.layers[0].weight.shape == (8, 2 * FIELDS + 2)


def test_a_shared_lattice_standardises_alike_cells_alike():
    x = np.asarray(_states(400, 15))
    E = LocalPotential(Lattice(CELLS, N, shared=True), width=8, data=x, key=jr.key(16))
    M = LocalFriction(Lattice(CELLS, N, shared=True), width=8, scaling=SCALING, key=jr.key(17))
    for f in range(FIELDS):
        field = x[:, f * CELLS:(f + 1) * CELLS]  # field f of every cell
        for stats in (E.shift, E.scale, M.scaling.shift, M.scaling.scale):
            assert len(set(stats[f * CELLS:(f + 1) * CELLS])) == 1
        np.testing.assert_allclose(E.shift[f * CELLS], field.mean(), rtol=1e-12)
        np.testing.assert_allclose(E.scale[f * CELLS], field.std(), rtol=1e-12)
    own = LocalFriction(Lattice(CELLS, N), width=8, scaling=SCALING, key=jr.key(17))
    assert own.scaling == SCALING


def test_no_nan_where_the_energy_gradient_vanishes():
    M = LocalFriction(Lattice(CELLS, N), width=8, scaling=SCALING, key=jr.key(6))
    x = _states(1, 7)[0]
    for r in (0.0, 1e-300, 1e-9):
        assert bool(jnp.all(jnp.isfinite(M(x, r * jnp.ones(N)))))
    grads = eqx.filter_grad(lambda m: jnp.sum(m(x, jnp.zeros(N)) ** 2 + m(x, jnp.ones(N))))(M)
    leaves = jax.tree_util.tree_leaves(eqx.filter(grads, eqx.is_inexact_array))
    assert leaves and all(bool(jnp.all(jnp.isfinite(v))) for v in leaves)


def test_local_blocks_round_trip_a_model_file(tmp_path):
    assert REGISTRY["potential"]["local"] is LocalPotential
    assert REGISTRY["friction"]["local"] is LocalFriction
    k = jr.split(jr.key(8), 2)
    model = mx.GenericModel(
        energy=LocalPotential(Lattice(CELLS, N, True), width=8, depth=1, activation="tanh",
                              data=_states(30, 10), output_scale=2.5, key=k[0]),
        entropy=mx.SumOf(_cell(0)[2:] + _cell(1)[2:]),
        poisson=mx.ZeroPoisson(N),
        friction=LocalFriction(Lattice(CELLS, N, shared=True), width=8, scaling=SCALING,
                               eps=1e-7, key=k[1]),
    )
    path = tmp_path / "local.mpx"
    mx.save(path, model, n=N)
    back = mx.load(path)
    assert back.spec() == model.spec()
    assert type(back.energy) is LocalPotential and type(back.friction) is LocalFriction
    xs = _states(16, 9)
    np.testing.assert_array_equal(np.asarray(jax.vmap(back.vector_field)(xs)),
                                  np.asarray(jax.vmap(model.vector_field)(xs)))


def test_training_with_the_command_line_spelling(tmp_path):
    data = generate(get_system("thermoelastic-chain", particles=3), trajectories=4, steps=30,
                    seed=0)
    config = RunConfig(poisson="canonical:3", entropy="sum:6,7,8", energy="local:3",
                       friction="local:3", width=16, steps=60, eval_every=30,
                       average_steps=0, validation=0.0, reversible_first=False)
    model, history, _, _, _ = train_run(data, config, tmp_path / "run", progress=False)
    assert type(model.energy) is LocalPotential and type(model.friction) is LocalFriction
    assert "degeneracy_M" not in history.train  # exact: no penalty to weigh
    t = eqx.filter_jit(eqx.filter_vmap(model.terms))(jnp.asarray(data.x[:40], jnp.float32))
    M, gE = t.friction, t.grad_energy
    scale = float(jnp.max(jnp.abs(M))) * float(jnp.max(jnp.abs(gE)))
    assert float(jnp.max(jnp.abs(jnp.einsum("bij,bj->bi", M, gE)))) < 1e-5 * scale


def test_a_local_energy_takes_no_quadratic_term(tmp_path):
    data = generate(get_system("thermoelastic-chain", particles=2), trajectories=3, steps=10,
                    seed=0)
    config = RunConfig(poisson="canonical:2", entropy="sum:4,5", energy="local:2",
                       quadratic=True, steps=10)
    with pytest.raises(mx.MetriplexError, match="--energy local .* no --quadratic"):
        train_run(data, config, tmp_path / "run", progress=False)


def test_the_command_line_spelling_is_checked_and_exact():
    cfg = RunConfig(poisson="canonical:3", entropy="sum:6,7,8", energy="local:3",
                    friction="local:3,periodic")
    validate(cfg, 9)
    assert exact_blocks(cfg) == (False, True)
    assert exact_blocks(replace(cfg, degeneracy="soft")) == (False, True)
    assert reversible_first_on(cfg) and confine_on(cfg)
    with pytest.raises(mx.MetriplexError, match="multiple of 4.*n=9"):
        validate(replace(cfg, energy="local:4"), 9)
    with pytest.raises(mx.MetriplexError, match="integer number of cells.*local:three"):
        validate(replace(cfg, friction="local:three"), 9)
    with pytest.raises(mx.MetriplexError, match="periodic.*shared.*local:3,ring"):
        validate(replace(cfg, friction="local:3,ring"), 9)
    with pytest.raises(mx.MetriplexError, match="--energy local reads .* Leave energy out"):
        validate(RunConfig(energy="local:5", features="pendulum", features_for="energy"), 10)
    with pytest.raises(mx.MetriplexError, match="--friction local reads .* Leave friction out"):
        validate(RunConfig(friction="local:5", features="pendulum", features_for="friction"), 10)
