"""Training stages before the main one: ``--starts`` tries several initialisations and trains
the best from its start, and ``--reversible-first`` trains the reversible part alone, so that the
friction joins an energy that already drives the motion (with ``--hold-energy``, the friction
is first trained to that energy held)."""

from __future__ import annotations

import dataclasses
import math
import sys
import time
from typing import TYPE_CHECKING, Any, Callable

import equinox as eqx
import jax
import numpy as np

from .._fit_loop import INTERRUPTED, ending
from .._balance import balance_temperatures, with_temperatures
from .._errors import TrainingDiverged
from .._model import GenericModel, with_dtype
from .._progress import progress_label
from .._units import Units
from ..data import Trajectories
from ..losses import Loss
from ..structure import Known
from ..train import Checkpoint, fit
from ._build import Given, build_loss, build_model, fit_settings
from .config import (LEARNED_POISSON, RunConfig, confine_on, entropy_variables, hold_energy_on,
                     reversible_first_on, temperature_init_on, temperature_weight)

if TYPE_CHECKING:
    from jax.typing import DTypeLike

#: Initialisations tried where L is learned (``--starts`` left out), and the steps each trains
#: before the best is chosen. A learned L and E trade a gauge (for L = a(x) J: a/phi'(E),
#: phi(E)), and some initialisations fall into a poor minimum early: a zero of a across the
#: pendulum's data from one in ~20 (before L of two variables kept one sign), the first of
#: three 30x behind the others after 1 000 steps on oscillator-family and 7x on the rigid
#: body (test error 8.2e-2 -> 4.5e-2 with the best of three; docs/zoo.md, *Found outside the
#: zoo*).
STARTS, START_STEPS = 3, 1_000

#: The slope along the entropy variables, in the networks' units, above which the main stage
#: starts from the temperatures of the data's energy balance (``--temperature-init``). A
#: network initialised at order one has slopes of order one and grows them by itself: the
#: true energies of every zoo case, system outside the zoo and reference experiment with a
#: given L and S = sum have slopes of 0.08-11 there. A gantry crane whose brake stores 50x
#: its mechanical energy has 1 600 (the balance read 860-970), which the network did not
#: reach (test error 0.24-0.33 -> 1.1e-2-4.5e-2; docs/zoo.md, *Temperatures from the energy
#: balance*).
SLOPE_FLOOR = 100.0


def left_of(max_seconds: float | None, since: float) -> float | None:
    """What is left of a wall-time cap ``max_seconds`` counted from ``since`` (a
    ``time.perf_counter()`` reading): at least a second, so that a stage still evaluates."""
    return None if max_seconds is None else max(max_seconds - (time.perf_counter() - since), 1.0)


def starts_for(config: RunConfig) -> int:
    """How many initialisations training tries (``--starts``); left out: :data:`STARTS`
    where L is learned, else 1."""
    if config.starts is not None:
        return config.starts
    return STARTS if config.poisson in LEARNED_POISSON else 1


