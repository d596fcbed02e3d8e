r"""The loop of :func:`~metriplex.fit`: chunks of compiled optimiser steps, an evaluation after
each (:class:`Evaluation`: the pair losses and the held-out rollouts that keep the best model),
the stopping rule, checkpoints and the L-BFGS finish (:class:`FitLoop`).

``fit`` builds the pieces from its arguments and runs one ``FitLoop``; everything the loop
changes lives in its :class:`~metriplex._train.TrainState`, which is what a checkpoint saves.
"""

from __future__ import annotations

import dataclasses
import math
import time
from typing import TYPE_CHECKING, Any, Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.random as jr

from ._errors import TrainingDiverged
from ._interrupt import CtrlC
from ._optimizers import annealing, learning_rate_of, with_learning_rate
from ._train import History, TrainState, make_lbfgs_chunk, spread
from ._progress import CAPPED_BAR, TIMED_BAR, progress_bar
from ._validate import rollout_score

#: How a training ended: the words ``History.stopped`` begins with, which :func:`ending` reads
#: (every reader asks it, never the prose itself).
CONVERGED, EARLY_STOP, STEP_BUDGET, TIME_BUDGET, INTERRUPTED, DIVERGED = (
    "converged", "early stop", "step budget", "time budget", "interrupted", "diverged")
#: The endings of a stopping rule: resumed, such a training is kept as it was, as one that
#: reached its steps is; one that its time budget cut trains on, where the resumed run's budget
#: allows.
ENDED = (EARLY_STOP, CONVERGED)


def ending(stopped: str) -> str:
    """How a training ended, from its ``History.stopped`` (or an outcome's ``stopped``): one of
    ``CONVERGED``, ``EARLY_STOP``, ``STEP_BUDGET``, ``TIME_BUDGET``, ``INTERRUPTED``,
    ``DIVERGED``; ``""`` where it had not ended, or the words are another's (a diverged
    training's outcome in ``--repeats`` keeps its error's message, "training diverged ...",
    and its own ``diverged`` flag)."""
    return next((e for e in (CONVERGED, EARLY_STOP, STEP_BUDGET, TIME_BUDGET, INTERRUPTED,
                             DIVERGED) if stopped.startswith(e)), "")

if TYPE_CHECKING:
    import numpy as np

    from ._fit_options import Checkpoint, LBFGSFinish
    from ._loss_base import Batch, Loss
    from ._model import AbstractModel
    from ._pairs import PairStore
    from ._validate import Average, Plateau
    from .integrate import AbstractScheme


@eqx.filter_jit
def _evaluate(params, batch, key, loss, static):
    """The loss on ``batch``: one compiled program for every fit of the same loss, model
    structure and shapes (several starts, the stages)."""
    return loss(eqx.combine(params, static), batch, key=key)


@dataclasses.dataclass
class Evaluation:
    """What one evaluation of :func:`~metriplex.fit` computes: the loss on fixed subsets of the
    training and validation pairs (``train_pairs``, ``valid_pairs``), and, with ``windows``,
    the score of held-out rollouts by ``scheme`` in units of ``state_units``."""

    loss: Loss
    static: Any
    train_pairs: Batch
    valid_pairs: Batch | None
    key: jax.Array
    windows: Any = None
    scheme: AbstractScheme | None = None
    state_units: np.ndarray | None = None

    def pairs(self, params: Any, batch: Batch) -> tuple[float, dict[str, float]]:
        """The loss and its terms on ``batch``, as Python floats."""
        total, parts = _evaluate(params, batch, self.key, self.loss, self.static)
        return float(total), {k: float(v) for k, v in parts.items()}

    def rollouts(self, params: Any) -> tuple[float, int]:
        """The held-out rollout score and the number of failed rollouts."""
        return rollout_score(eqx.combine(params, self.static), self.scheme, self.windows,
                             self.state_units)


