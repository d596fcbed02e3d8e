"""Training pairs held once (states plus row indices), the pooled state scale, and input noise."""

import equinox as eqx
import jax.numpy as jnp
import jax.random as jr
import numpy as np
import pytest

import metriplex as mx
from metriplex._errors import MetriplexError
from metriplex._pairs import PairRows, PairStore
from metriplex.config import RunConfig, validate
from metriplex.data import Pairs, Trajectories, state_scale
from helpers import damped_oscillator, make_data, oscillator_x0


def _ragged() -> Trajectories:
    rng = np.random.default_rng(0)
    rows = [(k, t, rng.normal(size=3)) for k, T in ((3, 5), (7, 2), (1, 4)) for t in range(T)]
    return Trajectories(
        x=np.array([r[2] for r in rows]),
        t=np.array([0.1 * r[1] * (1 + r[0]) for r in rows]),
        trajectory=np.array([r[0] for r in rows]),
    )


def test_pair_rows_give_the_pairs_of_trajectories_without_copying_the_states():
    data = _ragged()
    rows = PairRows.of(data, 3, "training")
    expected = data.pairs()
    assert rows.count == len(expected) == 4 + 1 + 3  # no pair across trajectories
    assert rows.x is data.x
    np.testing.assert_array_equal(rows.x[rows.first], expected.x0)
    np.testing.assert_array_equal(rows.x[rows.second], expected.x1)
    np.testing.assert_array_equal(rows.dt, expected.dt)
    store = PairStore.of(rows, np.ones(3), jnp.float64)
    batch = store.take(jnp.array([6, 0, 6]))
    np.testing.assert_array_equal(np.asarray(batch.x0), expected.x0[[6, 0, 6]])
    np.testing.assert_array_equal(np.asarray(batch.x1), expected.x1[[6, 0, 6]])
    np.testing.assert_array_equal(np.asarray(batch.dt), expected.dt[[6, 0, 6]])


def test_pair_rows_of_ready_pairs_and_their_checks():
    rng = np.random.default_rng(1)
    x0, x1, dt = rng.normal(size=(5, 2)), rng.normal(size=(5, 2)), np.full(5, 0.1)
    rows = PairRows.of(Pairs(x0, x1, dt), 2, "training")
    np.testing.assert_array_equal(rows.x[rows.first], x0)
    np.testing.assert_array_equal(rows.x[rows.second], x1)
    with pytest.raises(MetriplexError, match="model expects 3"):
        PairRows.of((x0, x1, dt), 3, "training")
    with pytest.raises(MetriplexError, match=r"every dt must be finite and > 0"):
        PairRows.of((x0, x1, -dt), 2, "training")
    x1[2, 1] = np.nan
    with pytest.raises(MetriplexError, match="validation data contain NaN"):
        PairRows.of((x0, x1, dt), 2, "validation")
    with pytest.raises(MetriplexError, match=r"dt of shape \(N,\)"):
        PairRows.of((x0, x1, dt[:3]), 2, "training")


def test_state_scale_pools_several_parts_block_by_block():
    rng = np.random.default_rng(2)
    # More rows than one block, a large offset, a tiny spread and a constant column.
    x = rng.normal(size=(150_000, 3)) * np.array([2.0, 1e-3, 0.0]) + np.array([0.0, 1e4, 5.0])
    expected = np.where(x.std(axis=0) > 0, x.std(axis=0), 1.0)
    np.testing.assert_allclose(state_scale(x), expected, rtol=1e-9)
    np.testing.assert_allclose(state_scale(x[:70_001], x[70_001:]), expected, rtol=1e-9)
    assert state_scale(x)[2] == 1.0


@pytest.fixture(scope="module")
def data():
    return make_data(damped_oscillator(), oscillator_x0(4), 0.1, 12, names=("q", "p", "s"))


def _fit(data, **kwargs):
    model = mx.GenericModel(
        energy=mx.MLPPotential(3, width=8, key=jr.key(0)),
        entropy=mx.SumOf((2,)), poisson=mx.CanonicalPoisson(3, pairs=1),
        friction=mx.CholeskyFriction(3, width=8, key=jr.key(1)))
    options = dict(steps=60, eval_every=20, stopping=None, rollout_check=None, progress=False,
                   key=jr.key(2))
    return mx.fit(model, data, **{**options, **kwargs})


@pytest.mark.slow
def test_input_noise_perturbs_training_reproducibly(data):
    _, plain = _fit(data)
    _, noisy = _fit(data, input_noise=0.05)
    _, again = _fit(data, input_noise=0.05)
    # The first evaluation (step 0, untrained) is the same; the noise changes what follows.
    assert plain.train["total"][0] == noisy.train["total"][0]
    assert plain.train["total"][1:] != noisy.train["total"][1:]
    assert noisy.train["total"] == again.train["total"]


def test_input_noise_out_of_range_is_refused(data):
    with pytest.raises(MetriplexError, match=r"input_noise must be in \[0, 1\).*got 1.5"):
        _fit(data, input_noise=1.5)
    with pytest.raises(MetriplexError, match=r"--input-noise must be in \[0, 1\).*got -0.1"):
        validate(RunConfig(input_noise=-0.1), 3)


