"""``--reversible-first`` and ``--w-temperature``: the options against a friction that
carries the motion (README, *Friction that carries the motion*)."""

import dataclasses

import equinox as eqx
import jax.numpy as jnp
import jax.random as jr
import pytest

import metriplex as mx
from metriplex import MetriplexError
from metriplex.app.config import (
    PRESETS,
    RunConfig,
    confine_margin,
    confine_on,
    exact_blocks,
    hold_energy_on,
    preset,
    reversible_first_on,
    temperature_init_on,
    temperature_weight,
    validate,
)
from metriplex.app._build import build_loss, build_model, units_for
from metriplex.app._stages import reversible_first
from metriplex.app.runs import train_run
from metriplex.systems import generate


def test_reversible_first_starts_the_main_training_from_a_trained_energy(tmp_path, capsys):
    data = generate("oscillator-bath", trajectories=6, steps=40, seed=0)
    config = RunConfig(poisson="canonical:1", entropy="sum:2", steps=300, eval_every=50,
                       average_steps=0, validation=0.34, reversible_first=False,
                       w_temperature=0.0, repeats=1, starts=1)
    # Only the main training's first evaluation (its start) is compared: the cold run needs
    # no more steps than one evaluation, and neither run another training or start.
    _, cold, _, _, _ = train_run(data, dataclasses.replace(config, steps=50), tmp_path / "cold",
                                 progress=False)
    assert "reversible first" not in capsys.readouterr().err
    first = dataclasses.replace(config, reversible_first=True, w_temperature=1.0)
    _, warm, _, _, _ = train_run(data, first, tmp_path / "warm", progress=False)
    err = capsys.readouterr().err
    assert "reversible first: L grad E alone" in err
    # the energy balance's temperature is of order one in the networks' units here: not set
    assert "temperatures from the energy balance" not in err
    # The main training's first evaluation already has an energy that drives the motion.
    assert warm.valid["total"][0] < 0.5 * cold.valid["total"][0]
    assert "temperature" in warm.train and "temperature" not in cold.train


@pytest.mark.parametrize("changes,match", [
    (dict(w_temperature=1.0), "--w-temperature .* --entropy sum:I,J,...; got --entropy neural"),
    (dict(reversible_first=True, friction="zero"),
     "--reversible-first .*--friction neural or exchange"),
    (dict(reversible_first=True, poisson="zero"), "got --friction neural --poisson zero"),
    (dict(w_temperature=-1.0, entropy="sum:2"), r"--w-temperature \(a loss weight\) must be >= 0"),
    (dict(hold_energy=True, reversible_first=False), "--hold-energy .* needs that stage"),
    (dict(temperature_init=True), "--temperature-init .*--entropy neural --energy neural"),
    (dict(temperature_init=True, entropy="sum:2", reversible_first=False),
     "--temperature-init .* without the first stage"),
    # a learned L trades a gauge with E: no balance to read
    (dict(temperature_init=True, entropy="sum:2"), "--temperature-init .*got --poisson neural"),
])
def test_the_thermal_options_refuse_what_they_cannot_do(changes, match):
    with pytest.raises(MetriplexError, match=match):
        validate(dataclasses.replace(RunConfig(), **changes), 3)


def test_temperatures_are_not_read_for_an_energy_that_reads_features():
    config = RunConfig(poisson="canonical:4", entropy="sum:8,9", features="pendulum")
    assert reversible_first_on(config) and not temperature_init_on(config)
    with pytest.raises(MetriplexError, match="--temperature-init .*--features pendulum"):
        validate(dataclasses.replace(config, temperature_init=True), 10)