@dataclasses.dataclass
class FitLoop:
    """One run of :func:`~metriplex.fit` from ``state``: ``run_chunk`` (the compiled optimiser
    steps on ``train``), evaluated by ``evaluation`` every ``eval_every`` steps (on the
    running ``average`` of the parameters, where given), stopped by
    ``stopping`` (a :class:`~metriplex.train.Plateau`, where the optimiser's rate can be
    adjusted), ``patience``, ``steps`` or ``max_seconds``; optionally checkpointed and finished
    by L-BFGS."""

    state: TrainState
    static: Any
    run_chunk: Callable
    train: PairStore
    evaluation: Evaluation
    steps: int
    eval_every: int
    stopping: Plateau | None
    adjustable: bool
    rate_at: Callable[[int], Any] | None
    patience: int | None
    max_seconds: float | None
    average: Average | None
    checkpoint: Checkpoint | None
    finish: LBFGSFinish | None
    progress: bool

    @property
    def history(self) -> History:
        """The training history (held by the state, so a checkpoint keeps it)."""
        return self.state.history

    def save_checkpoint(self) -> None:
        if self.checkpoint is not None:
            self.state.save(self.checkpoint.path)

    def next_chunk(self) -> None:
        """Up to ``eval_every`` optimiser steps; over the last fifth of the step budget the rate
        is annealed (cosine to 1%), so a run that the budget ends still finishes on a small
        rate."""
        state, steps = self.state, self.steps
        anneal_from = int(0.8 * steps)
        length = min(self.eval_every, steps - state.done)
        if self.adjustable and state.done >= anneal_from:
            state.opt_state = with_learning_rate(
                state.opt_state, state.lr * annealing(state.done, anneal_from, steps))
        state.key, sub = jr.split(state.key)
        state.params, state.opt_state, value, parts = self.run_chunk(
            state.params, state.opt_state, sub, jnp.asarray(length, jnp.int32), self.train)
        state.average_params = (state.params if self.average is None else
                                self.average.update(state.average_params, state.params, length,
                                                    steps))
        state.train_value = float(value)
        state.train_parts = {k: float(v) for k, v in parts.items()}
        state.done += length
        self.bar.update(length)

    def record_evaluation(self) -> tuple[float, int]:
        """Evaluate the current parameters (their average, where averaged), append to the
        history, keep the best model; return the score and the rollout failures (-1 without
        rollouts)."""
        state, history, ev, stopping = self.state, self.history, self.evaluation, self.stopping
        judged = state.average_params  # the parameters themselves unless averaged
        if state.done > 0:
            tr_total, tr_parts = state.train_value, state.train_parts
        else:
            tr_total, tr_parts = ev.pairs(judged, ev.train_pairs)
        if ev.valid_pairs is not None:
            va_total, va_parts = ev.pairs(judged, ev.valid_pairs)
        else:
            va_total, va_parts = tr_total, {}
        history.step.append(state.done)
        history.time.append(time.perf_counter() - self.start)
        history.learning_rate.append(learning_rate_of(state.opt_state, state.lr)
                                     if self.rate_at is None else float(self.rate_at(state.done)))
        for name, v in tr_parts.items():
            history.train.setdefault(name, []).append(v)
        history.train.setdefault("total", []).append(tr_total)
        for name, v in va_parts.items():
            history.valid.setdefault(name, []).append(v)
        if va_parts:
            history.valid.setdefault("total", []).append(va_total)
        if not math.isfinite(tr_total) or not math.isfinite(va_total):
            bad = [k for k, v in {**tr_parts, **va_parts}.items() if not math.isfinite(v)]
            history.stopped = f"{DIVERGED} at step {state.done} (non-finite: {', '.join(bad)})"
            raise TrainingDiverged(
                f"training diverged at step {state.done}: the loss term(s) {bad or ['total']} "
                f"became non-finite. The best model so far (step {history.best_step}) is "
                "kept on this exception (.model, .history; metriplex train saves it). Lower "
                "the learning rate or the loss weights; where it diverges early whatever the "
                "rate, train in float64 (--float64, fit's dtype=jnp.float64): data whose units "
                "are far from 1 can under- or overflow float32.",
                model=eqx.combine(state.best_params, self.static),
                history=history,
            )
        # The plateau schedule follows the (smooth) validation loss; the model kept is the one
        # with the best score: held-out rollouts when checked, else that loss.
        if va_total < state.plateau_best * (1.0 - (stopping.min_delta if stopping else 0.0)):
            state.since_best = 0
        else:
            state.since_best += 1
        if va_total < state.plateau_best:
            state.plateau_best, state.restart_params = va_total, judged
        score, failures = va_total, -1
        if ev.windows is not None:
            score, failures = ev.rollouts(judged)
            history.rollout.append(score)
            history.rollout_failures.append(failures)
        if score < state.best_value:
            state.best_value, state.best_params = score, judged
            history.best_step, history.best_valid = state.done, va_total
            if ev.windows is not None:
                history.best_rollout, history.best_rollout_failures = score, failures
        postfix = dict(loss=f"{tr_total:.3e}", valid=f"{va_total:.3e}")
        if ev.windows is not None:
            postfix["rollout"] = f"{score:.3g}" + (f" ({failures} failed)" if failures else "")
        if stopping is not None and self.adjustable:  # how far the stopping rule has come
            postfix["lr_cuts"] = f"{state.cuts}/{stopping.cuts}"
        if self.max_seconds is not None:  # the bar's own estimate runs to the step cap
            postfix["time_left"] = f"{max(self.max_seconds - history.time[-1], 0.0):.0f}s"
        self.bar.set_postfix(refresh=False, **postfix)  # redrawn with the bar, as often as it is
        return score, failures

    def should_stop(self) -> bool:
        """Apply the budgets and the plateau schedule after an evaluation."""
        state, history, stopping, patience = self.state, self.history, self.stopping, \
            self.patience
        if state.done >= self.steps:
            history.stopped = history.stopped or f"{STEP_BUDGET} reached ({self.steps} steps)"
            return True
        if self.max_seconds is not None and history.time[-1] >= self.max_seconds:
            history.stopped = (f"{TIME_BUDGET} reached ({self.max_seconds:g} s) at step "
                               f"{state.done}")
            return True
        if stopping is None:
            if patience is not None and state.since_best > patience:
                history.stopped = (f"{EARLY_STOP} at step {state.done} (no improvement in "
                                   f"{patience} evaluations)")
                history.converged = True
                return True
        elif state.since_best >= stopping.patience:
            if state.cuts >= stopping.cuts or not self.adjustable:
                history.stopped = (f"{CONVERGED} at step {state.done} (no improvement in "
                                   f"{stopping.patience} evaluations after {state.cuts} "
                                   "learning-rate cuts)")
                history.converged = True
                return True
            state.cuts += 1
            state.lr *= stopping.factor
            state.params, state.since_best = state.restart_params, 0
            state.average_params = state.restart_params
            state.opt_state = with_learning_rate(state.opt_state, state.lr)
        return False

    def lbfgs_finish(self, ctrl_c: CtrlC) -> None:
        """L-BFGS from the best model on a fixed batch; evaluations keep the best model."""
        state, history, ev, total = self.state, self.history, self.evaluation, self.finish.steps
        solver, chunk = make_lbfgs_chunk(ev.loss, self.static)
        chunk = eqx.filter_jit(chunk)
        pairs = self.train.take(jnp.asarray(spread(self.train.count, self.finish.pairs)),
                                ev.loss.window_shape)
        state.params = state.best_params
        opt_state = solver.init(state.params)
        self.bar = progress_bar(total=total, disable=not self.progress, desc="L-BFGS",
                                unit="it", leave=False)
        done = 0
        try:
            while done < total:
                length = min(self.eval_every, total - done)
                params, opt_state, value = chunk(state.params, opt_state, length, pairs, ev.key)
                if not math.isfinite(float(value)):
                    history.stopped += f"; L-BFGS stopped at iteration {done} (non-finite loss)"
                    break
                state.params = state.average_params = params  # L-BFGS's iterates, as they are
                done += length
                state.done += length
                self.bar.update(length)
                state.train_value, state.train_parts = ev.pairs(state.params, ev.train_pairs)
                self.record_evaluation()
                ctrl_c.check()
                if self.max_seconds is not None and history.time[-1] >= self.max_seconds:
                    break
        except KeyboardInterrupt:
            history.stopped += f"; L-BFGS interrupted at iteration {done}"
        finally:
            self.bar.close()
            history.lbfgs_steps = done

    def run(self, *, resume: bool) -> tuple[AbstractModel, History]:
        """Train until a budget or the stopping rule ends it (or Ctrl-C), finish with L-BFGS if
        asked, save the checkpoint; return the best model and the history."""
        state, history = self.state, self.history
        self.start = time.perf_counter() - (history.time[-1] if history.time else 0.0)
        evaluations = 0
        # The bar's own estimate of the time left runs to the step cap (hours at a few steps
        # a second): under a time budget the postfix says the time left instead, and where a
        # stopping rule ends the run the estimate is said to be the cap's.
        formats = ({"bar_format": TIMED_BAR} if self.max_seconds is not None else
                   {} if self.stopping is None and self.patience is None else
                   {"bar_format": CAPPED_BAR})
        self.bar = progress_bar(total=self.steps, initial=state.done,
                                disable=not self.progress, desc="fit", unit="step", leave=False,
                                **formats)
        with CtrlC() as ctrl_c:
            try:
                finished = resume and (state.done >= self.steps
                                       or ending(history.stopped) in ENDED)
                if resume and not finished and history.step and history.step[-1] == state.done:
                    # The restored history holds the evaluation at its step, unless Ctrl-C
                    # came between a chunk and its evaluation: then the loop makes it first.
                    self.next_chunk()
                while not finished:
                    ctrl_c.check()
                    self.record_evaluation()
                    evaluations += 1
                    if self.checkpoint is not None and evaluations % self.checkpoint.every == 0:
                        self.save_checkpoint()
                    ctrl_c.check()
                    if self.should_stop():
                        break
                    self.next_chunk()
            except KeyboardInterrupt:
                history.stopped = f"{INTERRUPTED} at step {state.done}"
            finally:
                self.bar.close()
            if (self.finish is not None and self.finish.steps
                    and ending(history.stopped) != INTERRUPTED
                    and history.lbfgs_steps == 0):
                self.lbfgs_finish(ctrl_c)
        self.save_checkpoint()
        return eqx.combine(state.best_params, self.static), history
