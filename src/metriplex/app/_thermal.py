"""The options against a friction that carries the motion (README, *Friction that carries the
motion*): whether training starts with L grad E alone, the weight of the hinge on negative
learned temperatures, which learned blocks are exactly degenerate (``--degeneracy``), whether
the learned E has the wall around the data (``--confine``), and their checks."""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

import numpy as np

from .._errors import MetriplexError
from ..structure.confinement import MARGIN
from ._option import entropy_variables as _sum_indices, option
from ._spellings import FRICTION, POISSON

if TYPE_CHECKING:
    from ..structure import AbstractPoisson, AbstractPotential


class ThermalFields(Protocol):
    """The fields of :class:`~metriplex.app.config.RunConfig` that these options read (a
    protocol, so that this module does not import the configuration that imports it)."""

    energy: str
    entropy: str
    poisson: str
    friction: str
    features: str
    features_for: str
    reversible_first: bool | None
    temperature_init: bool | None
    hold_energy: bool | None
    w_temperature: float | None
    degeneracy: str
    confine: bool | None


#: The ``--friction`` spellings whose M is learned (those of the spelling table that learn).
LEARNED_FRICTIONS = tuple(k for k, v in FRICTION.items() if v.learned)
#: The learned frictions built with M grad E = 0 exact whatever ``--degeneracy`` says.
EXACT_FRICTIONS = ("exchange", "local")


def reversible_first_on(config: ThermalFields) -> bool:
    """Whether training starts with L grad E alone (``--reversible-first``). By default (left
    out) it does when M is learned beside an L and an S that are not zero: then a friction
    alone can fit the data as well as the true split (README, *Friction that carries the
    motion*)."""
    if config.reversible_first is not None:
        return config.reversible_first
    return (option(config.friction).kind in LEARNED_FRICTIONS and config.poisson != "zero"
            and config.entropy != "zero")


def hold_energy_on(config: ThermalFields) -> bool:
    """Whether, between the first stage (L grad E alone) and the main one, the friction (and
    L or S where learned) is trained to the first stage's energy held (``--hold-energy``).
    Off unless asked for: it made the energetic pendulum up to 17x more accurate, but all nine
    zoo cases that it changes 1.0-1.8x less, and one of them missed the bar with it
    (docs/zoo.md, *The friction trained to the energy held*)."""
    return bool(config.hold_energy)


def temperature_init_on(config: ThermalFields) -> bool:
    """Whether the main stage may start with the learned E's temperatures dE/ds_i read from
    the data's energy balance (``--temperature-init``; :func:`metriplex._balance.
    balance_temperatures`, set where they are far beyond what the network reaches by itself:
    ``_stages.SLOPE_FLOOR``). Left out: wherever the balance can be read
    (:func:`_balance_readable`)."""
    if config.temperature_init is not None:
        return config.temperature_init
    return _balance_readable(config)


def _balance_readable(config: ThermalFields) -> bool:
    """Whether training starts with L grad E alone beside a **given** L, named entropy
    variables and the default energy network that reads the state itself (no features). A
    given L fixes the first stage's E up to a function of the entropy variables (its
    Casimirs), whose slope the balance reads; a learned L trades a further gauge with it
    (L = a J, E -> phi(E)), and the zoo's learned-L cases read negative temperatures."""
    features = {b.strip() for b in config.features_for.split(",")}
    return (reversible_first_on(config) and option(config.entropy).kind == "sum"
            and option(config.energy).kind == "neural"
            and not POISSON[option(config.poisson).kind].learned
            and (config.features == "none" or "energy" not in features))


def temperature_weight(config: ThermalFields) -> float:
    """The weight of the hinge on negative learned temperatures (``--w-temperature``); left
    out: 1 where the entropy variables are named and training starts with L grad E alone
    (:func:`reversible_first_on`), else 0."""
    if config.w_temperature is not None:
        return config.w_temperature
    return 1.0 if option(config.entropy).kind == "sum" and reversible_first_on(config) else 0.0


def check_thermal_options(config: ThermalFields) -> None:
    """``--w-temperature`` needs entropy variables; ``--reversible-first`` a learned friction
    beside a non-zero L; ``--hold-energy`` the first stage."""
    if (config.w_temperature or 0.0) > 0 and option(config.entropy).kind != "sum":
        raise MetriplexError(
            f"--w-temperature penalises negative temperatures dE/ds_i, so it needs the entropy "
            f"variables, --entropy sum:I,J,...; got --entropy {config.entropy}. Name them, or "
            "leave --w-temperature out.")
    if config.reversible_first and (option(config.friction).kind not in LEARNED_FRICTIONS
                                    or config.poisson == "zero"):
        raise MetriplexError(
            f"--reversible-first first trains L grad E alone, then adds the learned friction, so "
            f"it needs a learned friction (--friction {' or '.join(LEARNED_FRICTIONS)}) and an L "
            f"other than zero; got --friction "
            f"{config.friction} --poisson {config.poisson}. Leave --reversible-first out.")
    if config.temperature_init and not _balance_readable(config):
        raise MetriplexError(
            "--temperature-init reads the temperatures dE/ds_i from the energy of the first "
            "stage (L grad E alone), so it needs that stage beside a given L (--poisson "
            "canonical:K or file:...), the entropy variables (--entropy sum:I,J,...) and the "
            f"default energy network reading the state; got --poisson {config.poisson} "
            f"--entropy {config.entropy} --energy {config.energy} --features "
            f"{config.features}"
            + ("" if reversible_first_on(config) else " without the first stage")
            + ". Leave --temperature-init out.")
    if config.hold_energy and not reversible_first_on(config):
        raise MetriplexError(
            "--hold-energy trains the friction to the energy of the first stage (L grad E "
            "alone), so it needs that stage; got --hold-energy where training does not start "
            "with L grad E alone. Add --reversible-first, or leave --hold-energy out.")


