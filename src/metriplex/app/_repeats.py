"""``--repeats``: train again, from another initialisation, while the held-out rollouts of the
best model so far are poor, and keep the model that rolls them out best.

Which minimum a training ends in depends on its initialisation more than on anything else a
user sets: the same data and settings give a good model from one key and a poor one from
another (docs/zoo.md, *Trained again where the first training is poor*). The held-out
rollouts that choose the kept step within a training tell the poor ones apart, so training is
repeated only where they say the model is poor, and a good first training costs nothing more.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Sequence

import jax
import jax.random as jr

from .._fit_loop import INTERRUPTED, TIME_BUDGET, ending
from .._errors import TrainingDiverged
from .._model import with_dtype
from .._progress import progress_label
from .._units import Units
from ..data import Trajectories, noise_level, state_scale
from ..losses import Loss
from ..train import Checkpoint, LBFGSFinish, fit
from ._build import Given, build_loss, build_model, fit_settings, input_noise_of
from ._option import option
from ._resume import checkpoint_path, checkpoint_seconds, left_checkpoint, resuming_line
from ._stages import before_main, left_of
from .config import RunConfig, reversible_first_on

if TYPE_CHECKING:
    from jax.typing import DTypeLike

    from .._model import GenericModel
    from .._train import History

#: The trainings at most (``--repeats`` left out) where there are held-out trajectories.
REPEATS = 3
#: A model whose held-out rollouts err by at most this much (the root mean square over the
#: rollout check's windows, in units of each variable's standard deviation over the data),
#: none of them failing, is good: training is not repeated after it. 2 % of the spread, the
#: accuracy the zoo's bar asks; 0.1 left charged-particle at one training and 4.5e-2 where
#: this trains it twice to 1.9e-2, and no zoo case lost (docs/zoo.md).
GOOD_SCORE = 0.02
#: Where the held-out states carry noise, no model's score falls below it (the score is the
#: rollouts' error against those states, in the same units as :func:`~metriplex.data.noise_level`
#: measures the noise): a score within this factor of the noise on them is good too, its own
#: error at most about the noise's size (sqrt(1.5**2 - 1) = 1.1 times it). A new-user check's
#: 5 % noise (6.8 % of the held-out trajectories' spread): scores 0.064, 0.063, 0.065, four
#: trainings where one served; clean data, every case of the zoo and outside it: noise 0.
NOISE_FLOOR = 1.5


def good_score(valid: Trajectories | None) -> float:
    """The held-out score at or under which a training is good: :data:`GOOD_SCORE`, or
    :data:`NOISE_FLOOR` times the noise on the held-out states where that is larger."""
    return max(GOOD_SCORE, 0.0 if valid is None else NOISE_FLOOR * noise_level(valid))


#: The friction that the last of three or more trainings learns where L = 0 (``--poisson
#: zero``) and the friction is the default ``neural``: the pairwise exchange
#: (``structure.ExchangeFriction``), the form of heat conduction among cells, of diffusion and
#: of reactions. Two trainings of the Cholesky friction that both roll the held-out
#: trajectories out poorly say that it does not fit these data; the held-out rollouts then
#: choose between the two forms, as between any two trainings. Eight cells conducting in a
#: ring: 0.143 -> 0.0658 (one seed of three; the other two keep a default training); a 3 x 3
#: grid of cells from a new-user check: 0.419 -> 0.0606 (docs/zoo.md, *The last training with
#: the pairwise exchange*).
ALTERNATIVE_FRICTION = "exchange"


#: One more training after :data:`REPEATS` where E is the default network and the friction
#: alternative does not apply: E (and a learned S) with a learned quadratic form beside the
#: network (``--quadratic``). Off by default: on the zoo it was worse on six cases of nine, by
#: 1.2-1.5x, and gained no bar (docs/zoo.md, *Quadratic term*). But where three trainings all
#: roll the held-out trajectories out poorly, a network alone did not find these data's E:
#: six coupled oscillators with two baths (n = 14), whose E is a quadratic form plus a quartic
#: term, 0.209 -> 0.0169 (docs/zoo.md, *The fourth training with a quadratic form*). It comes
#: after the trainings of the form asked for, which stay as they were, and the held-out
#: rollouts choose among all of them: a case the network fits keeps its network.
ALTERNATIVE_ENERGY = "--quadratic"


def _friction_alternative(config: RunConfig) -> bool:
    return (config.friction == "neural" and config.poisson == "zero"
            and option(config.entropy).kind != "zero")


def _energy_alternative(config: RunConfig) -> bool:
    return (not _friction_alternative(config) and config.energy == "neural"
            and not config.quadratic)


def config_for(config: RunConfig, r: int, repeats: int) -> RunConfig:
    """Training ``r``'s settings (0 based, of at most ``repeats``): the run's, except that the
    last of three or more learns another form: :data:`ALTERNATIVE_FRICTION` where L = 0 and
    the run's friction is ``neural`` beside an entropy; and the last of four or more, where E
    is the default network without a quadratic form, one with it (:data:`ALTERNATIVE_ENERGY`)."""
    if r != repeats - 1:
        return config
    if r >= 2 and _friction_alternative(config):
        return dataclasses.replace(config, friction=ALTERNATIVE_FRICTION)
    if r >= REPEATS and _energy_alternative(config):
        return dataclasses.replace(config, quadratic=True)
    return config


def repeats_for(config: RunConfig, valid: Trajectories | None) -> int:
    """The trainings at most: ``--repeats``, left out :data:`REPEATS` (and one more, with
    :data:`ALTERNATIVE_ENERGY`, where E is the default network and the friction alternative
    does not apply); 1 without held-out trajectories (nothing to judge a training by)."""
    if valid is None:
        return 1
    if config.repeats is not None:
        return config.repeats
    return REPEATS + 1 if _energy_alternative(config) else REPEATS


@dataclasses.dataclass(frozen=True)
class Training:
    """One training of a run, called as ``training(r, resumed)``: training ``r`` (0 based; the
    first from the run's own ``keys``, ``(model key, fit key)``, the others from keys folded
    with ``r``) of the model ``config`` describes, from its checkpoint where ``resumed``, else
    from the first stage or the best of ``--starts`` initialisations; ``(best model,
    history)`` as :func:`~metriplex.fit` returns them. ``budget`` (seconds, counted from the
    ``time.perf_counter()`` reading ``began``) caps every stage and training together.
    ``first``: training 0's untrained model, built by the caller before it writes anything to
    the run folder, so that a structure the data cannot take is refused with nothing written."""

    config: RunConfig
    train: Trajectories
    valid: Trajectories | None
    units: Units
    constant: tuple[int, ...]
    given: Given
    dtype: DTypeLike
    loss: Loss
    keys: tuple[jax.Array, jax.Array]
    out: Path
    progress: bool
    budget: float | None
    began: float
    first: GenericModel
    repeats: int = 1

    def config_of(self, r: int) -> RunConfig:
        """Training ``r``'s settings (:func:`config_for`)."""
        return config_for(self.config, r, self.repeats)

    def degenerate(self, model: GenericModel, r: int) -> bool | None:
        """Whether training ``r``'s ``model`` keeps M grad E = 0 within the verdict's limit at
        the held-out states, where L = 0 beside the default friction; elsewhere ``None`` (not
        measured). With L = 0, E enters the flow only through that condition: an E that breaks
        it is not the motion's energy, however well the rollouts fit (new-user checks: M grad E
        0.15 and 0.63 relative, E's gradient 1e-9; the last training's exchange keeps it by
        construction)."""
        if self.repeats == 1 or not _friction_alternative(self.config_of(r)):
            return None
        from ..diagnostics import structure_residuals
        from ..verdict import Thresholds
        x = (self.train if self.valid is None else self.valid).x
        v = structure_residuals(model, x, scale=state_scale(x))["degeneracy_M_gradE_relative"]
        return v is not None and math.isfinite(v) and v <= Thresholds().degeneracy

    def change_of(self, r: int) -> str:
        """How training ``r``'s settings differ from the run's, as its flags (``""`` if not)."""
        config = self.config_of(r)
        if config is self.config:
            return ""
        if config.friction != self.config.friction:
            return f"--friction {config.friction}"
        return ALTERNATIVE_ENERGY

    def __call__(self, r: int, resumed: bool) -> tuple[GenericModel, History]:
        config, train, valid = self.config_of(r), self.train, self.valid
        loss = self.loss if config is self.config else build_loss(config, self.units, train)
        m_key, f_key = self.keys if r == 0 else tuple(jr.fold_in(k, r) for k in self.keys)
        model = self.first if r == 0 else build_model(
            config, train, key=m_key, units=self.units, constant=self.constant, given=self.given)
        main = resumed and checkpoint_path(self.out, r).is_file()
        which = f"training {r + 1}" if self.repeats > 1 else "the training"
        if main:
            print(resuming_line(checkpoint_path(self.out, r), which), file=sys.stderr)
        if not main:  # the stages before the main one, each resumed from its own checkpoint

            def checkpoint(stage: str) -> Checkpoint:
                path = checkpoint_path(self.out, r, stage)
                if resumed and path.is_file():
                    print(resuming_line(path, f"{which}'s {stage.replace('-', ' ')}"),
                          file=sys.stderr)
                return Checkpoint(path, every=config.checkpoint_every,
                                  resume=resumed and path.is_file())

            model = before_main(model, config, train, valid, units=self.units,
                                constant=self.constant, given=self.given, dtype=self.dtype,
                                model_key=m_key, loss=loss, key=jr.fold_in(f_key, 1),
                                progress=self.progress, checkpoint=checkpoint,
                                max_seconds=left_of(self.budget, self.began))
        # fit counts a resumed training's own time so far against its cap: add it to what is
        # left of the run's budget, which counts it already.
        left = left_of(self.budget, self.began)
        if left is not None and main:
            left += checkpoint_seconds(checkpoint_path(self.out, r))
        with progress_label("main stage") if reversible_first_on(config) \
                else contextlib.nullcontext():
            return fit(
                with_dtype(model, self.dtype), train, loss=loss, validation=valid,
                max_seconds=left, scale=self.units.rate,
                dtype=self.dtype, progress=self.progress,
                checkpoint=Checkpoint(checkpoint_path(self.out, r), every=config.checkpoint_every,
                                      resume=main),
                data_parallel=config.data_parallel,
                finish=LBFGSFinish(config.lbfgs_steps) if config.lbfgs_steps else None,
                input_noise=input_noise_of(config, train, self.constant), key=f_key,
                **fit_settings(config))