@pytest.mark.parametrize("structure,on", [
    (dict(poisson="canonical:1", entropy="sum:2"), True),
    (dict(entropy="sum:2"), True),
    (dict(poisson="zero", entropy="sum:0,1"), False),  # no L to drive the motion
    (dict(poisson="canonical:1", entropy="sum:2", friction="zero"), False),
    (dict(entropy="zero"), False),  # no S: M grad S = 0, the friction does nothing
    (dict(), True),  # all learned: no entropy variables, so no hinge (below)
])
def test_by_default_reversible_first_the_hinge_and_exact_m_go_together(structure, on):
    config = RunConfig(**structure)
    assert reversible_first_on(config) is on
    hinge = on and config.entropy.startswith("sum:")
    assert temperature_weight(config) == (1.0 if hinge else 0.0)
    # temperatures read where the hinge holds them and a given L fixes E up to a constant
    assert temperature_init_on(config) is (hinge and config.poisson != "neural")
    assert exact_blocks(config)[1] is (on and config.friction == "neural")
    # Said explicitly, each wins over the default.
    off = dataclasses.replace(config, reversible_first=False, w_temperature=0.0)
    assert not reversible_first_on(off) and temperature_weight(off) == 0.0
    assert not exact_blocks(off)[1]


@pytest.mark.parametrize("name", sorted(PRESETS))
def test_the_presets_keep_what_they_were_tuned_with(name):
    config = preset(name)
    assert not reversible_first_on(config) and temperature_weight(config) == 0.0
    assert not confine_on(config)


@pytest.mark.parametrize("structure,on", [
    (dict(poisson="canonical:1", entropy="sum:2"), True),  # S given, M grad E = 0 exact
    (dict(entropy="sum:2"), True),
    (dict(), True),  # S learned: E conserved too, the wall further out (confine_margin)
    (dict(degeneracy="soft"), False),
    (dict(entropy="zero"), False),  # no S: no first stage, M grad E = 0 not exact
    (dict(poisson="canonical:1", entropy="sum:2", degeneracy="soft"), False),  # E not conserved
    (dict(poisson="canonical:1", entropy="sum:2", friction="zero"), False),
    (dict(poisson="zero", entropy="sum:0,1"), False),
    # M given: exact degeneracy applies to learned blocks only, so E need not be conserved
    (dict(entropy="sum:2", friction="file:M.npy", degeneracy="exact"), False),
])
def test_the_wall_is_on_by_default_where_e_is_conserved(structure, on):
    config = RunConfig(**structure)
    assert confine_on(config) is on
    assert confine_on(dataclasses.replace(config, confine=not on)) is (not on)
    # One standard deviation out where S is given, three where it is learned.
    assert confine_margin(config) == (3.0 if config.entropy == "neural" else 1.0)


def test_the_wall_begins_three_standard_deviations_out_where_s_is_learned():
    data = generate("oscillator-bath", trajectories=4, steps=20, seed=0)
    for structure, margin in ((dict(), 3.0), (dict(poisson="canonical:1", entropy="sum:2"), 1.0)):
        model = build_model(RunConfig(**structure), data, key=jr.key(0))
        assert model.energy.confinement == mx.Confinement.around(data.x, margin)


def test_the_first_stage_trains_the_energy_with_the_wall_the_main_model_has():
    data = generate("oscillator-bath", trajectories=4, steps=20, seed=0)
    config = RunConfig(poisson="canonical:1", entropy="sum:2", steps=40, eval_every=20,
                       average_steps=0, validation=0.0)
    units = units_for(config, data)
    start = build_model(config, data, key=jr.key(0), units=units)
    assert start.energy.confinement is not None
    model = reversible_first(start, config, data, None, units=units, constant=(),
                             dtype=jnp.float64, key=jr.key(1),
                             main_loss=build_loss(config, units, data))
    assert model.energy.confinement == start.energy.confinement