def test_losses_networks_and_the_wall_agree_on_which_variables_are_constant():
    # One column moves by 1e-10 of its size: rounding, not signal. The loss scale, the
    # networks' input statistics and the wall read it from the same place, so they agree.
    from metriplex.structure import Confinement
    from metriplex.structure._mlp import data_statistics

    rng = np.random.default_rng(3)
    x = np.c_[rng.normal(size=200), 1e4 + 1e-6 * rng.normal(size=200), rng.normal(size=200)]
    assert state_scale(x)[1] == 1.0
    assert data_statistics(x)[1][1] == 1.0
    assert Confinement.around(x).indices == (0, 2)
    # Each variable is judged by its own size: one in small units beside one in large units
    # is not constant (a spread of 1e-4 next to values of 1e5).
    y = np.c_[1e5 + 1e3 * rng.normal(size=1000), 1e-4 * rng.normal(size=1000)]
    np.testing.assert_allclose(state_scale(y), y.std(axis=0), rtol=1e-9)
    assert data_statistics(y)[1][1] == pytest.approx(y[:, 1].std(), rel=1e-9)


def test_runs_of_consecutive_pairs_share_their_states_and_weigh_out_crossings():
    data = _ragged()  # trajectories of 4, 5 and 2 samples, in this order
    np.testing.assert_array_equal(data.trajectory, [1] * 4 + [3] * 5 + [7] * 2)
    rows = PairRows.of(data, 3, "training")
    assert rows.in_runs
    store = PairStore.of(rows, np.ones(3), jnp.float64)
    # Runs of 3 pairs from rows 2 (crosses from the first trajectory into the second), 0
    # and 9 (the last two rows: past the end).
    batch = store.take_runs(jnp.array([2, 0, 9], dtype=rows.first.dtype), 3)
    assert batch.runs.states.shape == (3 * 4, 3)
    x = data.x
    expected = [(2, 3), (3, 4), (4, 5), (0, 1), (1, 2), (2, 3), (9, 10), (10, 10), (10, 10)]
    np.testing.assert_array_equal(np.asarray(batch.x0), x[[a for a, _ in expected]])
    np.testing.assert_array_equal(np.asarray(batch.x1), x[[b for _, b in expected]])
    np.testing.assert_array_equal(np.asarray(batch.runs.states[batch.runs.first]),
                                  np.asarray(batch.x0))
    np.testing.assert_array_equal(np.asarray(batch.runs.states[batch.runs.second]),
                                  np.asarray(batch.x1))
    # Row 3 ends the first trajectory (3 -> 4 crosses), row 10 is the last row.
    np.testing.assert_array_equal(np.asarray(batch.weight), [1, 0, 1, 1, 1, 1, 1, 0, 0])
    dt = np.diff(data.t)
    np.testing.assert_allclose(np.asarray(batch.dt),
                               [dt[2], 1.0, dt[4], dt[0], dt[1], dt[2], dt[9], 1.0, 1.0])
    # Ready pairs are no runs of rows.
    x0 = np.arange(6.0).reshape(3, 2)
    assert not PairRows.of(Pairs(x0, x0 + 1, np.ones(3)), 2, "training").in_runs


def test_a_loss_on_runs_equals_the_loss_on_the_data_pairs_they_hold():
    data = _ragged()
    rows = PairRows.of(data, 3, "training")
    store = PairStore.of(rows, np.array([1.0, 2.0, 0.5]), jnp.float64)
    model = mx.GenericModel(
        energy=mx.MLPPotential(3, width=8, key=jr.key(0)), entropy=mx.SumOf((2,)),
        poisson=mx.CanonicalPoisson(3, pairs=1),
        friction=mx.CholeskyFriction(3, width=8, key=jr.key(1)))
    loss = mx.CrankNicolsonResidual() + 3.0 * mx.DegeneracyPenalty()
    assert loss.reads_runs
    runs = store.take_runs(jnp.array([2, 0], dtype=rows.first.dtype), 3)
    total, parts = eqx.filter_jit(loss)(model, runs)  # one program, not one per operation
    # The same pairs without the crossing one, as independent pairs: the residual is theirs;
    # the penalties, read at the states, also see the state the crossing "pair" starts from.
    pairs = store.take(jnp.array([2, 3, 0, 1, 2]))  # pair k from row k (k < 3), k + 1 after
    _, expected = eqx.filter_jit(loss)(model, pairs)
    np.testing.assert_allclose(parts["residual"], expected["residual"], rtol=1e-12)
    assert np.isfinite(total)


def test_fit_draws_runs_only_where_every_term_reads_them(data):
    from typing import ClassVar

    from metriplex.losses import AbstractLossTerm

    class PairDifference(AbstractLossTerm):
        name: ClassVar[str] = "difference"

        def __call__(self, model, batch, ctx, key):
            return jnp.mean((batch.x1 - batch.x0) ** 2)

    assert not (mx.CrankNicolsonResidual() + PairDifference()).reads_runs
    assert not mx.DegeneracyPenalty(at_midpoints=True).reads_runs
    assert (mx.CrankNicolsonResidual() + mx.NegativeTemperature((2,))
            + mx.JacobiPenalty()).reads_runs
    _, independent = _fit(data)
    _, runs = _fit(data, consecutive=4)
    assert runs.train["total"][0] == independent.train["total"][0]  # step 0: untrained
    assert runs.train["total"][-1] < 0.6 * runs.train["total"][0]  # it trains (0.52)
    assert runs.train["total"][1:] != independent.train["total"][1:]
    with pytest.raises(MetriplexError, match=r"consecutive must be an integer >= 1.*got 0"):
        _fit(data, consecutive=0)


def test_fit_progress_in_a_log_is_not_redrawn_at_every_evaluation(data, capsys, monkeypatch):
    # Written to a pipe or file (stderr under pytest), the bar is redrawn at most every 30 s;
    # each evaluation's figures must not force a redraw of their own (they did: a frame per
    # 100 steps in every log).
    monkeypatch.delenv("TQDM_MININTERVAL", raising=False)
    capsys.readouterr()
    _fit(data, progress=True, steps=600, eval_every=50)
    frames = capsys.readouterr().err.count("\r")
    assert 1 <= frames <= 4, frames
