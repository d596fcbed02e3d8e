"""Variables constant along every trajectory (a parameter recorded with the data): detected in
the data, held exactly constant by the learned L and M (``MaskedPoisson``, ``MaskedFriction``),
with the structure intact, by default and from the command line."""

import contextlib
import io
import json
import re

import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np
import pytest

import metriplex as mx
from metriplex.app._build import build_model
from metriplex.app.config import RunConfig
from metriplex.app.runs import train_run
from metriplex.cli import main
from metriplex.structure import (
    CholeskyFriction,
    MaskedFriction,
    MaskedPoisson,
    MLPPotential,
    ProjectedCholeskyFriction,
    ProjectedSkewMLPPoisson,
    SkewMLPPoisson,
)
from metriplex.systems import generate


def _trajectories(columns):
    """Three trajectories of 5 samples; ``columns(k, t)`` gives trajectory k's states."""
    t = np.linspace(0.0, 1.0, 5)
    return mx.Trajectories.from_list([(t, columns(k, t)) for k in range(3)])


def test_the_data_name_the_variables_constant_along_every_trajectory():
    moving = _trajectories(lambda k, t: np.stack([np.sin(t + k), np.full_like(t, 2.0 + k),
                                                  np.full_like(t, 7.0), t * k], axis=1))
    # Column 1 is a parameter (another value per trajectory), column 2 one value everywhere,
    # column 3 moves in every trajectory but the first.
    assert moving.constant_variables() == (1, 2)
    rounding = _trajectories(lambda k, t: np.stack(
        [np.cos(t), 1e4 * (1.0 + k + 1e-16 * np.arange(len(t)))], axis=1))
    assert rounding.constant_variables() == (1,)
    slow = _trajectories(lambda k, t: np.stack([np.cos(t), 1.0 + k + 1e-9 * t], axis=1))
    assert slow.constant_variables() == ()
    still = _trajectories(lambda k, t: np.ones((len(t), 2)) * k)
    assert still.constant_variables() == ()  # nothing moves: no variable is singled out


def _masked_model(n=4, constant=(3,), seed=0):
    k = jr.split(jr.key(seed), 4)
    return mx.GenericModel(
        energy=MLPPotential(n, width=16, key=k[0]),
        entropy=MLPPotential(n, width=16, key=k[1]),
        poisson=MaskedPoisson(ProjectedSkewMLPPoisson(n, width=16, key=k[2]), constant),
        friction=MaskedFriction(ProjectedCholeskyFriction(n, width=16, key=k[3]), constant),
    )


def test_masked_blocks_hold_the_variables_and_keep_the_generic_structure():
    # Three free variables: a 2 x 2 antisymmetric L with L grad S = 0 would have to be zero.
    model = _masked_model(n=5, constant=(1, 3))
    x = jr.normal(jr.key(1), (16, 5))
    t = jax.vmap(model.terms)(x)
    L, M = np.asarray(t.poisson), np.asarray(t.friction)
    for m in (L, M):
        assert np.all(m[:, [1, 3], :] == 0.0) and np.all(m[:, :, [1, 3]] == 0.0)
        assert np.abs(m[:, :, [0, 2, 4]][:, [0, 2, 4]]).max() > 1e-3  # the others are learned
    np.testing.assert_array_equal(L, -np.swapaxes(L, 1, 2))
    np.testing.assert_allclose(M, np.swapaxes(M, 1, 2), atol=1e-14)
    assert np.linalg.eigvalsh(M).min() > -1e-12
    # The wrapped blocks are exactly degenerate against the masked gradients, so the masked
    # ones are exactly degenerate against the full gradients.
    LgS = np.einsum("bij,bj->bi", L, np.asarray(t.grad_entropy))
    MgE = np.einsum("bij,bj->bi", M, np.asarray(t.grad_energy))
    assert np.abs(LgS).max() < 1e-12 and np.abs(MgE).max() < 1e-12
    f = np.asarray(jax.vmap(model.vector_field)(x))
    assert np.all(f[:, [1, 3]] == 0.0) and np.abs(f[:, [0, 2, 4]]).min() > 0.0
    # The potentials still depend on the held variables (they are parameters, not absent).
    assert np.abs(np.asarray(t.grad_energy)[:, 3]).min() > 0.0


def test_a_masked_block_is_saved_and_loaded(tmp_path):
    k = jr.split(jr.key(2), 4)
    model = mx.GenericModel(
        energy=MLPPotential(3, width=8, key=k[0]), entropy=mx.SumOf((2,)),
        poisson=MaskedPoisson(SkewMLPPoisson(3, width=8, key=k[1]), (0,)),
        friction=MaskedFriction(CholeskyFriction(3, width=8, key=k[2]), (0,)))
    mx.save(tmp_path / "m.mpx", model, n=3)
    back = mx.load(tmp_path / "m.mpx")
    assert back.spec() == model.spec() and back.poisson.constant == (0,)
    assert model.spec()["poisson"]["base"]["kind"] == "neural"
    x = jnp.asarray([0.3, -1.0, 0.5])
    np.testing.assert_array_equal(back.vector_field(x), model.vector_field(x))


