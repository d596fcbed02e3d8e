"""Temperatures from the energy balance (``--temperature-init``): the slope of the learned E
along the entropy variables, read from the data before the main stage."""

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np
import pytest

import metriplex as mx
from metriplex._balance import balance_temperatures, with_temperatures
from metriplex.app._build import build_model
from metriplex.app._stages import SLOPE_FLOOR, _balanced
from metriplex.app.config import RunConfig
from metriplex.systems import generate


def _mechanical_energy() -> mx.MLPPotential:
    """A network energy of (q, p, s) that does not depend on s (its s inputs zeroed), with
    the linear term whose s slope the balance sets."""
    energy = mx.MLPPotential(3, width=8, depth=2, linear=True, key=jr.key(0))
    first = energy.hidden.layers[0]
    return eqx.tree_at(lambda e: e.hidden.layers[0].weight, energy,
                       first.weight.at[:, 2].set(0.0))


def _heated(energy: mx.MLPPotential, temperature: float, trajectories: int = 3,
            steps: int = 50) -> mx.Trajectories:
    """Trajectories whose (q, p) wander and whose s takes up exactly what the energy loses:
    E + temperature * s constant along each."""
    rng = np.random.default_rng(1)
    rows, ids, times = [], [], []
    for k in range(trajectories):
        qp = np.cumsum(0.1 * rng.normal(size=(steps, 2)), axis=0) + rng.normal(size=2)
        e = np.asarray(jax.vmap(energy)(jnp.column_stack([qp, np.zeros(steps)])))
        s = 10.0 * k - (e - e[0]) / temperature
        rows.append(np.column_stack([qp, s]))
        ids.append(np.full(steps, k))
        times.append(0.1 * np.arange(steps))
    return mx.Trajectories(np.concatenate(ids), np.concatenate(times), np.vstack(rows))


def test_the_balance_reads_the_temperature_that_keeps_the_energy_constant():
    energy = _mechanical_energy()
    data = _heated(energy, temperature=250.0)
    t = balance_temperatures(energy, data, [2])
    assert t == pytest.approx([250.0], rel=1e-8)
    balanced = with_temperatures(energy, [2], t)
    e0 = np.asarray(jax.vmap(energy)(jnp.asarray(data.x)))
    e1 = np.asarray(jax.vmap(balanced)(jnp.asarray(data.x)))
    for k in range(3):  # constant along each trajectory now, to rounding
        rows = data.trajectory == k
        assert np.ptp(e1[rows]) < 1e-9 * np.ptp(e0[rows])
    # the slope it adds is the temperature, in the data's units, whatever the scales
    grad = jax.grad(balanced)(jnp.asarray(data.x[0])) - jax.grad(energy)(jnp.asarray(data.x[0]))
    np.testing.assert_allclose(np.asarray(grad), [0.0, 0.0, 250.0], rtol=1e-10, atol=1e-10)


def test_no_temperature_where_the_entropy_is_still_and_none_below_zero():
    energy = _mechanical_energy()
    data = _heated(energy, temperature=250.0)
    still = mx.Trajectories(data.trajectory, data.t, data.x.copy())
    still.x[:, 2] = 5.0
    assert balance_temperatures(energy, still, [2]).tolist() == [0.0]
    falling = mx.Trajectories(data.trajectory, data.t, data.x * np.array([1.0, 1.0, -1.0]))
    assert balance_temperatures(energy, falling, [2]).tolist() == [0.0]


def test_the_linear_term_is_off_unless_asked_and_kept_by_the_model_file(tmp_path):
    plain = mx.MLPPotential(3, width=8, depth=1, key=jr.key(0))
    assert plain.linear is None and "linear" not in plain.spec()
    energy = with_temperatures(mx.MLPPotential(3, width=8, depth=1, linear=True,
                                               key=jr.key(0)), [2], np.array([3.0]))
    assert energy.spec()["linear"] is True
    again = mx.MLPPotential.from_spec(energy.spec(), 3, key=jr.key(1))
    assert again.linear is not None
    assert jax.tree_util.tree_structure(again) == jax.tree_util.tree_structure(energy)
    model = mx.GenericModel(energy=energy, entropy=mx.SumOf((2,)),
                            poisson=mx.CanonicalPoisson(3, 1), friction=mx.ZeroFriction(3))
    mx.save(tmp_path / "m.mpx", model, n=3)
    loaded = mx.load(tmp_path / "m.mpx")
    np.testing.assert_array_equal(np.asarray(loaded.energy.linear), np.asarray(energy.linear))


