"""What the data can determine of a learned E, S and temperatures (``identified``): the gauges
that leave the flow unchanged, said wherever the learned E or S is shown (audit: with L = 0 a
negative energy of the right flow was told its data were not GENERIC)."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np
import pytest

import metriplex as mx
from metriplex import systems
from metriplex.app._build import build_model
from metriplex.app._warnings import structure_warnings
from metriplex.config import RunConfig
from metriplex.diagnostics import identified
from metriplex.verdict import train_reference, verdict


@pytest.mark.parametrize("flags,gauges", [
    (dict(poisson="canonical:1", entropy="sum:2"), ("constant", "given", "determined")),
    (dict(poisson="zero", entropy="sum:2"), ("function", "given", "ratios")),
    (dict(poisson="canonical:1"), ("constant", "function", "none")),
    (dict(), ("factor", "function", "none")),
    (dict(poisson="lie-poisson", entropy="sum:2"), ("factor", "given", "factor")),
    (dict(entropy="zero", friction="zero"), ("factor", "zero", None)),
    (dict(poisson="zero", entropy="sum:2", friction="zero"), ("none", "given", "ratios")),
    (dict(poisson="zero"), ("function", "function_of_energy", "none")),
])
def test_what_the_data_determine_follows_which_blocks_are_given(flags, gauges):
    data = systems.generate("oscillator-bath", trajectories=3, steps=5, seed=0)
    found = identified(build_model(RunConfig(**flags), data, key=jr.key(0)))
    assert (found["energy"], found["entropy"], found["temperatures"]) == gauges
    assert found["statement"].startswith("what the data determine: E ")
    assert "E" in found["learned"] and ("L" in found["learned"]) == (gauges[0] == "factor")


def test_with_l_zero_a_negative_energy_is_the_same_flow_and_no_violation():
    system = systems.get_system("heat-exchange")
    data = systems.generate(system, trajectories=6, steps=30, seed=1)
    truth = system.model
    flipped = eqx.tree_at(lambda m: m.energy, truth, mx.Known(lambda x: -truth.energy(x)))
    x = jnp.asarray(data.x[::7])
    np.testing.assert_allclose(jax.vmap(flipped.vector_field)(x),
                               jax.vmap(truth.vector_field)(x), rtol=1e-12)
    report = mx.evaluate(flipped, data, scheme=mx.RK4())
    assert report["temperature_negative_fraction"] == 1.0
    assert report["identified"]["temperatures"] == "ratios"
    assert not any("feeds the motion" in w for w in structure_warnings(report))
    # A learned energy in its place is told what the data determine of it.
    learned = build_model(RunConfig(poisson="zero", entropy="sum:0,1"), data, key=jr.key(0))
    sr = mx.diagnostics.structure_residuals(learned, data.x)
    assert sr["identified"]["learned"] == ["E", "M"]
    (line,) = [w for w in structure_warnings(sr) if w.startswith("note:")]
    assert line.startswith("note: what the data determine: E only up to a function of itself")
    assert "only the ratios of the temperatures" in line
    # a reactor's M conserves the amount of matter too: a new-user check's E was mostly that
    assert "any F(E, C)" in line
    reference = train_reference(data, steps=300, width=8)  # the truth fits alone (< 3 %)
    same = [verdict(m, data, report=r, converged=True, reference=reference)
            for m, r in ((truth, mx.evaluate(truth, data, scheme=mx.RK4())), (flipped, report))]
    assert same[0]["outcome"] == same[1]["outcome"], [v["statement"] for v in same]
    temps = [r for r in same[1]["reasons"] if r["name"] == "temperatures"][0]
    # With L = 0 what is checked is that one state's temperatures share a sign.
    assert temps["passed"] is True and temps["value"] == 0.0
    assert "with L = 0 the sign of E is free" in temps["note"]
    assert same[1]["outcome"] == "consistent", same[1]["statement"]
    # ... of the structure, not the accuracy, which it names (a new-user check read
    # "consistent" of rollouts 14 % off as a good model).
    err = report["rollout_error_standardised_mean"]
    assert f"not the accuracy: the rollouts err by {err:.3g} in standard deviations" in \
        same[1]["statement"]
    # ... with the median and the worst trajectory: a mean can be one or two trajectories'
    # (new-user check 27: mean 0.076, median 0.011, two of eight crossing a separatrix).
    each = report["rollout_error_standardised"]
    assert len(each) == len(data.ids) and np.isclose(np.mean(each), err)
    worst = int(np.argmax(each))
    assert (f"median {np.median(each):.3g}, the worst (trajectory {data.ids[worst]}) "
            f"{each[worst]:.3g})") in same[1]["statement"]
    from metriplex._verdict_outcome import _accuracy
    uneven = _accuracy({"rollout_error_standardised_mean": 0.076, "trajectory_ids": [4, 7, 9],
                        "rollout_error_standardised": [0.01, 0.5, 0.012]})
    assert "median 0.012, the worst (trajectory 7) 0.5)" in uneven, uneven
    # two trajectories, or a failed one (its error inf), or an older report: the mean alone
    for each in ([0.01, 0.5], [0.01, np.inf, 0.012], None):
        said = _accuracy({"rollout_error_standardised_mean": 0.076,
                          "rollout_error_standardised": each})
        assert said.endswith("(rollout_error_standardised_mean)."), said
    assert same[1]["statement"].endswith("What the data determine: E is given; S is given.")
    # Temperatures of both signs in one state are no choice of E's sign (new-user check 14:
    # "a choice of E's sign, not an error" said of a nine-cell grid where most states had
    # both): the note says so and the check fails.
    from metriplex._verdict_checks import _temperature_check
    from metriplex.verdict import Thresholds

    mixed = eqx.tree_at(lambda m: m.energy, truth, mx.Known(
        lambda x: truth.energy(x) - 2.0 * truth.energy(x.at[0].set(data.x[0, 0]))))
    sr = mx.diagnostics.structure_residuals(mixed, data.x)
    assert sr["temperature_mixed_fraction"] == 1.0 and sr["temperature_negative_fraction"] == 0.5
    check = _temperature_check(sr, Thresholds(), {})
    assert check["passed"] is False and "not the energy up to its gauge" in check["note"]
    as_learned = {**sr, "identified": {**sr["identified"], "learned": ["E", "M"],
                                       "energy": "function"}}  # the note speaks of a learned E
    (line,) = [w for w in structure_warnings(as_learned) if w.startswith("note:")]
    assert "at 100% of the states they have both signs, which no sign of E gives" in line


def test_a_learned_entropy_says_its_temperatures_are_not_determined():
    data = systems.generate("oscillator-bath", trajectories=3, steps=5, seed=0)
    model = build_model(RunConfig(poisson="canonical:1"), data, key=jr.key(0))
    report = mx.diagnostics.structure_residuals(model, data.x)
    assert report["temperature_min"] is None
    assert "S is learned, so the temperatures are not determined" in \
        report["null_reasons"]["temperature_min"]


def test_with_l_zero_s_is_fixed_only_up_to_a_function_of_s_and_e():
    # A new-user check's two rooms and a wall (L = 0, S learned): the learned S grew along
    # every trajectory but ordered states against the entropy (Spearman -0.72), and the note
    # said "up to an increasing function of itself". S + h(E) is the same flow: M grad E = 0.
    system = systems.get_system("heat-exchange")
    data = systems.generate(system, trajectories=4, steps=20, seed=2)
    truth = system.model
    E, S = mx.diagnostics.energy_entropy_along(truth, data.x)
    shifted = eqx.tree_at(lambda m: m.entropy, truth, mx.Known(
        lambda x: truth.entropy(x) - 3.0 * np.std(S) * ((truth.energy(x) - E.mean()) / E.std()) ** 2))
    x = jnp.asarray(data.x[::5])
    np.testing.assert_allclose(jax.vmap(shifted.vector_field)(x),
                               jax.vmap(truth.vector_field)(x), rtol=1e-9, atol=1e-12)
    learned = build_model(RunConfig(poisson="zero"), data, key=jr.key(0))
    (line,) = [w for w in structure_warnings(mx.diagnostics.structure_residuals(learned, data.x))
               if w.startswith("note:")]
    assert "S only up to G(S, E), any function that increases with S at fixed E" in line
