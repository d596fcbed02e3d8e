r"""The verdict: are these data consistent with the fitted GENERIC model?

Three outcomes, and every one says why, figure by figure:

- **consistent**: the structured model explains the held-out data about as well as an
  unconstrained model of the same capacity, *and* it is itself GENERIC (degenerate, Jacobi,
  entropy never decreasing along its rollouts), *and* the evidence is sound (every rollout
  completed, the reference fits; how training ended does not decide it);
- **not consistent**: on sound evidence, the structured model leaves much more of the observed
  rates unexplained than the unconstrained reference: the structure, as fitted, cannot
  represent the dynamics;
- **cannot tell**: the evidence is not sound (a rollout failed, a misfit's training did not
  converge, the reference fits badly, so that neither the structure nor the data is blamed), or
  the model fits but is not GENERIC (its fit then proves nothing about GENERIC).

**The residual comparison.** The floor that no model beats (noise, the time step) is measured
with a **black box of the same capacity**: an unconstrained MLP vector field
:math:`\dot x = f_\theta(x)` trained with the same Crank–Nicolson pair loss on
``1 - validation`` of the trajectories. Both models are scored on the held-out trajectories by
their **relative residual**

.. math:: r = \sqrt{\frac{\operatorname{mean}_\text{pairs}|D_\tau^{-1}(\Delta x/\Delta t -
   \bar f)|^2}{\operatorname{mean}_\text{pairs}|D_\tau^{-1}\Delta x/\Delta t|^2}},

the fraction of the observed rates that the model leaves unexplained, in the data's own rate
units :math:`D_\tau = \operatorname{diag}(d_i/\tau)` (:class:`metriplex.Units`): it does not
depend on the units of time or of any state variable, and neither does the black box, whose
networks work in those units too. The **residual ratio** is
:math:`r_\text{GENERIC}/\max(r_\text{black box},\ \text{tolerance})`.

**The checks** (each a ``reasons`` entry ``{name, value, threshold, passed, effect, note}``;
``passed`` is ``None`` when a check does not apply; ``effect`` is the outcome a failed check
leads to). The limits are in :class:`Thresholds`; what each means:

========================== ============== ================================================
name                       limit          meaning
========================== ============== ================================================
``held_out_pairs``         10             pairs the black-box reference did not train on
                                          (a fifth of the trajectories, or the last fifth
                                          of a single one), where both models are
                                          compared: fewer are too little data for a
                                          residual comparison (cannot tell)
``rollout_failures``       0              a rollout of the structured model from a data
                                          trajectory's first state blew up or an implicit
                                          step did not converge: its rollout figures are
                                          incomplete (cannot tell)
``rollout_skill``          1              the structured model's completed rollouts err
                                          more than predicting x(t) = x(0): it predicts
                                          nothing, and its residuals prove nothing (cannot
                                          tell)
``training_converged``     true           failed residual ratio: training stopped on a
                                          plateau, not on a step or time cap (nor did the
                                          cap end the repeats before any was judged good):
                                          the misfit of a model still improving is no
                                          evidence (cannot tell; unknown without a history)
``step_sensitivity``       0.1            refining the time step 4x changes more than 10%
                                          of the structured model's predicted motion
                                          (:func:`metriplex.diagnostics.step_sensitivity`):
                                          its predictions belong to its scheme at the data's
                                          step, not to a vector field (cannot tell; only
                                          where the report measured it)
``training_range``         6              the data reach beyond the model's training data,
                                          more than 6 standard deviations from their mean
                                          (only with ``trained_on``): there the model
                                          extrapolates (cannot tell)
``training_coverage``      0.05           failed residual ratio, ``trained_on``: over 5% of
                                          the states beyond 3 of those (cannot tell)
``training_pairs``         0.5 (least)    failed residual ratio, ``trained_on``: the model
                                          trained on under half the pairs that the
                                          reference trains on here (cannot tell)
``training_trajectories``  3 (least)      failed residual ratio, ``trained_on``: the model
                                          trained on one or two trajectories (cannot tell)
``reference_residual``     0.3            the black box leaves more than 30% of the held-out
                                          rates (9% of their power) unexplained: too few
                                          trajectories to generalise from, noise, a coarse
                                          time step or a short reference training dominate,
                                          so a residual comparison blames nobody
                                          (cannot tell; not needed when the structured
                                          model's own residual is within the tolerance)
``reference_residual_      0.5            where the reference leaves more than the tolerance
correlation``                             (3% of the rates) unexplained: the lag-one
                                          correlation of its residuals along the held-out
                                          trajectories. Noise on the recorded states gives
                                          about -0.5; above 0.5 what it leaves is dynamics
                                          that neither model has (an input or a parameter
                                          that changes in time, a variable missing from the
                                          data, too few trajectories for the reference to
                                          generalise), which a structured model that leaves
                                          as much would hide (cannot tell, where the
                                          residual ratio passes: it weakens only a
                                          "consistent")
``given_entropy``          0.1            where S is given, the fraction of the held-out
                                          pairs along which the data decrease it by more
                                          than noise on the states would (the pairs
                                          themselves, no fitted field): GENERIC data never
                                          do, whatever the fit (not consistent, before any
                                          other check; ``passed`` is ``None`` if S is learned)
``residual_ratio``         2              the structured model leaves more than twice the
                                          residual of the reference (four times its power),
                                          where residuals under the tolerance (3% of the
                                          rates) count as the tolerance: below it,
                                          differences are what training budgets decide;
                                          or more than 3% and 5x the reference's own
                                          (``far_residual``, ``far_ratio``) (not consistent)
``training_roughness``     2              with a failed residual ratio and ``trained_on``:
                                          the training data were over twice as rough as
                                          these (:func:`metriplex.data.roughness`) and the
                                          residual here within that (cannot tell)
``degeneracy_L_gradS``     0.1            :math:`|L\nabla S|/(|L|_F|\nabla S|)` in
                                          standardised coordinates, 0 when exact; an
                                          antisymmetric L reaches at most
                                          :math:`1/\sqrt2 \approx 0.71` (no degeneracy at all)
                                          (cannot tell)
``degeneracy_M_gradE``     0.1            :math:`|M\nabla E|/(|M|_F|\nabla E|)`, 0 exact, at
                                          most 1 (cannot tell)
``jacobi``                 0.1            :math:`|J|/(3\max(|T|,|L|^2))`, :math:`T = (\partial
                                          L)L`: 0 for a Poisson bivector, 1 when the three
                                          cyclic terms do not cancel at all; against
                                          :math:`|L|^2` where L varies less than its size
                                          (close to a constant L, as an untrained
                                          ``SkewMLPPoisson`` is: 0.004–0.03, where
                                          :math:`|J|/(3|T|)` gave 0.05–0.56) (cannot tell)
``entropy_production``     0.01           the fraction of the states along the structured
                                          model's rollouts where its own flow decreases its
                                          entropy by more than 1% of the fastest rate the
                                          state's speed allows
                                          (:func:`metriplex.diagnostics.
                                          entropy_production_negative_fraction`); exactly 0
                                          for a GENERIC model (cannot tell)
``friction_psd``           1e-5           the most negative eigenvalue of the standardised
                                          :math:`M` relative to its largest: M must be
                                          positive semi-definite, up to float32 rounding
                                          (cannot tell)
``poisson_antisymmetry``   1e-5           :math:`|L + L^\top|/|L|`, up to rounding
                                          (cannot tell)
``temperatures``           0.01           where S is a sum of entropy variables, the
                                          fraction of the data's states and entropies where
                                          the learned temperature
                                          :math:`\partial E/\partial s_i` is negative:
                                          entropy production then feeds the motion, which
                                          no physical system does (cannot tell; ``passed``
                                          is ``None`` for any other entropy). Where L = 0,
                                          E is fixed only up to a function of itself and
                                          -E gives the same flow: then the fraction of the
                                          states whose temperatures have both signs
``reversible_share``       0.01 (least)   the share of the standardised motion at the
                                          data's states that :math:`L\nabla E` drives;
                                          below it friction carries the motion, which any
                                          flow whose entropy grows admits, so the fit does
                                          not identify E (0.68–1 for every true system of
                                          the zoo and the reference experiments with
                                          :math:`L \ne 0`; cannot tell; ``passed`` is
                                          ``None`` where L = 0)
========================== ============== ================================================

The degeneracy, Jacobi and PSD figures are taken at the data's states in standardised
coordinates :math:`\tilde x = x/d` (:func:`metriplex.diagnostics.structure_residuals` with the
data scale), so none of them depends on the units of time, state, :math:`E` or :math:`S`.
A figure that cannot be computed (a degeneracy whose factors are all zero, e.g.
:math:`S = 0`) is ``None`` with the check passed and the reason in its ``note``; never 0.0.

Outcome: a failed ``given_entropy`` → **not consistent**; else a failed ``held_out_pairs``,
``training_converged``, ``training_range``, ``training_coverage``, ``training_roughness``,
``training_pairs``, ``training_trajectories`` or ``reference_residual``
→ **cannot tell**;
else a failed ``residual_ratio`` → **not consistent**, unless the observed data break neither
law (:func:`~metriplex._verdict_outcome.weigh_misfit`), rollouts failed or the step decides the
prediction (then **cannot tell**; the last two not after a converged training far beyond the
reference: :func:`~metriplex._verdict_checks._far_beyond`); else any failed → **cannot tell**;
else **consistent**. The command line's ``metriplex evaluate --strict`` exits with
:data:`EXIT_STATUS` of the outcome (0 consistent, 1 not consistent, 3 cannot tell).

With **not consistent**, the report also names what the observed data do under the learned
:math:`E` and :math:`S` (measured on the data's own pairs beyond what noise on the states
gives, not on any fitted field): the learned energy changing along the observed flow (first
law), the learned entropy decreasing (second law), and the variables the structure cannot fit. The verdict holds for the structure
that was fitted: with ``S = s`` given, data whose ``s`` decreases are not GENERIC, even though
another entropy might exist.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any

import numpy as np

from ._errors import MetriplexError
from ._model import GenericModel, float_dtype, weights
from ._precision import in_full_precision
# The black-box reference and the held-out measurements (BlackBoxModel, ... public from here).
from ._reference import (BlackBoxModel, Reference, _finite, _observed_laws, _residuals,
                         _serial_correlation, train_reference)
# The checks (each a ``reasons`` entry) and the outcome names, public from here.
from ._verdict_checks import (CANNOT_TELL, CONSISTENT, GIVEN_ENTROPY_FALLS, MISSING_VARIABLE,
                              NOT_CONSISTENT, NOT_POISSON, REVERSIBLE_ONLY, UNIDENTIFIED_SPLIT,
                              _SPLIT_CHECKS, _far_beyond, _residual_checks, _reversible_only,
                              _said, _soundness_checks, _structure_checks)
from ._verdict_outcome import _accuracy, _given_entropy_check, _outcome, _violations, weigh_misfit
from ._verdict_skill import _skill_check
from ._verdict_training import _converged_where_misfit, _training_checks
from .data import Trajectories, state_scale, time_scale
from .structure import ZeroFriction, ZeroPotential

if TYPE_CHECKING:
    from ._train import History
    from ._units import Units
    from .integrate import AbstractScheme

#: What a "consistent" adds in place of ``REVERSIBLE_ONLY`` where M was given as zero: it
#: spoke of "the learned friction" beside a friction given as none (new-user check 13).
CONSERVATIVE = "The model is conservative, as given (M = 0): L grad E drives all of the motion."

__all__ = ["CANNOT_TELL", "CONSISTENT", "EXIT_STATUS", "NOT_CONSISTENT", "BlackBoxModel",
           "Reference", "Thresholds", "train_reference", "verdict"]

#: Exit status of ``metriplex evaluate --strict`` for each outcome (2 stays "bad input").
EXIT_STATUS = {CONSISTENT: 0, NOT_CONSISTENT: 1, CANNOT_TELL: 3}


@dataclasses.dataclass(frozen=True)
class Thresholds:
    """The limits of the verdict's checks; their meaning is in the module docstring.

    Defaults are fixed by what each figure means (a fraction of the rates, a relative
    residual on its natural 0–1 scale, rounding), not tuned on any data set.
    """

    held_out_pairs: int = 10
    residual_ratio: float = 2.0
    tolerance: float = 0.03
    reference_residual: float = 0.3
    residual_correlation: float = 0.5
    degeneracy: float = 0.1
    jacobi: float = 0.1
    entropy_production: float = 0.01
    rounding: float = 1e-5
    negative_temperatures: float = 0.01
    reversible_share: float = 0.01
    far_ratio: float = 5.0
    far_residual: float = 0.03
    step_sensitivity: float = 0.1
    training_range: float = 6.0
    training_coverage: float = 0.05
    training_pairs: float = 0.5
    training_trajectories: int = 3
    training_roughness: float = 2.0
    rollout_skill: float = 1.0
    given_entropy: float = 0.1


@in_full_precision
def verdict(
    model: GenericModel,
    data: Trajectories,
    *,
    report: dict[str, Any] | None = None,
    converged: bool | None = None,
    stopped: str | None = None,
    history: History | None = None,
    scheme: AbstractScheme | None = None,
    reference: Reference | None = None,
    width: int = 64,
    depth: int = 2,
    steps: int = 3000,
    learning_rate: float = 1e-2,
    batch_size: int = 256,
    thresholds: Thresholds = Thresholds(),
    validation: float = 0.2,
    seed: int = 0,
    progress: bool = False,
    trained_on: Units | None = None,
) -> dict[str, Any]:
    """Whether ``data`` are consistent with the GENERIC ``model``: the verdict of the checks in
    the module docstring.

    ``report``: :func:`metriplex.evaluate` of ``model`` on ``data`` (computed with ``scheme``
    when not given): its rollout failures and the entropy production along its rollouts are
    weighed. ``converged``/``stopped``: how the model's training ended, or ``history`` (the
    :class:`~metriplex.train.History` that :func:`~metriplex.fit` returned) to read them from;
    unknown when none is given (a ground-truth model); weighed only where the ratio fails.
    ``reference``: a :func:`train_reference` of ``data`` to reuse; otherwise the black box
    trains here (``width``, ``depth``, ``steps``, ``learning_rate``, ``batch_size``; their
    defaults are those of ``metriplex train``, which ``metriplex evaluate`` passes from the
    run, so that both give the same figures) on ``1 - validation`` of the trajectories. Both
    models are scored on the rest.
    ``trained_on``: the units of the model's training data (``Units.from_data``; a run's
    ``config.json`` keeps them), to check that ``data`` stay where the model was trained.

    Returns a JSON-able dict: ``outcome`` ("consistent" | "not consistent" | "cannot tell"),
    ``consistent`` (outcome == "consistent"), ``statement`` (one sentence naming each deciding
    check with its figure), ``reasons`` (every check), ``ratio`` and the residuals.
    """
    from .diagnostics import evaluate, structure_residuals

    th = thresholds
    if history is not None and converged is None:
        converged, stopped = history.converged, stopped or history.stopped
    dtype = float_dtype(model)
    if report is None:
        report = evaluate(model, data, scheme=scheme)
    if reference is None:
        reference = train_reference(data, width=width, depth=depth, steps=steps,
                                    learning_rate=learning_rate, batch_size=batch_size,
                                    validation=validation, seed=seed, dtype=dtype,
                                    progress=progress)
    elif (reference.rows, reference.n) != (len(data.t), data.n):
        raise MetriplexError(
            f"the reference was trained on other data ({reference.rows} rows x {reference.n} "
            f"variables; these have {len(data.t)} x {data.n}). Train it on these data with "
            "train_reference(data), or leave reference out."
        )
    train, valid = data.split(reference.validation, seed=reference.seed)
    held = valid if valid is not None else train
    d = state_scale(train.x)
    rate = d / time_scale(train, d)
    box, box_note = reference.model, reference.note
    pairs = held.pairs()
    rates = (pairs.x1 - pairs.x0) / pairs.dt[:, None] / rate[None, :]
    signal = float(np.mean(np.sum(rates**2, axis=1)))
    r_gen = _residuals(model, pairs, rate, dtype)
    rel_gen = _finite(np.sqrt(np.mean(np.sum(r_gen**2, axis=1)) / max(signal, 1e-300)))
    if box is not None:
        r_box = _residuals(box, pairs, rate, float_dtype(box))
        rel_box = _finite(np.sqrt(np.mean(np.sum(r_box**2, axis=1)) / max(signal, 1e-300)))
        same = held.trajectory[1:] == held.trajectory[:-1]  # the pairs' rows, as pairs() takes
        correlation = _serial_correlation(r_box, held.trajectory[:-1][same])
    else:
        r_box, rel_box, correlation = None, None, None

    # The checks, in the order of the module docstring's table.
    reasons = _soundness_checks(report, len(data), converged, stopped, th,
                                held_out=len(pairs.dt) if valid is not None else 0,
                                fraction=reference.validation) + _skill_check(report, th)
    compared, ratio = _residual_checks(rel_gen, rel_box, box_note, th, correlation)
    ratio_passed = next(r["passed"] for r in compared if r["name"] == "residual_ratio")
    reasons = _converged_where_misfit(reasons, ratio_passed) + compared + _training_checks(
        data, trained_on, rel_gen, th=th,
        misfit=None if ratio_passed is None else not ratio_passed,
        reference_pairs=len(train.t) - len(train.ids))
    sr = structure_residuals(model, data.x, scale=state_scale(data.x))
    entropy_free = bool(weights(model.entropy)) or isinstance(model.entropy, ZeroPotential)
    reasons += _structure_checks(sr, report, th, entropy_free=entropy_free)
    observed = _observed_laws(model, held, d, dtype)  # the data's laws, no fitted field
    reasons = weigh_misfit(reasons, observed)
    reasons.append(_given_entropy_check(observed, th.given_entropy, given=not entropy_free))
    failed = [r for r in reasons if r["passed"] is False]
    outcome = _outcome(failed, ratio, converged, _far_beyond(rel_gen, rel_box, th))
    excess = None
    if r_box is not None:
        excess_v = (np.mean(r_gen**2, axis=0) - np.mean(r_box**2, axis=0)) / max(signal, 1e-300)
        excess = {name: _finite(v) for name, v in zip(data.names, excess_v)}
    laws = _violations(observed, excess, given=not entropy_free) \
        if outcome == NOT_CONSISTENT else []

    # A fit by L grad E alone says so wherever it is not refuted (a new-user check's piston).
    reversible = "" if not _reversible_only(sr, entropy_free) else " " + (
        CONSERVATIVE if isinstance(model.friction, ZeroFriction) else REVERSIBLE_ONLY)
    if outcome == CONSISTENT:
        key = [r for r in reasons if r["name"] == "residual_ratio"][0]
        statement = (f"consistent with GENERIC: {_said(key)}; the fitted model is GENERIC and "
                     f"its rollouts complete (all {sum(r['passed'] is True for r in reasons)} "
                     "applicable checks pass; see verdict.reasons)." + _accuracy(report) + (
                         " " + sr["identified"]["statement"][0].upper()
                         + sr["identified"]["statement"][1:]) + reversible)
    elif outcome == NOT_CONSISTENT:
        statement = ("NOT consistent with GENERIC (as fitted): "
                     + "; ".join(_said(r) for r in failed) + ("; " + "; ".join(laws) if laws
                                                            else "") + ". " + (
                         GIVEN_ENTROPY_FALLS + " " if any(w.startswith("second law") for w in laws)
                         and not entropy_free else "") + MISSING_VARIABLE)
    else:
        statement = ("cannot tell whether the data are consistent with GENERIC: "
                     + "; ".join(_said(r) for r in failed) + ".")
        names = {r["name"] for r in failed}
        if "jacobi" in names and bool(weights(model.poisson)):
            statement += " " + NOT_POISSON
        if bool(weights(model.entropy)) and names & _SPLIT_CHECKS:
            statement += " " + UNIDENTIFIED_SPLIT
        statement += reversible
    return {
        "outcome": outcome,
        "consistent": outcome == CONSISTENT,
        "statement": statement,
        "reasons": reasons,
        "ratio": ratio,
        "threshold": th.residual_ratio,
        "tolerance": th.tolerance,
        "residual_generic_relative": rel_gen,
        "residual_black_box_relative": rel_box,
        "excess_residual_per_variable": excess,
        "observed_energy_rate_relative_median": observed["energy_rate_relative_median"],
        "observed_entropy_decreasing_fraction": observed["entropy_decreasing_fraction"],
        "violations": laws,
        "identified": sr["identified"],
        "held_out_trajectories": int(len(held)),
        "thresholds": dataclasses.asdict(th),
    }