@dataclasses.dataclass(frozen=True)
class Outcome:
    """How one training ended: the held-out rollout ``score`` and ``failures`` of its kept
    model (``score`` infinite where it diverged or was not judged), its ``best_step``, how it
    ``stopped``, its wall time in ``seconds`` (with the stages before the main one), whether
    its stopping rule ended it (``converged``) and whether it ``diverged``."""

    score: float
    failures: int
    best_step: int
    stopped: str
    seconds: float
    converged: bool = False
    diverged: bool = False
    change: str = ""
    degenerate: bool | None = None

    @classmethod
    def of(cls, history: History, seconds: float) -> Outcome:
        score = history.best_rollout
        return cls(score=score if math.isfinite(score) else math.inf,
                   failures=max(history.best_rollout_failures, 0),
                   best_step=history.best_step, stopped=history.stopped, seconds=seconds,
                   converged=history.converged)

    @classmethod
    def from_json(cls, obj: dict[str, Any]) -> Outcome:
        """The outcome that :meth:`to_json` wrote (``config.json``'s ``trainings``)."""
        known = {f.name for f in dataclasses.fields(cls)} - {"score"}
        score = obj.get("score")
        return cls(score=math.inf if score is None else float(score),
                   **{"failures": 0, "best_step": 0, "stopped": "", "seconds": 0.0,
                      **{k: v for k, v in obj.items() if k in known}})

    def good(self, limit: float = GOOD_SCORE) -> bool:
        """Held-out rollouts within ``limit`` (:func:`good_score`), none failing, and the model
        not found to break M grad E = 0 (``degenerate``: :meth:`Training.degenerate`; ``None``
        where it was not measured)."""
        return self.failures == 0 and self.score <= limit and self.degenerate is not False

    def rank(self, limit: float = GOOD_SCORE) -> tuple[int, bool, float]:
        """Fewer failed held-out rollouts first, then a good one (:meth:`good`), a lower score."""
        return self.failures, not self.good(limit), self.score

    def to_json(self) -> dict[str, Any]:
        return {**dataclasses.asdict(self),
                "score": self.score if math.isfinite(self.score) else None}