def test_max_minutes_caps_both_stages(tmp_path, capsys):
    data = generate("oscillator-bath", trajectories=6, steps=40, seed=0)
    # 0.06 s: less than compiling one step takes on any machine, so both stages stop at their
    # first evaluation, whatever the machine's speed.
    config = RunConfig(poisson="canonical:1", entropy="sum:2", steps=5000, eval_every=50,
                       average_steps=0, validation=0.34, max_minutes=0.001)
    _, history, _, _, _ = train_run(data, config, tmp_path / "run", progress=False)
    err = capsys.readouterr().err
    assert "reversible first: L grad E alone, time budget reached" in err
    assert history.stopped.startswith("time budget reached")


def test_with_s_learned_reversible_first_adds_no_temperature_hinge():
    # Everything learned: training starts from L grad E, but without entropy variables there
    # are no temperatures dE/ds_i to hinge on.
    config = RunConfig()
    assert reversible_first_on(config) and temperature_weight(config) == 0.0
    assert exact_blocks(config) == (False, True)


def _stage_fits(monkeypatch):
    """The models that the stages' ``fit`` calls return, in order."""
    import metriplex.app._stages as stages

    fits, real_fit = [], stages.fit

    def spy(*args, **kwargs):
        model, history = real_fit(*args, **kwargs)
        fits.append(model)
        return model, history

    monkeypatch.setattr(stages, "fit", spy)
    return fits


def _reversible_first(config, data):
    units = units_for(config, data)
    start = build_model(config, data, key=jr.key(0), units=units)
    return start, reversible_first(start, config, data, None, units=units, constant=(),
                                   dtype=jnp.float64, key=jr.key(1),
                                   main_loss=build_loss(config, units, data))


@pytest.mark.parametrize("poisson", ["neural", "casimir3", "lie-poisson"])
def test_every_learned_l_of_the_first_stage_is_carried_into_the_main_one(poisson, monkeypatch):
    data = generate("relaxing-rigid-body", trajectories=4, steps=20, seed=0)
    # One start: the carry is the same after the best of several (tests/test_starts.py).
    config = RunConfig(poisson=poisson, steps=40, eval_every=20, average_steps=0,
                       validation=0.0, starts=1)
    assert not hold_energy_on(config)  # off by default: the first stage is the last fit
    fits = _stage_fits(monkeypatch)
    start, model = _reversible_first(config, data)
    assert bool(eqx.tree_equal(model.poisson, fits[-1].poisson))
    assert bool(eqx.tree_equal(model.energy, fits[-1].energy))
    assert bool(eqx.tree_equal(model.friction, start.friction))
    # The first stage did train L: it is not the L the main model was built with.
    assert not bool(eqx.tree_equal(model.poisson, start.poisson))


def test_hold_energy_trains_the_rest_to_the_first_stage_energy(monkeypatch):
    data = generate("relaxing-rigid-body", trajectories=4, steps=20, seed=0)
    config = RunConfig(steps=40, eval_every=20, average_steps=0, validation=0.0, starts=1,
                       hold_energy=True)
    fits = _stage_fits(monkeypatch)
    start, model = _reversible_first(config, data)
    # Two fits: L grad E alone, then the rest with E held.
    assert len(fits) == 2
    first, held = fits
    assert isinstance(first.friction, mx.ZeroFriction) and isinstance(held.energy, mx.Known)
    assert bool(eqx.tree_equal(model.energy, first.energy))
    assert bool(eqx.tree_equal(model.poisson, held.poisson))
    assert bool(eqx.tree_equal(model.friction, held.friction))
    # The first stage trained L, the held one M: neither is what the model was built with.
    assert not bool(eqx.tree_equal(model.poisson, start.poisson))
    assert not bool(eqx.tree_equal(model.friction, start.friction))


def test_the_command_line_spells_hold_energy():
    from metriplex.app._commands import _config_from_args
    from metriplex.app.cli import build_parser

    for flag, value in (("--hold-energy", True), ("--no-hold-energy", False), (None, None)):
        argv = ["train", "d.npz", "--out", "r"] + ([flag] if flag else [])
        assert _config_from_args(build_parser().parse_args(argv)).hold_energy is value
