"""Figures stay readable when rollouts fail and when there are many variables (#14): finite
axes, failures marked and counted, a label on every axis, legends beside the lines, never
over them. Warnings are errors here, so every figure also renders without one."""

import jax.numpy as jnp
import matplotlib.pyplot as plt
import numpy as np
import pytest

import metriplex as mx
from metriplex import plots
from metriplex.runs import report_figures

FIGURES = ("trajectories", "error", "residual", "energy_entropy")


def _check_axes(fig):
    """Every visible panel has a y label, an x label where its x axis is numbered (panels
    that share the bottom panel's time axis are not), and finite limits."""
    fig.canvas.draw()
    for ax in fig.axes:
        if not ax.axison:
            continue
        assert ax.get_ylabel(), ax.get_title()
        if any(t.get_visible() and t.get_text() for t in ax.get_xticklabels()):
            assert ax.get_xlabel(), (ax.get_title(), ax.get_ylabel())
        assert np.all(np.isfinite(ax.get_ylim())) and np.all(np.isfinite(ax.get_xlim()))


def _legend_outside(ax):
    """The legend's box and the axes' box do not overlap (up to a pixel)."""
    legend = ax.get_legend()
    r = ax.figure.canvas.get_renderer()
    lb, ab = legend.get_window_extent(r), ax.get_window_extent(r)
    return lb.x0 >= ab.x1 - 1 or lb.x1 <= ab.x0 + 1 or lb.y0 >= ab.y1 - 1 or lb.y1 <= ab.y0 + 1


def test_error_figure_of_failed_rollouts_has_a_readable_axis_and_counts_the_failures():
    # 20 trajectories, 3 of which blow up (1e13 before the step that fails, then NaN), one
    # with a denormal error (1e-315) and an exact zero at t = 0: what made the axis span
    # 1e-315 ... 1e13.
    T, K = 50, 20
    ts = np.tile(np.linspace(0.0, 5.0, T), (K, 1))
    rng = np.random.default_rng(0)
    err = np.abs(rng.normal(size=(K, T))) * 1e-2
    err[:, 0] = 0.0
    err[1, 5] = 1e-315
    failed = np.full(K, -1)
    for k, step in ((3, 30), (7, 12), (11, 1)):
        failed[k] = step
        err[k, step - 1] = 1e13
        err[k, step:] = np.nan
    per_var = {f"x{i}": err[0] * (i + 1) for i in range(3)}
    fig = plots.rollout_errors(ts, err, failed_step=failed, per_variable=per_var, trajectory=0)
    _check_axes(fig)
    left = fig.axes[0]
    assert "3 of 20 failed" in left.get_title()
    lo, hi = left.get_ylim()
    assert lo >= 1e-14 and hi <= 10 * plots.ERROR_CEILING, (lo, hi)
    marks = [ln for ln in left.get_lines() if ln.get_marker() == "x" and len(ln.get_xdata())]
    assert len(marks) == 3
    assert sorted(float(m.get_xdata()[0]) for m in marks) == sorted(
        float(ts[0, s]) for s in (30, 12, 1))
    plt.close(fig)
    # The single-trajectory figure of the experiments: the same axis rules, the failure marked.
    e = err[3].copy()
    fig = plots.error_over_time(ts[3], e, reference=err[0], failed_at=float(ts[3, 30]))
    _check_axes(fig)
    lo, hi = fig.axes[0].get_ylim()
    assert lo >= 1e-14 and hi <= 10 * plots.ERROR_CEILING
    assert "failed at t = " in fig.axes[0].get_title()
    plt.close(fig)


def test_many_variables_name_the_largest_and_keep_the_legend_off_the_lines():
    T, n = 30, 50
    ts = np.linspace(0.0, 3.0, T)
    rng = np.random.default_rng(1)
    names = [f"v{i}" for i in range(n)]
    per_var = {name: (1.0 + 0.5 * np.sin(ts)) * (i + 1) for i, name in enumerate(names)}
    fig = plots.rollout_errors(np.tile(ts, (2, 1)), np.abs(rng.normal(size=(2, T))),
                               per_variable=per_var, trajectory=0)
    _check_axes(fig)
    right = fig.axes[1]
    labels = right.get_legend_handles_labels()[1]
    assert len(labels) == plots.MAX_LABELS + 1 and labels[-1] == "other 42 variables"
    assert set(labels[:-1]) == {f"v{i}" for i in range(n - plots.MAX_LABELS, n)}  # the largest
    assert _legend_outside(right)
    plt.close(fig)
    fig = plots.residual_over_time(ts[1:], rng.normal(size=(T - 1, n)), names)
    _check_axes(fig)
    assert _legend_outside(fig.axes[0])
    plt.close(fig)
    fig = plots.trajectories(ts, rng.normal(size=(T, n)), rng.normal(size=(T, n)), names)
    _check_axes(fig)
    assert "first 12 of 50 variables" in fig.get_suptitle()
    plt.close(fig)