def train_repeats(
    one: Callable[[int, bool], tuple[GenericModel, History]], *, repeats: int, out: Path,
    resume: bool, budget: float | None, began: float,
    keep: Callable[[GenericModel, History], None], change: Callable[[int], str] = lambda r: "",
    good: float = GOOD_SCORE, earlier: Sequence[float] = (),
    degenerate: Callable[[GenericModel, int], bool | None] = lambda model, r: None,
) -> tuple[GenericModel, History, list[Outcome], int]:
    """Up to ``repeats`` trainings ``one(r, resume_r)`` (``r`` from 0; ``resume_r`` where
    ``resume`` and training ``r`` left a checkpoint, of a stage or its own); the next runs only
    while the best so far is not :meth:`Outcome.good` (at ``good``, :func:`good_score`), the
    last one converged or diverged (one that a step budget ended wants more steps, not another
    start), the wall-time ``budget``
    (seconds from ``began``) lasts and no training was interrupted. Returns ``(best model, its
    history, every training's outcome, the index of the best)``. ``keep(model, history)``
    saves each new best before the next training, so that an interruption never loses it. A
    training that diverges counts as a failed one; where all diverge, the last error is
    raised. ``change(r)``: how training ``r``'s settings differ from the run's, as flags
    (:meth:`Training.change_of`), said when it starts and kept in its outcome. ``earlier``: the
    seconds each training had taken in the run that this one resumes (at least its main stage's,
    which its checkpoint holds), which a resumed training's outcome counts with its own (a
    resumed run recorded 134 s for a training of 735 s). ``degenerate(model, r)``: whether
    training ``r``'s model keeps M grad E = 0 (:meth:`Training.degenerate`); if not, not good
    (Ctrl-C while it is measured keeps the finished training, unmeasured, and ends the run)."""
    best: tuple[GenericModel, History, Outcome] | None = None
    chosen = 0
    outcomes: list[Outcome] = []
    diverged: TrainingDiverged | None = None
    for r in range(repeats):
        if r and _enough(best, outcomes[-1], budget, began, good):
            break
        if r:
            print(_again_line(r, repeats, best, change(r), good), file=sys.stderr)
        resumed = resume and left_checkpoint(out, r)
        before = 0.0 if not resumed else max(earlier[r] if r < len(earlier) else 0.0,
                                              checkpoint_seconds(checkpoint_path(out, r)))
        start = time.perf_counter() - before
        try:
            # Each bar of the training says which one it is (a run of four took 21 minutes).
            with progress_label(f"training {r + 1} of at most {repeats}") if repeats > 1 \
                    else contextlib.nullcontext():
                model, history = one(r, resumed)
        except TrainingDiverged as e:
            diverged = e
            outcomes.append(Outcome(math.inf, 0, 0, str(e), time.perf_counter() - start,
                                    diverged=True, change=change(r)))
            continue
        except KeyboardInterrupt:
            if best is None:
                raise
            # Ctrl-C in a stage before training r's main one: the best model so far is the
            # run's; --resume goes on with training r from its stage's checkpoint, if any.
            best[1].stopped = f"{INTERRUPTED} in training {r + 1}"
            break
        after = ""  # Ctrl-C after the training: it is done, so it is ranked, unmeasured
        try:
            degenerate_r = (None if ending(history.stopped) == INTERRUPTED
                            else degenerate(model, r))
        except KeyboardInterrupt:
            degenerate_r, after = None, f"{INTERRUPTED} after training {r + 1} had ended"
            history.stopped = f"{after} ({history.stopped})"
        outcome = dataclasses.replace(Outcome.of(history, time.perf_counter() - start),
                                      change=change(r), degenerate=degenerate_r)
        outcomes.append(outcome)
        if best is None or outcome.rank(good) < best[2].rank(good):
            best, chosen = (model, history, outcome), r
            if r + 1 < repeats:
                keep(model, history)
        if ending(history.stopped) == INTERRUPTED:
            if best[1] is not history:  # the run stops here: say so on the kept history
                best[1].stopped = after or f"{history.stopped} of training {r + 1}"
            break
    if best is None:
        assert diverged is not None
        raise diverged
    cut = [i for i, o in enumerate(outcomes) if ending(o.stopped) == TIME_BUDGET]
    if cut and not best[2].good(good):  # said: a Python caller gets no final line
        print(f"repeats: the time budget ended training {cut[-1] + 1} of at most {repeats} "
              f"before it converged; the best so far (training {chosen + 1}) is kept, not "
              "judged good: allow more time (--resume with a larger --max-minutes)",
              file=sys.stderr)
    return best[0], best[1], outcomes, chosen