@pytest.mark.parametrize("constant, match", [
    ((4,), r"distinct indices in \[0, 3\].*got \[4\]"),
    ((1, 1), r"distinct indices.*got \[1, 1\]"),
    ((0, 1, 2, 3), r"fewer than the n=4 variables"),
])
def test_masks_that_cannot_be_are_refused(constant, match):
    with pytest.raises(mx.MetriplexError, match=match):
        MaskedPoisson(SkewMLPPoisson(4, width=8, key=jr.key(0)), constant)


def test_a_block_without_a_size_cannot_be_masked():
    known = mx.KnownFriction(lambda x: jnp.zeros((x.shape[0], x.shape[0]), x.dtype))
    with pytest.raises(mx.MetriplexError, match=r"MaskedFriction wraps a block that states its "
                       r"size n .*KnownFriction does not\. Wrap the learned block"):
        MaskedFriction(known, (0,))


def _cli(*args):
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        code = main([str(a) for a in args])
    return code, err.getvalue()


def test_training_holds_a_recorded_parameter_constant_by_default(tmp_path, capsys):
    """The oscillator family: its stiffness k (column 3) is a parameter, constant along each
    trajectory. Defaults detect it, say so, record it, and the learned model's rollouts keep
    it exactly; with ``--constant none`` the model gives it a rate. (``train_run`` is what
    ``metriplex train`` runs before it evaluates.)"""
    data = generate("oscillator-family", trajectories=6, steps=30, dt=0.02, seed=0)
    # (one start: the starts are tests/test_starts.py's; no held-out trajectories: what is
    # checked here does not depend on them)
    train_run(data, RunConfig(steps=10, eval_every=10, float64=True, starts=1, validation=0.0),
              tmp_path / "run", progress=False)
    assert "k (column 3) is constant along every training trajectory" in capsys.readouterr().err
    header = json.loads((tmp_path / "run" / "config.json").read_text())
    assert header["constant_variables"] == [3]
    model = mx.load(tmp_path / "run" / "model.mpx")
    assert model.poisson.constant == (3,) and model.friction.constant == (3,)
    x0 = jnp.asarray(data.x[:1])
    ts = jnp.asarray(np.arange(20) * 0.02)
    xs = np.asarray(mx.simulate(model, x0, ts))
    assert np.all(xs[..., 3] == xs[:, :1, 3]) and np.ptp(xs[..., 0]) > 0.0

    free = build_model(RunConfig(constant="none"), data, key=jr.key(0))
    assert "constant" not in free.spec()["poisson"]
    assert abs(float(free.vector_field(jnp.asarray(data.x[0]))[3])) > 0.0
    held = build_model(RunConfig(constant="2,3"), data, key=jr.key(0))
    assert held.poisson.constant == (2, 3) and held.friction.constant == (2, 3)


def test_constant_option_names_the_rule(tmp_path):
    mx.write(tmp_path / "d.npz", generate("oscillator-family", trajectories=3, steps=5,
                                          dt=0.02, seed=0))
    for value, match in (("7", r"--constant indices must lie in \[0, 3\].*got \[7\]"),
                         ("k", r"--constant expects comma-separated integer indices.*'k'")):
        code, err = _cli("train", tmp_path / "d.npz", "--out", tmp_path / "r", "--constant",
                         value)
        assert code != 0 and "Traceback" not in err
        assert re.search(match, err), err


def test_jitter_on_a_recorded_parameter_is_the_median_gap_between_its_values():
    from metriplex.app._build import input_noise_of

    t = np.arange(4) * 0.1
    ks = [1.0 + 0.1 * i for i in range(21) if i not in (3, 9)]  # gaps of 0.1 and 0.2
    data = mx.Trajectories.from_list(
        [(t, np.stack([np.cos(t) * k, np.sin(t), np.full(4, k)], axis=1)) for k in ks],
        ("q", "p", "k"))
    on = RunConfig(jitter_constants=True, input_noise=0.01)
    noise = input_noise_of(on, data, (2,))
    assert noise[:2] == (0.01, 0.01)  # the other variables keep --input-noise
    assert noise[2] == pytest.approx(0.1 / np.std(data.x[:, 2]))
    few = data.select([0, 9, 18])  # three far-apart values: at most a quarter of a std
    assert input_noise_of(on, few, (2,))[2] == 0.25
    off = RunConfig(jitter_constants=False, input_noise=0.01)
    assert input_noise_of(off, data, (2,)) == 0.01
    assert RunConfig().jitter_constants  # on by default
    assert input_noise_of(on, data, ()) == 0.01  # nothing held constant
    # fit takes one fraction per variable, and refuses any outside [0, 1).
    model = mx.GenericModel(mx.MLPPotential(3, width=8, key=jr.key(0)), mx.SumOf((2,)),
                            mx.CanonicalPoisson(3, 1), mx.ZeroFriction(3))
    mx.fit(model, data, steps=2, batch_size=4, validation=0.0, input_noise=noise,
           key=jr.key(1), progress=False)
    with pytest.raises(mx.MetriplexError, match=r"input_noise must be in \[0, 1\)"):
        mx.fit(model, data, steps=2, input_noise=(0.0, 0.0, 1.5), key=jr.key(1), progress=False)
