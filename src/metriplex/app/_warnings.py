"""What train and evaluate add to their figures when the figures alone could mislead: a model
that does not beat predicting no motion, learned temperatures that are negative, a learned
entropy that rises far more than the data's, a learned energy that does not drive the
motion or that the data do not conserve, a learned entropy that decreases, data whose time
is in another unit than the training data's, data that reach where the model was never
trained, data it was trained on, a validation part that does not move, samples that jump
away and back (outliers), and many variables that a state made of cells would fit better."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from ..verdict import Thresholds
from ._law_warnings import ENERGY_CHANGE as ENERGY_CHANGE  # noqa: F401 (re-exported)
from ._law_warnings import ENTROPY_RISE as ENTROPY_RISE  # noqa: F401 (re-exported)
from ._law_warnings import energy_change_warning, entropy_rise_warning
from ._horizon_note import every_note, predictability_note, step_warning

if TYPE_CHECKING:
    from .._units import Units
    from ..data import Trajectories

# The warnings fire where the verdict's structure checks fail: one limit for both.
_LIMITS = Thresholds()


#: Above this fraction of negative learned temperatures, train and evaluate warn (0 for every
#: true system of the zoo and of the reference experiments with S a sum of entropies). The
#: entropies' share of the energy gradient (``temperature_share``) is reported, not warned
#: on: a true system has it as low as 2.6e-4 (the spinning satellite).
NEGATIVE_TEMPERATURES = _LIMITS.negative_temperatures


def identified_note(metrics: dict) -> list[str]:
    """A note of what the data determine of the learned E, S and temperatures (evaluate's
    ``identified``, :func:`metriplex.diagnostics.identified`) where it is less than E up to a
    constant and S as given: a physicist reading the learned E or S needs its gauge."""
    ident = metrics.get("identified") or {}
    if not (("E" in ident.get("learned", ()) and ident.get("energy") != "constant")
            or str(ident.get("entropy")).startswith("function")):
        return []
    negative, mixed = (metrics.get(k) for k in ("temperature_negative_fraction",
                                                 "temperature_mixed_fraction"))
    sign = ""
    if ident.get("temperatures") == "ratios" and negative:
        sign = f" The learned temperatures are negative at {_share(negative)} of the states: " + (
            f"with L = 0 E's sign is free, but at {_share(mixed)} of the states they have both "
            "signs, which no sign of E gives: there this E is not the energy up to its gauge."
            if mixed and mixed > NEGATIVE_TEMPERATURES else
            "with L = 0 that is a choice of E's sign, not an error.")
    return [f"note: {ident['statement']}{sign} See the README, What the data determine."]


def _share(fraction: float) -> str:
    """A fraction as a percentage, with two significant digits under 1 %, never "0%" for a
    fraction that is not zero."""
    return f"{fraction:.0%}" if fraction >= 0.01 or fraction == 0 else f"{100 * fraction:.2g}%"


def temperature_warnings(metrics: dict) -> list[str]:
    """Warnings on the learned temperatures dE/ds_i (where S is a sum of entropy variables):
    negative ones feed the motion with the entropy production."""
    out = []
    negative = metrics.get("temperature_negative_fraction")
    if (metrics.get("identified") or {}).get("temperatures") == "ratios":
        return out  # L = 0: their sign is E's gauge (identified_note says so), not an error
    if negative is not None and negative > NEGATIVE_TEMPERATURES:
        out.append(f"warning: the learned temperatures dE/ds_i are negative at {negative:.0%} "
                   f"of the states (least {metrics['temperature_min']:.3g}): entropy "
                   "production then feeds the motion, and rollouts beyond the data can run "
                   "away. Data that gain energy from outside the recorded variables (a "
                   "drive, a negative friction) need them: such data are not GENERIC with "
                   "this S. Otherwise give more trajectories, or check which variables are "
                   "entropies (--entropy sum:...).")
    return out


#: Below this share of the motion driven by L grad E (``reversible_share``), train and
#: evaluate warn. Every true system of the zoo and of the reference experiments with L != 0
#: has 0.68 or more.
REVERSIBLE_SHARE = _LIMITS.reversible_share


#: Above this fraction of rollout states where the model's own flow decreases its learned
#: entropy (``entropy_production_negative_fraction``), train and evaluate warn. A GENERIC
#: model has none: its entropy production is grad S . M grad S >= 0.
NEGATIVE_PRODUCTION = _LIMITS.entropy_production


#: At or below this relative |L grad S|, L grad S = 0 holds (by construction, to rounding), and
#: a decreasing entropy is the friction's.
EXACT_RESIDUAL = 1e-6


#: Above this share of the motion driven by L grad E, the learned friction is called idle (the
#: model is reversible) in the warning on a decreasing entropy.
IDLE_FRICTION_SHARE = 0.999


def _idle_friction(share: float | None) -> str:
    """What the decreasing-entropy warning adds where the learned friction moves almost
    nothing: S then plays almost no part in the model (as for a conservative system, whose
    learned S no data can determine)."""
    if share is None or share <= IDLE_FRICTION_SHARE:
        return ""
    drives = "none" if share >= 1.0 else f"only {1 - share:.1e}"
    return (f" The friction drives {drives} of the motion, so this S plays almost no part in "
            "the model: if the system's motion is reversible (nothing damps it, no heat "
            "flows), this warning does not concern its dynamics; if it is damped or heat flows "
            "(an isolated system keeps its energy either way), L grad E carries that part too, "
            "as it can where nothing is given, and the friction was not learned: give the "
            "structure you know (--entropy sum:..., --poisson ...) to tell them apart.")


#: With this many variables or more and a held-out error above POOR, train names the blocks for
#: a state made of cells: on a new-user check's chain of 6 masses and baths (n = 18) the default
#: blocks gave 0.38 on test trajectories, the cells' 6.7e-2 in the same 3 minutes; on the zoo's
#: 30-variable chain 0.545 against 1.55e-3.
MANY_VARIABLES = 12
POOR = 0.05


def cells_hint(metrics: dict, config: Any, n: int) -> list[str]:
    """Where many variables train poorly with the default energy and friction, the blocks for a
    state made of cells (a chain or a lattice), which a user with such a system may not
    know of."""
    error = metrics.get("rollout_error_mean_completed")
    if (n < MANY_VARIABLES or error is None or error <= POOR
            or str(config.energy).startswith("local") or str(config.friction) != "neural"):
        return []
    return [f"hint: {n} variables and a held-out error of {error:.2g}: if the state is made of "
            "alike cells and nothing else (a chain or a lattice, each cell's fields stored "
            "field by field; not one bath shared by every cell), "
            "--energy local:CELLS --friction local:CELLS learns it as sums over neighbouring "
            "cells (docs/structure.md, States made of cells; on a chain of 6 masses with "
            "their baths, 0.38 with the default blocks, 0.067 with these, in 3 minutes). A "
            "step of theirs costs more, up to 10x: give them time (a 40-cell heat rod did "
            "worse with them in 3 minutes, 1.15 against 0.41)."]


def structure_warnings(metrics: dict) -> list[str]:
    """Every warning on what the learned structure means: :func:`temperature_warnings`,
    :func:`entropy_rise_warning`, :func:`energy_change_warning`, the horizon of prediction
    (:func:`~metriplex.app._horizon_note.predictability_note`; ``every_note`` for evaluate
    --every), a learned energy that drives
    almost none of the motion (friction carries it), and a learned entropy that the model's
    own flow decreases (L grad S = 0 only as a penalty)."""
    out = (temperature_warnings(metrics) + entropy_rise_warning(metrics)
           + energy_change_warning(metrics) + identified_note(metrics)
           + predictability_note(metrics) + every_note(metrics))
    negative = metrics.get("entropy_production_negative_fraction")
    if negative is not None and negative > NEGATIVE_PRODUCTION:
        residual = metrics.get("degeneracy_L_gradS_relative")
        held = "" if residual is None else f" (relative residual {residual:.2g})"
        cause = (f"L grad S is not zero{held}" if residual is None or residual > EXACT_RESIDUAL
                 else f"L grad S is zero{held}, so the friction M is not positive "
                 "semi-definite there (friction_min_eigenvalue in the metrics)")
        out.append(f"warning: the learned entropy decreases at {negative:.0%} of the rollout "
                   f"states: {cause}, so this S is not an entropy of the model's flow. "
                   "Where L and S are learned, L grad S = 0 is a penalty by default and "
                   "--degeneracy exact makes it exact with --poisson neural or casimir3 (it "
                   "can cost accuracy, see docs/zoo.md); where L is given, S must be one of its "
                   "Casimirs (by default S is then learned of the variables L leaves free, "
                   "where L has such coordinates; not with --degeneracy soft)."
                   + _idle_friction(metrics.get("reversible_share")))
    share = metrics.get("reversible_share")
    if share is not None and share < REVERSIBLE_SHARE:
        out.append(f"warning: the learned energy drives {share:.1e} of the motion (L grad E); "
                   "friction (M grad S) carries the rest. Any flow whose entropy grows can be "
                   "written that way, so this fit does not identify E: do not read the learned "
                   "E as the system's energy, and expect rollouts beyond the data to run away "
                   "(see 'Friction that carries the motion' in the README).")
    return out


#: Beyond this factor between the data's time scale and the training data's, rollout and
#: evaluate warn: the same system in the same unit of time moves at the same pace.
TIME_SCALE_FACTOR = 10.0


def time_unit_warning(units: dict, data: Trajectories) -> list[str]:
    """A warning where ``data`` move on a time scale (:func:`metriplex.data.time_scale`) more
    than :data:`TIME_SCALE_FACTOR` times apart from that of the training data (``units``:
    config.json's ``units``): times in another unit (ms against s) give a model steps it was
    never trained on, and every figure then says so only as a large error; and
    :func:`~metriplex.app._horizon_note.step_warning`, on steps far larger than training's."""
    return _time_scale_warning(units, data) + step_warning(units, data)


def _time_scale_warning(units: dict, data: Trajectories) -> list[str]:
    from ..data import time_scale

    trained = units.get("time")
    pairs = data.pairs()
    if not trained or len(pairs.dt) == 0:
        return []
    tau = time_scale(pairs)
    ratio = tau / float(trained)
    if 1.0 / TIME_SCALE_FACTOR <= ratio <= TIME_SCALE_FACTOR:
        return []
    return [f"warning: these data move on a time scale {ratio:.3g} times the training data's "
            f"({tau:.3g} against {float(trained):.3g} time units): is "
            "their time in the same unit (s, ms, h) as the training data's? The model's "
            "steps are taken in the training data's unit."]


def trained_units(units: dict) -> Units | None:
    """config.json's ``units`` as :class:`metriplex.Units`; ``None`` for an older run."""
    from .._units import Units

    return Units(**units) if units.get("shift") is not None else None


def training_range_warning(units: dict, data: Trajectories) -> list[str]:
    """A warning naming the trajectories of ``data`` that reach beyond the training data's
    extent, more than the verdict's ``training_range`` training standard deviations from
    their mean (:meth:`~metriplex.Units.farthest`; ``units``: config.json's): there the model
    extrapolates, and their errors say how, not how well it learned the system."""
    trained = trained_units(units)
    if trained is None:
        return []
    far = [(tid, *trained.farthest(x)) for tid, (_, x) in zip(data.ids, data)]
    far = [(tid, d, var) for tid, d, _, var in far if d > _LIMITS.training_range]
    if not far:
        return _coverage_note(trained, data)
    tid, d, var = max(far, key=lambda f: f[1])
    ids = listing([str(f[0]) for f in far], 10, sep=", ")
    return [f"warning: {len(far)} of {len(data)} trajectories ({ids}) reach states the model "
            f"was never trained on ({data.names[var]} at {d:.3g} training standard deviations "
            f"from its training mean, in trajectory {tid}): their rollout errors say how the "
            "model extrapolates, not how well it learned the system."]


def _coverage_note(trained: Units, data: Trajectories) -> list[str]:
    """A note where more than the verdict's ``training_coverage`` share of ``data``'s states
    lie beyond ``BEYOND`` training standard deviations in some variable, though none as far as
    :func:`training_range_warning` names: a test of mild extrapolation erred 4x its validation
    error with nothing said (new-user check 13, 12 % of its states beyond)."""
    from .._verdict_training import BEYOND, beyond_share

    share, most = beyond_share(data, trained)
    if share <= _LIMITS.training_coverage:
        return []
    return [f"note: {share:.0%} of the evaluated states lie beyond {BEYOND:g} training standard "
            f"deviations of the training mean, and beyond the training data's range, in some "
            f"variable (most often {most}): there the model extrapolates, and the errors grow "
            "with how far it must."]


#: A validation part whose every variable spreads less than this share of its spread in the
#: training part hardly moves: the scores that keep the model and stop training say little.
STILL_VALIDATION = 0.01


def still_validation_warning(train: Trajectories, valid: Trajectories | None) -> list[str]:
    """A warning where the validation part barely moves (:data:`STILL_VALIDATION`), such as
    the last fifth of a single trajectory that has come to rest."""
    import numpy as np

    if valid is None or len(valid.t) < 2:
        return []
    d_train, d_valid = np.std(train.x, axis=0), np.std(valid.x, axis=0)
    moving = d_train > 0
    share = float(np.max(d_valid[moving] / d_train[moving])) if moving.any() else 1.0
    if share >= STILL_VALIDATION:
        return []
    single = len(train.ids) == 1 and list(valid.ids) == list(train.ids)
    where = (f"the only trajectory's samples from t = {valid.t[0]:.6g} on" if single else
             f"{len(valid.ids)} validation trajectories")
    return [f"warning: the validation part ({where}) barely moves: each variable spreads at "
            f"most {share:.2g} of its spread in the training part, so the held-out scores that "
            "keep the model and stop training say little about the dynamics; give more "
            "trajectories" + ("." if single else " (or choose moving ones with "
                              "--validation-ids).")]


def casimir_note(free: tuple[int, ...] | None, train: Trajectories) -> list[str]:
    """The note where S is learned of the variables a given L leaves free (``free``)."""
    if free is None:
        return []
    return [f"note: S is learned as a function of {', '.join(train.names[i] for i in free)} "
            "only, the variables the given L leaves free, so L grad S = 0 holds exactly "
            "(--degeneracy soft learns it of every variable)"]


#: A sample is an outlier when its variable jumps to it and back by more than this many times
#: both the variable's median step and the steps around the jump.
SPIKE = 30.0


def outlier_warning(data: Trajectories, what: str = "training data") -> list[str]:
    """A warning naming the samples of ``data`` at which a variable jumps away and straight
    back (by :data:`SPIKE` times its median step and the neighbouring steps): one such sample
    in 4 500 made a model 80x worse, and nothing pointed at it."""
    import numpy as np

    found, typical = [], np.maximum(np.median(np.abs(np.diff(data.x, axis=0)), axis=0), 1e-300)
    for tid, (t, x) in zip(data.ids, data):
        if len(t) < 3:
            continue
        d = np.diff(x, axis=0)
        big = np.abs(d) > SPIKE * typical
        back = big[:-1] & big[1:] & (np.sign(d[:-1]) == -np.sign(d[1:]))
        pad = np.pad(np.abs(d), ((1, 1), (0, 0)))
        calm = np.minimum(np.abs(d[:-1]), np.abs(d[1:])) > SPIKE * np.maximum(pad[:-3], pad[3:])
        for k, i in zip(*np.nonzero(back & calm)):
            found.append(f"trajectory {tid} at t = {t[k + 1]:.6g} ({data.names[i]})")
    return [f"warning: {len(found)} sample(s) of the {what} jump away and straight back, by "
            f"more than {SPIKE:g}x the typical step: {listing(found, 5)}. If they are recording "
            "errors, remove them: one such pair can dominate the residual it is fitted by."
            ] if found else []


def listing(found: list[str], most: int, sep: str = "; ") -> str:
    """The first ``most`` of ``found``, joined by ``sep``, with "..." for the rest."""
    return sep.join(found[:most]) + (sep + "..." if len(found) > most else "")


def trained_on(run: dict, data: Trajectories) -> list[int]:
    """The ids of ``data`` that the run of ``run`` (its config.json) trained on: those that
    start where one of its training trajectories starts, to a rounding of 1e-6 (so that the
    training data written again with fewer digits, or into another file, are caught; runs
    from before 2026-12-06 did not record the starts)."""
    import numpy as np

    starts = np.asarray((run.get("data") or {}).get("train_starts") or [], dtype=np.float64)
    if starts.ndim != 2 or starts.shape[1] != data.n:
        return []
    tol = 1e-6 * (np.abs(starts) + np.abs(starts).max(axis=0))
    return [int(i) for i, (_, x) in zip(data.ids, data)
            if np.any(np.all(np.abs(starts - x[0]) <= tol, axis=1))]


def in_sample_warning(trained: list[int], k: int) -> str:
    """The warning of ``evaluate`` where the ids ``trained`` of its ``k`` trajectories were
    trained on (:func:`trained_on`)."""
    from ._selection import format_ids

    return (f"warning: {len(trained)} of the {k} trajectories evaluated were trained on (they "
            f"start where this run's training trajectories start: {format_ids(trained)}): the "
            "errors and the verdict's comparison are in-sample, not a test; evaluate on "
            "trajectories the run never saw (its validation ids are in config.json).")