def _enough(best: tuple[Any, History, Outcome] | None, last: Outcome, budget: float | None,
            began: float, good: float = GOOD_SCORE) -> bool:
    if best is not None and (best[2].good(good) or ending(best[1].stopped) == INTERRUPTED):
        return True
    if not (last.converged or last.diverged):
        return True
    return budget is not None and time.perf_counter() - began >= budget


def _again_line(r: int, repeats: int, best: tuple[Any, History, Outcome] | None,
                change: str = "", good: float = GOOD_SCORE) -> str:
    if best is None:
        why = "every training so far diverged"
    else:
        o = best[2]
        why = (f"{o.failures} held-out rollout(s) of the best model so far failed"
               if o.failures else
               "the best model so far leaves M grad E = 0 unmet at the held-out states (with "
               "L = 0 nothing else ties its learned E to the motion)"
               if o.degenerate is False and o.score <= good else
               f"the held-out rollouts of the best model so far err by {o.score:.3g} of the "
               f"data's spread (good: <= {good:.3g}"
               + (f", {NOISE_FLOOR}x the noise on the held-out states)" if good > GOOD_SCORE
                  else ")"))
    how = (f"with {change} (the form the {r} before did not fit; the held-out rollouts "
           "choose)" if change else "from another initialisation")
    return (f"repeats: {why}; training {r + 1} of at most {repeats} {how} (--repeats 1: one "
            "training only)")