def best_start(build: Callable[[jax.Array], GenericModel], key: jax.Array, *, starts: int,
               train: Trajectories, valid: Trajectories | None, fit_args: dict[str, Any],
               label: str) -> GenericModel:
    """Of ``starts`` initialisations ``build(key_i)`` (the first from ``key`` itself), the one
    whose training with ``fit_args`` for :data:`START_STEPS` steps (at most a tenth of
    ``fit_args["steps"]``, the stage's cap) reached the lowest validation loss (training loss
    without validation), **untrained**: the stage then trains it from its start, so where the
    first initialisation is best it runs exactly as with one start. ``label`` names the stage
    on the line this prints."""
    first = build(key)
    if starts <= 1:
        return first
    steps = min(START_STEPS, max(fit_args.get("steps", START_STEPS) // 10, 1))
    scores, chosen, best = [], 0, first
    began = time.perf_counter()
    for i in range(starts):
        start = first if i == 0 else build(jax.random.fold_in(key, i))
        try:  # the tries share the stage's wall-time cap, if any
            _, history = fit(start, train, validation=valid, rollout_check=None,
                             progress=False, key=jax.random.fold_in(key, starts + i),
                             **{**fit_args, "steps": steps, "stopping": None, "average": None,
                                "max_seconds": left_of(fit_args.get("max_seconds"), began)})
            if ending(history.stopped) == INTERRUPTED:
                raise KeyboardInterrupt
            score = math.inf if math.isnan(history.best_valid) else history.best_valid
        except TrainingDiverged:
            score = math.inf
        scores.append(score)
        if score < scores[chosen]:
            chosen, best = i, start
    print(f"{label}: initialisation {chosen + 1} of {starts}, trained from its start (validation "
          f"losses after {steps} steps each: {', '.join(f'{v:.2e}' for v in scores)})",
          file=sys.stderr)
    return best


def _best_initialisation(config: RunConfig, key: jax.Array, *, starts: int, label: str,
                         train: Trajectories, valid: Trajectories | None, units: Units,
                         constant: tuple[int, ...], dtype: DTypeLike, loss: Any,
                         given: Given | None = None,
                         max_seconds: float | None = None) -> GenericModel:
    """:func:`best_start` over the models ``config`` describes, each tried with its training
    settings and ``loss``."""
    return best_start(
        lambda k: with_dtype(build_model(config, train, key=k, units=units, constant=constant,
                                         given=given), dtype),
        key, starts=starts, train=train, valid=valid, label=label,
        fit_args=dict(fit_settings(config), loss=loss, scale=units.rate, dtype=dtype,
                      max_seconds=max_seconds))


def _stage(start: GenericModel, config: RunConfig, train: Trajectories,
           valid: Trajectories | None, *, loss: Any, units: Units, dtype: DTypeLike,
           key: jax.Array, progress: bool, max_seconds: float | None,
           checkpoint: Checkpoint | None = None) -> tuple[GenericModel, str]:
    """A stage before the main one, trained from ``start`` with ``config``'s settings and kept
    by its validation loss, not by held-out rollouts: ``(model, how it stopped)``. With a
    ``checkpoint`` an interrupted stage is kept there, and resumed from it where it says so."""
    try:
        fitted, history = fit(start, train, loss=loss, validation=valid, max_seconds=max_seconds,
                              scale=units.rate, dtype=dtype, progress=progress,
                              rollout_check=None, checkpoint=checkpoint, key=key,
                              **fit_settings(config))
        stopped = history.stopped
    except TrainingDiverged as e:
        # The main training starts from the best model before the divergence (or the untrained
        # one) and meets the same settings: it keeps and saves its own best model.
        fitted, stopped = (start if e.model is None else e.model), str(e)
    if ending(stopped) == INTERRUPTED:
        # Stop the whole training, as Ctrl-C asks (the stage's checkpoint, if any, keeps it).
        raise KeyboardInterrupt
    return fitted, stopped


def reversible_first(model: GenericModel, config: RunConfig, train: Trajectories,
                     valid: Trajectories | None, *, units: Units, constant: tuple[int, ...],
                     dtype: DTypeLike, key: jax.Array, main_loss: Loss,
                     progress: bool = False, max_seconds: float | None = None,
                     checkpoint: Callable[[str], Checkpoint] | None = None) -> GenericModel:
    r"""``model`` with its energy (and its learned L) taken from a first training of the same
    configuration with no friction, :math:`\dot x = L\nabla E` alone (and, with
    ``--hold-energy``, the rest then trained to that energy held: :func:`friction_to_energy`).

    With S given and entropy produced along the data, a pure-friction model (E = 0, M = f
    f^T/σ) fits as exactly as the true one (README, *Friction that carries the motion*), and
    training from scratch tends to end there. Started from an energy that already drives the
    motion, the friction is left with what the energy cannot explain. The first stage keeps
    the model of its best validation loss: its held-out rollouts cannot follow the entropies,
    so judging it by them would keep an almost untrained one. ``main_loss`` is the main
    stage's (``build_loss(config, units, train)``), which the held stage trains with.
    ``max_seconds`` caps this stage and the held one together (``--max-minutes``, which the
    main stage shares). ``checkpoint(stage)``, where given, is the :class:`~metriplex.Checkpoint`
    of the stage named ``"first-stage"`` or ``"held-stage"``; a first stage resumed from its
    checkpoint skips the choice of initialisation (the checkpoint holds the chosen one, trained).
    """
    # The first stage keeps the hinge on negative temperatures and the wall that the main one
    # has (decided for the main stage's structure, since its energy is carried over).
    first = dataclasses.replace(config, friction="zero", reversible_first=False,
                                hold_energy=False, temperature_init=False,
                                w_temperature=temperature_weight(config),
                                confine=confine_on(config))
    init_key, key = jax.random.split(key)
    began = time.perf_counter()
    loss = build_loss(first, units, train)
    saved = None if checkpoint is None else checkpoint("first-stage")
    if saved is not None and saved.resume:  # any model of the structure: its weights are read
        start = with_dtype(build_model(first, train, key=init_key, units=units,
                                       constant=constant), dtype)
    else:
        start = _best_initialisation(first, init_key, starts=starts_for(config),
                                     label="reversible first", train=train, valid=valid,
                                     units=units, constant=constant, dtype=dtype, loss=loss,
                                     max_seconds=max_seconds)
    with progress_label("first stage"):
        fitted, stopped = _stage(start, first, train, valid, loss=loss, units=units,
                                 dtype=dtype, key=key, progress=progress, checkpoint=saved,
                                 max_seconds=left_of(max_seconds, began))
    print(f"reversible first: L grad E alone, {stopped}", file=sys.stderr)
    model = eqx.tree_at(lambda m: m.energy, model, fitted.energy)
    if temperature_init_on(config):  # a network energy reading the state (checked)
        model = _balanced(model, entropy_variables(config), train)
    if config.poisson in LEARNED_POISSON:
        model = eqx.tree_at(lambda m: m.poisson, model, fitted.poisson)
    if not hold_energy_on(config):
        return model
    return friction_to_energy(model, config, train, valid, loss=main_loss, units=units,
                              dtype=dtype, key=jax.random.fold_in(key, 1), progress=progress,
                              max_seconds=left_of(max_seconds, began),
                              checkpoint=None if checkpoint is None else checkpoint("held-stage"))


def _balanced(model: GenericModel, indices: tuple[int, ...],
              train: Trajectories) -> GenericModel:
    """``model`` with its energy's temperatures along the entropy variables ``indices`` read
    from the training data's energy balance (``--temperature-init``) where, in the networks'
    units, they exceed :data:`SLOPE_FLOOR`; said on one line. Below it the energy gets a zero
    slope, which changes nothing (never trained, it keeps the structure that ``build_model``
    gives and a resumed main stage reads)."""
    temperatures = balance_temperatures(model.energy, train, indices)
    energy = with_temperatures(model.energy, indices, temperatures)
    slope = float(np.max(np.abs(np.asarray(energy.linear))))
    if slope > SLOPE_FLOOR:
        said = ", ".join(f"{t:.3g}" for t in temperatures)
        print(f"temperatures from the energy balance: {said} added to dE/ds_i ({slope:.3g} in "
              f"the networks' units; --no-temperature-init turns this off)", file=sys.stderr)
    else:
        energy = with_temperatures(model.energy, indices, np.zeros(len(indices)))
    return eqx.tree_at(lambda m: m.energy, model, energy)


def friction_to_energy(model: GenericModel, config: RunConfig, train: Trajectories,
                       valid: Trajectories | None, *, loss: Loss, units: Units,
                       dtype: DTypeLike, key: jax.Array, progress: bool = False,
                       max_seconds: float | None = None,
                       checkpoint: Checkpoint | None = None) -> GenericModel:
    r"""``model`` with the rest of it (friction, and L or S where learned) trained to the
    energy of the first stage, which it holds: ``--hold-energy``, between the first stage of
    ``--reversible-first`` and the main one.

    The main stage starts with a friction that explains nothing yet, so the entropies' rates
    are its largest residual, and at the full learning rate their gradients reach the energy
    (through the temperatures and the exact degeneracy) and undo the fit of the forces that the
    first stage made (the energetic pendulum, full size: a mean square residual of the
    momenta of 0.04 of their rates' scale after the first stage, 0.2 after the main one).
    Held, the energy gives the friction time to fit; the main stage then trains everything from
    there, with the same ``loss``. Like the first stage it keeps the model of its best
    validation loss and stops on its plateau, within ``config.steps``. The energy is held as a
    :class:`~metriplex.Known` function of the state, so the optimiser never sees its parameters.
    """
    energy = model.energy
    # A closure, not the module itself: Known's function is static (hashed), and a module
    # holds arrays.
    held = eqx.tree_at(lambda m: m.energy, model, Known(lambda x: energy(x)))
    began = time.perf_counter()
    with progress_label("held stage"):
        fitted, stopped = _stage(held, config, train, valid, loss=loss, units=units,
                                 dtype=dtype, key=key, progress=progress,
                                 max_seconds=max_seconds, checkpoint=checkpoint)
    print(f"friction to the energy held: {stopped} ({time.perf_counter() - began:.0f} s)",
          file=sys.stderr)
    return eqx.tree_at(lambda m: m.energy, fitted, energy)


def before_main(model: GenericModel, config: RunConfig, train: Trajectories,
                valid: Trajectories | None, *, units: Units, constant: tuple[int, ...],
                given: Given, dtype: DTypeLike, model_key: jax.Array, key: jax.Array,
                loss: Loss, progress: bool = False, max_seconds: float | None = None,
                checkpoint: Callable[[str], Checkpoint] | None = None) -> GenericModel:
    """The model the main stage starts from: ``model`` (built from ``model_key``) after the
    first stage where ``--reversible-first`` is on (which tries ``--starts`` initialisations
    itself, and keeps ``checkpoint(stage)``: :func:`reversible_first`), else the best of
    ``--starts`` initialisations of the whole model, each tried with the main stage's
    ``loss`` (short trainings, not checkpointed: a resumed run tries them again)."""
    if reversible_first_on(config):
        return reversible_first(model, config, train, valid, units=units, constant=constant,
                                dtype=dtype, key=key, main_loss=loss, progress=progress,
                                max_seconds=max_seconds, checkpoint=checkpoint)
    starts = starts_for(config)
    if starts <= 1:
        return model
    return _best_initialisation(config, model_key, starts=starts, label="starts", train=train,
                                valid=valid, units=units, constant=constant, dtype=dtype,
                                loss=loss, given=given, max_seconds=max_seconds)