def entropy_variables(config: ThermalFields) -> tuple[int, ...]:
    """The indices of ``--entropy sum:I,J,...`` (checked against the data by :func:`validate`)."""
    return _sum_indices(config.entropy)


#: ``--degeneracy``: ``auto`` makes a learned L exactly degenerate when S is given (then
#: L grad S = 0 costs one projection with a known gradient, and the learned entropy can never
#: decrease in a rollout), a learned M exactly degenerate when training starts with L grad E
#: alone (:func:`reversible_first_on`: the learned flow then conserves the learned energy) and
#: keeps the other conditions as penalties; ``exact`` makes every
#: learned L and M exactly degenerate; ``soft`` uses penalties only. ``--friction exchange``
#: and ``--friction local:CELLS`` build M exactly degenerate in every mode
#: (``structure.ExchangeFriction``, ``structure.LocalFriction``).
DEGENERACY_MODES = ("auto", "soft", "exact")

#: The learned L that ``exact`` builds exactly degenerate: ``neural`` as ``projected-neural``,
#: ``casimir3`` as ``casimir3-entropy`` (S its Casimir; not where S = 0, which would leave L = 0),
#: ``lie-poisson`` as ``projected-lie-poisson`` beside a sum of entropy variables only (whose
#: constant gradient keeps L linear); ``exact`` is refused with it beside another S.
PROJECTABLE_POISSON = ("neural", "casimir3", "lie-poisson")


def exact_blocks(config: ThermalFields) -> tuple[bool, bool]:
    """Whether the learned ``(L, M)`` are built exactly degenerate (see ``DEGENERACY_MODES``)."""
    summed = option(config.entropy).kind == "sum"
    if config.degeneracy == "exact":
        kind = option(config.poisson).kind
        return kind == "neural" or (kind == "casimir3" and config.entropy != "zero") or (
            kind == "lie-poisson" and summed), True
    by_construction = option(config.friction).kind in EXACT_FRICTIONS  # in any mode
    if config.degeneracy == "soft":
        return False, by_construction
    # Not lie-poisson, which exact projects beside a sum (linear still): measured less
    # accurate on two systems (docs/zoo.md, *New-user check 21*).
    return (config.poisson == "neural" and summed,
            by_construction or (config.friction == "neural" and reversible_first_on(config)))


def confine_on(config: ThermalFields) -> bool:
    """Whether the learned E gets the wall around the training data (``--confine``). By default
    (left out) it does wherever a learned M has M grad E = 0 exact beside an S that is not zero
    (given as a sum, or learned): then the learned flow conserves E, and the wall's bounded
    level sets keep every rollout bounded. How far out it begins: :func:`confine_margin`."""
    if config.confine is not None:
        return config.confine
    return (option(config.entropy).kind != "zero"
            and option(config.friction).kind in LEARNED_FRICTIONS
            and exact_blocks(config)[1])


#: Where S is learned the wall begins this many standard deviations beyond the training states
#: (:func:`confine_margin`): a zoo case's test states reach 2.2 beyond them, and the wall one
#: standard deviation out cost it 100x in accuracy (docs/zoo.md, *The wall where S is learned*).
LEARNED_ENTROPY_MARGIN = 3.0


def confine_margin(config: ThermalFields) -> float:
    """How many standard deviations beyond the training states the wall begins: the
    confinement's ``MARGIN`` (1) where S is given as a sum of entropy variables (measured on
    every zoo case and reference experiment that gives it), :data:`LEARNED_ENTROPY_MARGIN` (3)
    where S is learned."""
    return LEARNED_ENTROPY_MARGIN if option(config.entropy).kind == "neural" else MARGIN


def check_entropy_left_still(poisson: AbstractPoisson | None,
                             entropy: AbstractPotential | None, flags: str) -> None:
    """Refuse a given constant L that moves a given S = sum of variables: L grad S = 0 is one
    of GENERIC's degeneracy conditions, and no training can meet it then. ``poisson`` and
    ``entropy`` are the given blocks (None where learned); ``flags`` names the options."""
    from ..structure import CanonicalPoisson, ConstantPoisson, SumOf

    if not isinstance(entropy, SumOf):
        return
    if isinstance(poisson, CanonicalPoisson):
        L = np.asarray(poisson.matrix())
    elif isinstance(poisson, ConstantPoisson):
        L = np.asarray(poisson.matrix)
    else:
        return
    moved = L[:, list(entropy.indices)].sum(axis=1)  # L grad S, grad S = sum of unit vectors
    if np.max(np.abs(moved)) <= 1e-12 * max(1.0, float(np.max(np.abs(L)))):
        return
    still = [i for i in range(L.shape[0]) if not np.any(L[:, i]) and not np.any(L[i, :])]
    raise MetriplexError(
        f"{flags}: the given L moves the given entropy (L grad S = "
        f"{np.round(moved, 12).tolist()}), so L grad S = 0, a degeneracy condition of GENERIC, "
        "cannot hold and the entropy would change along the reversible motion. Name as entropy "
        "variables ones that L leaves still"
        + (f" (here {still})" if still else "")
        + ", or learn S (--entropy neural)."
    )