def test_the_energy_has_the_term_where_its_temperatures_are_read_from_the_data():
    data = generate("oscillator-bath", trajectories=3, steps=10, seed=0)
    given = RunConfig(poisson="canonical:1", entropy="sum:2")
    assert build_model(given, data, key=jr.key(0)).energy.linear is not None
    off = dataclasses.replace(given, temperature_init=False)
    assert build_model(off, data, key=jr.key(0)).energy.linear is None
    assert build_model(RunConfig(), data, key=jr.key(0)).energy.linear is None
    # a learned L trades a gauge with E (L = a J, E -> phi(E)): no balance to read
    learned_l = RunConfig(entropy="sum:2")
    assert build_model(learned_l, data, key=jr.key(0)).energy.linear is None


def test_a_zero_slope_changes_nothing_and_a_set_one_is_never_trained():
    energy = mx.MLPPotential(3, width=8, depth=1, linear=True, key=jr.key(0))
    plain = mx.MLPPotential(3, width=8, depth=1, key=jr.key(0))
    x = jr.normal(jr.key(1), (5, 3))
    np.testing.assert_array_equal(np.asarray(jax.vmap(energy)(x)), np.asarray(jax.vmap(plain)(x)))
    set_ = with_temperatures(energy, [2], np.array([4.0]))
    grads = eqx.filter_grad(lambda e: jnp.sum(jax.vmap(e)(x) ** 2))(set_)
    assert not np.any(np.asarray(grads.linear))  # the optimiser never moves it
    assert np.any(np.asarray(grads.out.weight))


@pytest.mark.parametrize("temperature,set_", [(2500.0, True), (20.0, False)])
def test_the_main_stage_starts_from_the_balance_only_where_the_network_could_not_reach_it(
        temperature, set_, capsys):
    energy = _mechanical_energy()
    data = _heated(energy, temperature)
    model = mx.GenericModel(energy=eqx.tree_at(lambda e: e.linear, energy, None),
                            entropy=mx.SumOf((2,)), poisson=mx.CanonicalPoisson(3, 1),
                            friction=mx.ZeroFriction(3))
    balanced = _balanced(model, (2,), data)
    slope = np.asarray(balanced.energy.linear)  # in the networks' units (scale 1 here)
    assert (temperature > SLOPE_FLOOR) is set_
    np.testing.assert_allclose(slope, [0.0, 0.0, temperature if set_ else 0.0], rtol=1e-8)
    assert ("temperatures from the energy balance" in capsys.readouterr().err) is set_


def test_where_no_temperature_is_set_the_training_is_the_one_without_the_option(tmp_path):
    from metriplex.app.runs import train_run

    data = generate("oscillator-bath", trajectories=4, steps=20, seed=0)
    config = RunConfig(poisson="canonical:1", entropy="sum:2", steps=20, eval_every=10,
                       average_steps=0, validation=0.25, repeats=1, starts=1)
    histories = []
    for option in (True, False):  # on (as by default here), its slope below the floor
        run = train_run(data, dataclasses.replace(config, temperature_init=option),
                        tmp_path / str(option), progress=False)
        histories.append(run[1])
    assert histories[0].valid["total"] == histories[1].valid["total"]
    assert histories[0].train["total"] == histories[1].train["total"]


def test_with_two_entropy_variables_both_temperatures_are_read_and_none_is_negative():
    energy = mx.MLPPotential(4, width=8, depth=2, linear=True, key=jr.key(0))
    weight = energy.hidden.layers[0].weight
    energy = eqx.tree_at(lambda e: e.hidden.layers[0].weight, energy,
                         weight.at[:, 2:].set(0.0))  # E of (q, p) only
    rng = np.random.default_rng(2)
    qp = np.cumsum(0.1 * rng.normal(size=(80, 2)), axis=0)
    e = np.asarray(jax.vmap(energy)(jnp.column_stack([qp, np.zeros((80, 2))])))
    share = rng.uniform(0.2, 0.8, size=79)  # how the lost energy splits between the two
    lost = -np.diff(e)
    for t1, t2, expect in ((300.0, 40.0, (300.0, 40.0)), (300.0, -40.0, None)):
        s1 = np.concatenate([[0.0], np.cumsum(share * lost / t1)])
        s2 = np.concatenate([[1.0], 1.0 + np.cumsum((1 - share) * lost / t2)])
        data = mx.Trajectories(np.zeros(80, np.int64), 0.1 * np.arange(80.0),
                               np.column_stack([qp, s1, s2]))
        t = balance_temperatures(energy, data, [2, 3])
        if expect is not None:
            np.testing.assert_allclose(t, expect, rtol=1e-7)
        else:  # a negative one is zero, and the other fitted again without it
            assert t[1] == 0.0 and t[0] > 0.0
            refit = -np.dot(np.diff(e), np.diff(s1)) / np.dot(np.diff(s1), np.diff(s1))
            assert t[0] == pytest.approx(refit, rel=1e-7)