def test_a_variable_has_one_colour_in_every_figure_and_the_bold_trajectory_is_named():
    # A new-user check: error.png drew q orange and p green, residual.png the other way round
    # (colours by rank of size, which differs between the figures); the bold trajectory of the
    # left panel was in no legend.
    T = 30
    ts = np.linspace(0.0, 3.0, T)
    names = ["q", "p", "s"]
    errors = {"q": np.full(T, 1e-3), "p": np.full(T, 1e-1), "s": np.full(T, 1e-2)}
    fig = plots.rollout_errors(np.tile(ts, (2, 1)), np.full((2, T), 1e-2), per_variable=errors,
                               trajectory=1, ids=[4, 7])
    colours = {line.get_label(): line.get_color() for line in fig.axes[1].get_lines()}
    assert "trajectory 7, per variable at right" in fig.axes[0].get_legend_handles_labels()[1]
    plt.close(fig)
    residual = np.stack([np.full(T - 1, v) for v in (1e-1, 1e-3, 1e-2)], axis=1)  # p smallest
    fig = plots.residual_over_time(ts[1:], residual, names)
    again = {line.get_label(): line.get_color() for line in fig.axes[0].get_lines()}
    plt.close(fig)
    assert {k: colours[k] for k in names} == {k: again[k] for k in names}
    assert len({colours[k] for k in names}) == 3
    # None named is grey, the colour of the unnamed ones (matplotlib's C7 is).
    many = {f"v{i}": np.full(T, 1.0 + i) for i in range(9)}
    fig = plots.residual_over_time(ts[1:], np.stack([v[1:] for v in many.values()], 1), list(many))
    named = [line.get_color() for line in fig.axes[0].get_lines() if line.get_label() in many]
    plt.close(fig)
    assert "C7" not in named and len(set(named)) == len(named)


def _blow_up(c):
    """p' = -c (p^2 + 1): p = tan(...) blows up, sooner from some states than from others."""
    return mx.GenericModel(mx.Known(lambda x: c * x[0] * (x[1] ** 2 + 1.0)), mx.SumOf((2,)),
                           mx.CanonicalPoisson(3, 1), mx.ZeroFriction(3))


def test_report_figures_of_failing_rollouts(tmp_path):
    ts = np.arange(21) * 0.1
    xs = np.random.default_rng(0).normal(size=(8, 21, 3))
    # Ragged: trajectory 3 (the one drawn, and it fails) is shorter than the padded grid.
    data = mx.Trajectories.from_list([(ts[:T], x[:T]) for x, T in zip(xs, [21, 18, 21, 19] * 2)],
                                     ("q", "p", "s"))
    report_figures(_blow_up(0.5), data, tmp_path, scheme="rk4", k=3)
    for name in FIGURES:
        for ext in ("png", "pdf", "npz"):
            assert (tmp_path / f"{name}.{ext}").is_file(), (name, ext)
    with np.load(tmp_path / "error.npz") as raw:
        failed, error = raw["failed_step"], raw["error"]
    assert failed[3] >= 0 and 0 < np.sum(failed >= 0) < len(failed)
    # A failed rollout has no error after its failure: NaN, never a number standing for it.
    for k in np.flatnonzero(failed >= 0):
        assert np.all(np.isnan(error[k, failed[k]:]))
    with np.load(tmp_path / "energy_entropy.npz") as saved:
        energy = saved["energy"]
    assert np.all(np.isnan(energy[failed[3]:])) and np.all(np.isfinite(energy[:failed[3]]))


