"""Training stages before the main one: ``--reversible-first`` trains the reversible part
alone, so that the friction joins an energy that already drives the motion."""

from __future__ import annotations

import dataclasses
import sys
from typing import TYPE_CHECKING

import equinox as eqx
import jax

from .._errors import TrainingDiverged
from .._model import GenericModel, with_dtype
from .._units import Units
from ..data import Trajectories
from ..train import fit
from ._build import build_loss, build_model, fit_settings
from .config import LEARNED_POISSON, RunConfig, confine_on, temperature_weight

if TYPE_CHECKING:
    from jax.typing import DTypeLike


def reversible_first(model: GenericModel, config: RunConfig, train: Trajectories,
                     valid: Trajectories | None, *, units: Units, constant: tuple[int, ...],
                     dtype: DTypeLike, key: jax.Array, progress: bool = False,
                     max_seconds: float | None = None) -> GenericModel:
    r"""``model`` with its energy (and its learned L) taken from a first training of the same
    configuration with no friction, :math:`\dot x = L\nabla E` alone.

    With S given and entropy produced along the data, a pure-friction model (E = 0, M = f
    f^T/σ) fits as exactly as the true one (README, *Friction that carries the motion*), and
    training from scratch tends to end there. Started from an energy that already drives the
    motion, the friction is left with what the energy cannot explain. The first stage keeps
    the model of its best validation loss: its held-out rollouts cannot follow the entropies,
    so judging it by them would keep an almost untrained one. ``max_seconds`` caps this stage
    (``--max-minutes``, which the main stage shares).
    """
    # The first stage keeps the hinge on negative temperatures and the wall that the main one
    # has (decided for the main stage's structure, since its energy is carried over).
    first = dataclasses.replace(config, friction="zero", reversible_first=False,
                                w_temperature=temperature_weight(config),
                                confine=confine_on(config))
    init_key, key = jax.random.split(key)
    start = with_dtype(build_model(first, train, key=init_key, units=units,
                                   constant=constant), dtype)
    try:
        fitted, history = fit(
            start, train, loss=build_loss(first, units), validation=valid,
            max_seconds=max_seconds, scale=units.rate, dtype=dtype, progress=progress,
            rollout_check=None, key=key, **fit_settings(first),
        )
        stopped = history.stopped
    except TrainingDiverged as e:
        # The main training starts from the best energy before the divergence (or the untrained
        # one) and meets the same settings: it keeps and saves its own best model.
        fitted, stopped = (start if e.model is None else e.model), str(e)
    if stopped.startswith("interrupted"):
        # Nothing of this stage is checkpointed: stop the whole training, as Ctrl-C asks.
        raise KeyboardInterrupt
    print(f"reversible first: L grad E alone, {stopped}", file=sys.stderr)
    model = eqx.tree_at(lambda m: m.energy, model, fitted.energy)
    if config.poisson in LEARNED_POISSON:
        model = eqx.tree_at(lambda m: m.poisson, model, fitted.poisson)
    return model