def test_a_tiny_change_of_the_energy_is_drawn_flat_and_the_data_beside_the_rollout():
    # An autoscaled axis made a relative change of 5e-5 fill the panel, under an offset label
    # that overlapped the title (found by a new-user check of the verdict).
    ts = np.linspace(0.0, 2.0, 21)
    E = 38.93 + 2e-3 * np.floor(ts)  # steps of 2e-3 where the data's energies spread over 20
    S = np.linspace(1.0, 1.5, 21)
    fig = plots.energy_entropy(ts, E, S, E_data=E + 1e-4, S_data=S[::-1], spreads=(20.0, 2.0))
    energy, entropy = fig.axes
    lo, hi = energy.get_ylim()
    assert hi - lo >= 0.2 - 1e-9  # at least 1% of the spread: the steps look as small as they are
    fig.canvas.draw()
    assert not energy.yaxis.get_offset_text().get_text()
    labels = [line.get_label() for line in energy.get_lines()]
    assert "learned E along the data" in labels and "learned E along the learned rollout" in labels
    assert entropy.get_ylim()[1] - entropy.get_ylim()[0] < 1.0  # wider data: autoscaled as before
    # The title says how much the rollout moves, against the spread over the data (an axis
    # 1 % of it still made a 0.26 % drift look like a first-law violation: audit 8), and how
    # much the learned E moves along the data (29 % of its spread where the data were noisy,
    # under a title that spoke of the rollout alone: audit 9).
    title = energy.get_title()
    assert "on the rollout: moves by 0.004, 0.02% of its spread over the data" in title
    assert "on the data: moves by 0.004, 0.02% of its spread over the data" in title
    # ... and by how much it drifts beyond noise and oscillation, what the metric
    # energy_change_along_data_over_spread reads (a new-user check saw 1.80 % here, 0.36 % there).
    from metriplex._roughness import range_beyond_noise
    drift = range_beyond_noise(E + 1e-4, ts) / 20.0
    assert f"(drift beyond noise: {drift:.2%})" in title and 0 < drift <= 0.004 / 20
    assert "drift beyond noise" not in entropy.get_title()
    assert "on the rollout: moves by 0.5, 25.00% of its spread" in entropy.get_title()
    plt.close(fig)


def test_an_energy_constant_to_rounding_is_called_so_not_said_to_move_by_zero():
    # A new-user check's figure read "moves by 0, 0.00% of its spread" for an E of spread 1e-9
    # at 0.084 in float32, beside a warning that it moved by 0.89 of that spread.
    ts = np.linspace(0.0, 2.0, 21)
    E = np.full(21, -0.0843)
    fig = plots.energy_entropy(ts, E, np.linspace(1.0, 1.5, 21), E_data=E,
                               spreads=(4.5e-8, 2.0), energy_rounding=0.22)
    energy, entropy = fig.axes
    assert "constant over the data to rounding (0.22 of its spread" in energy.get_title()
    assert "no energy learned" in energy.get_title() and "moves by" not in energy.get_title()
    lo, hi = energy.get_ylim()
    assert lo < -0.0843 < hi and hi - lo > 1e-3  # flat, not rounding steps filling the panel
    assert "moves by" in entropy.get_title()
    plt.close(fig)


def test_a_rollout_that_fails_at_its_first_step_still_draws_on_the_whole_time_axis():
    ts = np.linspace(0.0, 2.0, 21)
    E = np.full(21, np.nan)
    E[0] = 33.2
    fig = plots.energy_entropy(ts, E, -E, failed_at=0.1)
    _check_axes(fig)
    for ax in fig.axes:
        assert ax.get_xlim() == (0.0, 2.0)
        assert ax.get_lines()[0].get_marker() == "o"  # one point, drawn as a point
        assert "failed at t = 0.1" in ax.get_title()
    plt.close(fig)
    fig = plots.rollout_errors(ts[None, :], np.full((1, 21), np.nan), failed_step=[1])
    _check_axes(fig)
    assert "1 of 1 failed" in fig.axes[0].get_title()
    assert fig.axes[0].get_xlim() == (0.0, 2.0)
    plt.close(fig)


def test_report_figures_with_fifty_variables(tmp_path):
    n = 50
    w = jnp.linspace(0.5, 3.0, n // 2)
    chain = mx.GenericModel(
        mx.Known(lambda x: 0.5 * jnp.sum(w**2 * x[: n // 2] ** 2 + x[n // 2:] ** 2)),
        mx.ZeroPotential(), mx.CanonicalPoisson(n, n // 2), mx.ZeroFriction(n))
    ts = np.arange(16) * 0.1
    x0 = np.random.default_rng(2).uniform(-1.0, 1.0, (2, n))
    xs = np.asarray(mx.solve(chain, jnp.asarray(x0), jnp.asarray(ts), scheme=mx.RK4()).xs)
    noisy = xs + 1e-3 * np.random.default_rng(3).normal(size=xs.shape)
    data = mx.Trajectories.from_list([(ts, x) for x in noisy])
    report_figures(chain, data, tmp_path, scheme="rk4")
    for name in FIGURES:
        assert (tmp_path / f"{name}.png").is_file(), name
    with np.load(tmp_path / "error.npz") as saved:
        assert saved["error_per_variable"].shape == (16, n)


def test_a_loss_term_that_is_exactly_zero_does_not_stretch_the_loss_axis():
    # The temperature hinge is 0 at almost every evaluation; drawn at 1e-300, it made the axis
    # span 1e-314 ... 1e14 and the loss's fall over six decades a flat line.
    from metriplex._train import History

    steps = list(range(0, 500, 10))
    fall = list(np.geomspace(0.17, 7e-7, len(steps)))
    history = History(step=steps, best_step=400,
                      train={"residual": fall, "temperature": [3e-7] + [0.0] * (len(steps) - 1),
                             "total": fall},
                      valid={"residual": fall, "total": fall})
    fig = plots.loss_curves(history)
    _check_axes(fig)
    lo, hi = fig.axes[0].get_ylim()
    assert 1e-8 < lo < 7e-7 and 0.17 < hi < 1.0, (lo, hi)
    plt.close(fig)


def test_the_report_shows_the_worst_trajectory_and_names_it(tmp_path):
    # One bad trajectory among good ones was never drawn: the figures showed the first.
    oscillator = mx.GenericModel(mx.Known(lambda x: 0.5 * (x[0] ** 2 + x[1] ** 2)),
                                 mx.SumOf((2,)), mx.CanonicalPoisson(3, 1), mx.ZeroFriction(3))
    ts = np.arange(41) * 0.05
    starts = [(1.0, 0.0), (0.5, 0.5), (0.0, 1.0), (-1.0, 0.3)]
    xs = [np.stack([a * np.cos(ts) + b * np.sin(ts), b * np.cos(ts) - a * np.sin(ts),
                    np.zeros_like(ts)], axis=1) for a, b in starts]
    xs[2][1:, :2] *= 1.5  # observed trajectory 2 is not the model's
    data = mx.Trajectories.from_list([(ts, x) for x in xs], ("q", "p", "s"))
    report_figures(oscillator, data, str(tmp_path / "worst"))  # a str folder, like mx.save's
    for k in (4, -1, 2.0):  # a position in the data, not an id; refused before any rollout
        with pytest.raises(mx.MetriplexError, match=r"k is the position of a trajectory"):
            report_figures(oscillator, data, tmp_path / "bad", k=k)
    for name in ("trajectories", "error"):
        with np.load(tmp_path / "worst" / f"{name}.npz") as saved:
            assert int(saved["trajectory" if name == "trajectories" else "shown"]) == 2
    # Where rollouts fail, the first to fail.
    rng = np.random.default_rng(0)
    data = mx.Trajectories.from_list([(ts[::2], rng.normal(size=(21, 3))) for _ in range(8)],
                                     ("q", "p", "s"))
    report_figures(_blow_up(0.5), data, tmp_path / "failed", scheme="rk4")
    with np.load(tmp_path / "failed" / "error.npz") as saved:
        failed, shown = saved["failed_step"], int(saved["shown"])
    assert 0 < np.sum(failed >= 0) < len(failed)
    assert failed[shown] >= 0 and failed[shown] == failed[failed >= 0].min()


def test_the_error_figure_is_standardised_so_an_offset_does_not_shrink_it(tmp_path):
    # A new-user check's bath entropy near 1000 drew rollout errors of 1e-5 (the relative
    # error, which the offset shrinks) where evaluate's standardised error was 7e-3.
    oscillator = mx.GenericModel(mx.Known(lambda x: 0.5 * (x[0] ** 2 + x[1] ** 2)),
                                 mx.SumOf((2,)), mx.CanonicalPoisson(3, 1), mx.ZeroFriction(3))
    ts = np.arange(41) * 0.05
    xs = [np.stack([a * np.cos(ts) + b * np.sin(ts), b * np.cos(ts) - a * np.sin(ts),
                    np.linspace(0.0, 0.2, len(ts))], axis=1)
          for a, b in [(1.0, 0.0), (0.5, 0.5), (0.0, 1.0)]]
    xs[1] = xs[1] * np.array([1.1, 1.1, 1.0])  # one trajectory the model misses
    saved = {}
    for offset in (0.0, 1000.0):
        data = mx.Trajectories.from_list([(ts, x + [0.0, 0.0, offset]) for x in xs],
                                         ("q", "p", "s"))
        report = mx.evaluate(oscillator, data, scheme=mx.RK4())
        report_figures(oscillator, data, tmp_path / str(offset), scheme="rk4")
        with np.load(tmp_path / str(offset) / "error.npz") as error:
            saved[offset] = error["error"]
        # Each curve's root mean square over time is the trajectory's standardised error.
        rms = np.sqrt(np.nanmean(saved[offset] ** 2, axis=1))
        assert np.mean(rms) == pytest.approx(report["rollout_error_standardised_mean"],
                                             rel=1e-6)
    np.testing.assert_allclose(saved[1000.0], saved[0.0], rtol=1e-6, atol=1e-9)
    assert np.nanmax(saved[0.0]) > 1e-2


def test_the_worst_trajectory_is_the_first_to_fail_whatever_the_integer_width():
    # JAX's int32 failed steps wrapped the int64 sentinel to -1, so a trajectory that had not
    # failed (the first) was shown as "the worst" beside one that had.
    from metriplex._solve.rollout import Rollout
    from metriplex.app._report import worst_trajectory

    for failed in ([-1, -1, 24, -1], [-1, 30, 12, -1]):
        out = Rollout(np.zeros((4, 3)), np.zeros((4, 3, 1)), np.asarray(failed, np.int32),
                      np.zeros(4, np.int32))
        assert worst_trajectory(out, np.zeros((4, 3, 1)), [3] * 4) == int(np.argmin(
            [f if f >= 0 else 99 for f in failed]))


def test_the_report_draws_the_learned_temperatures_with_what_the_data_determine(tmp_path):
    # Where S is a sum of entropy variables the report adds dE/ds_i at the data's states (a
    # physicist asking "what are its temperatures?" had only their least value: audit 8).
    import jax
    import jax.numpy as jnp

    from metriplex.app._temperature_plot import fit_clause, temperatures
    from metriplex.systems import generate, get_system

    truth = get_system("heat-exchange").model
    data = generate("heat-exchange", trajectories=2, steps=10, seed=0)
    report_figures(truth, data, tmp_path / "sum", scheme="rk4")
    with np.load(tmp_path / "sum" / "temperatures.npz") as saved:
        s, T, names = saved["entropy_variables"], saved["temperature"], saved["names"]
    assert list(names) == list(data.names) and len(s) == len(data.x)
    true = jax.vmap(jax.grad(truth.energy))(jnp.asarray(s))
    np.testing.assert_allclose(T, true, rtol=1e-12)
    fig = temperatures(s, T, list(names), gauge="ratios")
    assert "only their ratios are determined" in fig.get_suptitle()
    plt.close(fig)
    # Where nothing is free, the title says how well the model fits, not that the
    # temperatures are accurate (new-user checks 26 and 28: rollouts 8 % off, 0.56-1.0 of the
    # true temperatures, under "as accurate as the fit").
    errors = np.array([[0.0, 0.1, 0.1], [0.0, 0.2, np.nan], [0.0, 5.0, np.nan]])
    clause = fit_clause(errors, np.array([-1, -1, 2]))
    assert clause == " (its rollouts of these data err by 0.11 of their spread, " \
        "standardised; 1 of 3 failed)", clause
    assert "no rollout" in fit_clause(errors, np.array([1, 1, 2]))
    fig = temperatures(s, T, list(names), gauge="determined", fit=clause)
    title = " ".join(fig.get_suptitle().split())
    assert "only as well as the model fits them (its rollouts" in title and "{" not in title
    plt.close(fig)
    learned = mx.GenericModel(mx.Known(lambda x: x @ x), mx.Known(lambda x: x[0]),
                              mx.ZeroPoisson(2), mx.ZeroFriction(2))
    report_figures(learned, data, tmp_path / "other", scheme="rk4")
    assert not list((tmp_path / "other").glob("temperatures.*"))


def test_the_error_axis_is_not_stretched_by_the_rounding_of_the_first_state():
    # A float32 rollout starts at the data's state up to rounding (1e-8); that point set the
    # axis's floor, squeezing the errors of 1e-2 into its top sixth (audit 9).
    ts = np.linspace(0.0, 5.0, 51)
    err = np.full(51, 2e-2)
    err[0] = 1e-8
    for fig in (plots.error_over_time(ts, err, per_variable={"q": err, "p": 0.5 * err}),
                plots.rollout_errors(ts[None], err[None], per_variable={"q": err})):
        for ax in fig.axes:
            assert ax.get_ylim()[0] > 1e-4, ax.get_title()
        plt.close(fig)
