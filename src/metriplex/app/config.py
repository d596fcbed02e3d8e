"""Run configuration: what is learned and what is given, as plain JSON-able settings.

The command line and the experiment presets describe a run with a :class:`RunConfig`;
:func:`~metriplex.app._build.build_model` and :func:`~metriplex.app._build.build_loss` turn
it into the objects the library works with (``GenericModel``, ``Loss``), and
:func:`scheme_from_name` turns ``--scheme`` and ``--solver`` into a scheme. Library code itself
takes objects, never these strings. What each option may say, with its help text, is in
:mod:`metriplex.app._choices`, re-exported here.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

from .._errors import MetriplexError, expect_integer
from ..integrate import ROOT_FINDERS, SCHEMES, AbstractImplicitScheme, AbstractScheme
from ..structure import ACTIVATION, ACTIVATIONS
from ..structure.potential import FeatureMap

from ._choices import (  # noqa: F401
    DEGENERACY_POINTS,
    ENERGY_CHOICES,
    ENTROPY_CHOICES,
    FRICTION_CHOICES,
    JACOBI_CHOICES,
    POISSON_CHOICES,
    RESIDUAL_METRICS,
    SCHEDULES,
    choices_help,
)

from ._option import option
from ._presets import PRESETS
from ._spellings import SPELLINGS, Spelling
from ._spellings import indices as _indices

from ._thermal import (  # noqa: F401 (re-exported)
    DEGENERACY_MODES,
    check_entropy_left_still,
    check_thermal_options,
    confine_margin,
    confine_on,
    entropy_variables,
    exact_blocks,
    hold_energy_on,
    reversible_first_on,
    temperature_init_on,
    temperature_weight,
)

# The command line's trajectory selection, importable from here as before.
from ._selection import (  # noqa: F401
    IDS_SYNTAX,
    TrajectoryIds,
    check_selection,
    choose_trajectories,
    format_ids,
    parse_ids,
    read_split,
)

FEATURES = {
    # The seed paper's pendulum featurisation: (|q1|^2, |q2 - q1|^2, |p1|^2, |p2|^2, s1, s2).
    "pendulum": FeatureMap(
        squared_norms=(((0, 1), ()), ((2, 3), (0, 1)), ((4, 5), ()), ((6, 7), ())),
        passthrough=(8, 9),
    ),
}


@dataclasses.dataclass
class RunConfig:
    """Every setting of a training run. Field names match the command-line options."""

    energy: str = "neural"
    entropy: str = "neural"
    poisson: str = "neural"
    friction: str = "neural"
    degeneracy: str = "auto"
    degeneracy_at: str = "states"
    jacobi: str = "auto"  # exact with lie-poisson, else none: _build.jacobi_of
    jacobi_probes: int = 1
    jacobi_samples: int | None = None
    features: str = "none"
    features_for: str = "energy,entropy"
    scheme: str | None = None  # None: cn, or hermite where the training steps are coarse
    w_traj: float = 1.0
    w_degeneracy_L: float = 10.0
    w_degeneracy_M: float = 10.0
    w_jacobi: float = 1.0
    quadratic: bool = False
    width: int = 64
    depth: int = 2
    activation: str = ACTIVATION
    lr: float = 1e-2
    weight_decay: float = 0.0
    steps: int = 100_000
    batch_size: int = 256
    validation: float = 0.2
    eval_every: int = 100
    patience: int | None = None
    lr_cuts: int = 3
    schedule: str = "plateau"
    max_minutes: float | None = None
    seed: int = 0
    float64: bool | None = None  # None: float64 where float32 would round the data (runs)
    checkpoint_every: int = 10
    data_parallel: bool = False
    lbfgs_steps: int = 0
    input_noise: float = 0.0
    jitter_constants: bool = True
    consecutive: int = 1
    every: int | None = None
    window_steps: int = 0
    residual_metric: str = "auto"
    average_steps: int = 500
    w_temperature: float | None = None
    reversible_first: bool | None = None
    temperature_init: bool | None = None
    hold_energy: bool | None = None
    starts: int | None = None
    repeats: int | None = None
    confine: bool | None = None
    constant: str = "auto"

    def to_json(self) -> dict[str, Any]:
        """The settings as a JSON-able dict, one entry per field: :meth:`from_json` rebuilds
        them."""
        return dataclasses.asdict(self)

    @classmethod
    def from_json(cls, obj: dict[str, Any]) -> "RunConfig":
        """The configuration that :meth:`to_json` wrote; fields left out take their defaults, and an
        unknown key is refused."""
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(obj) - known)
        if unknown:
            raise MetriplexError(
                f"unknown configuration key(s) {unknown}; known keys are {sorted(known)}."
            )
        return cls(**obj)


def _choice(value: str, allowed: tuple[str, ...], flag: str) -> str:
    head = option(value).kind
    if head not in allowed:
        raise MetriplexError(
            f"{flag} must be one of {', '.join(allowed)}; got {value!r}."
        )
    return head


def scheme_from_name(name: str, *, solver: str | None = None) -> AbstractScheme:
    """The scheme that ``--scheme`` calls ``name`` (a key of
    :data:`~metriplex.integrate.SCHEMES`), for an implicit one solved by the root finder that
    ``--solver`` calls ``solver`` (a key of :data:`~metriplex.integrate.ROOT_FINDERS`;
    default: the scheme's own default, ``auto``)."""
    if name not in SCHEMES:
        raise MetriplexError(
            f"unknown time-stepping scheme {name!r}; choose one of {sorted(SCHEMES)}."
        )
    cls = SCHEMES[name]
    if solver is None:
        return cls()
    if not issubclass(cls, AbstractImplicitScheme):
        implicit = ", ".join(k for k, c in SCHEMES.items()
                             if issubclass(c, AbstractImplicitScheme))
        raise MetriplexError(
            f"--solver applies to the implicit schemes ({implicit}); "
            f"{name!r} is explicit. Leave --solver out."
        )
    if solver not in ROOT_FINDERS:
        raise MetriplexError(
            f"--solver must be one of {', '.join(ROOT_FINDERS)}; got {solver!r}."
        )
    root_finder, _ = ROOT_FINDERS[solver]
    return cls(root_finder=root_finder())


def validate(config: RunConfig, n: int) -> None:
    """Check that every structure option fits data with ``n`` variables."""
    for flag, value in (("--energy", config.energy), ("--entropy", config.entropy),
                        ("--poisson", config.poisson), ("--friction", config.friction)):
        spelling = _spelling(value, flag)
        if spelling.given is not None:
            spelling.given(option(value).argument, n)  # its checks (a file: its matrix)
        elif spelling.check is not None:
            spelling.check(option(value).argument, n)
    check_entropy_left_still(_given(config.poisson, "--poisson", n),
                             _given(config.entropy, "--entropy", n),
                             f"--poisson {config.poisson} with --entropy {config.entropy}")
    if config.constant not in ("auto", "none"):
        _indices(config.constant, n, "--constant")
    _choice(config.degeneracy, DEGENERACY_MODES, "--degeneracy")
    if config.degeneracy == "exact" and option(config.poisson).kind == "lie-poisson" \
            and option(config.entropy).kind != "sum":
        raise MetriplexError(
            "--degeneracy exact builds a learned L with L grad S = 0, which a Lie-Poisson L "
            "(linear in the state) cannot be beside a learned S; got --poisson lie-poisson "
            f"with --entropy {config.entropy}. Give S as a sum of entropy variables "
            "(--entropy sum:I,J), use --degeneracy auto (the default) or soft (L grad S = 0 "
            "a penalty), or --poisson neural or casimir3 with --degeneracy exact."
        )
    _choice(config.degeneracy_at, DEGENERACY_POINTS, "--degeneracy-at")
    _choice(config.residual_metric, RESIDUAL_METRICS, "--residual-metric")
    _choice(config.jacobi, tuple(JACOBI_CHOICES), "--jacobi")
    if config.features not in ("none", *FEATURES):
        raise MetriplexError(
            f"--features must be 'none' or one of {sorted(FEATURES)}; got {config.features!r}."
        )
    if config.features != "none":
        try:
            FEATURES[config.features].check(n)
        except MetriplexError as e:
            raise MetriplexError(
                f"--features {config.features} does not fit these data: {e} Those features "
                f"are made for the system they are named after; leave --features out (none) "
                f"for other data.") from None
    _feature_blocks(config)
    if config.scheme is not None:
        scheme_from_name(config.scheme)
    if config.jacobi_samples is not None and config.jacobi_samples < 1:
        raise MetriplexError(
            f"--jacobi-samples must be >= 1 (pairs per batch that the Jacobi penalty sees); got "
            f"{config.jacobi_samples}. Leave it out to use the whole batch."
        )
    check_seed(config.seed)
    for name in FLOAT_FIELDS:
        v = getattr(config, name)
        if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float))
                              or not math.isfinite(v)):
            raise MetriplexError(
                f"--{name.replace('_', '-')} must be a finite number; got {v!r}."
            )
    if config.jacobi_probes < 1:
        raise MetriplexError(
            f"--jacobi-probes must be >= 1 (random probes per sample of the stochastic Jacobi "
            f"penalty); got {config.jacobi_probes}."
        )
    if config.checkpoint_every < 1:
        raise MetriplexError(
            f"--checkpoint-every must be >= 1 (validations between checkpoints); got "
            f"{config.checkpoint_every}."
        )
    if config.patience is not None and config.patience < 1:
        raise MetriplexError(f"--patience must be >= 1 evaluations; got {config.patience}.")
    if config.lr_cuts < 0:
        raise MetriplexError(f"--lr-cuts must be >= 0; got {config.lr_cuts}.")
    for name, meaning in (("lbfgs_steps", "the iterations of the L-BFGS finish"),
                          ("window_steps", "the steps of the training rollouts from data states"),
                          ("consecutive", "the consecutive pairs of each run in a training "
                                          "batch"),
                          ("average_steps", "the optimiser steps that the running average of "
                                            "the parameters spans")):
        expect_integer(getattr(config, name), least=0, what=f"--{name.replace('_', '-')}",
                       fix=f"It counts {meaning}; 0 turns it off.")
    if config.every is not None:
        expect_integer(config.every, least=1, what="--every",
                       fix="It counts the samples between the two states of a training pair; "
                           "1 trains on neighbouring samples (leave it out to choose it from "
                           "the data).")
    if config.starts is not None:
        expect_integer(config.starts, least=1, what="--starts",
                       fix="It counts the initialisations tried before the best is trained; "
                           "1 trains the first one only.")
    if config.repeats is not None:
        expect_integer(config.repeats, least=1, what="--repeats",
                       fix="It counts the trainings at most, each from another "
                           "initialisation while the best so far is poor; 1 trains once.")
    if not 0 <= config.input_noise < 1:
        raise MetriplexError(
            f"--input-noise must be in [0, 1) (a fraction of each variable's standard "
            f"deviation; 0 for none); got {config.input_noise}."
        )
    if config.schedule not in SCHEDULES:
        raise MetriplexError(
            f"--schedule must be one of {', '.join(SCHEDULES)}; got {config.schedule!r}. "
            "Example: --schedule plateau."
        )
    if config.activation not in ACTIVATIONS:
        raise MetriplexError(
            f"--activation must be one of {', '.join(sorted(ACTIVATIONS))} (smooth, as the "
            f"gradients of E and S need); got {config.activation!r}. Example: --activation "
            f"{ACTIVATION}."
        )
    if config.max_minutes is not None and not config.max_minutes > 0:
        raise MetriplexError(f"--max-minutes must be > 0; got {config.max_minutes}.")
    what = {"width": "units per hidden layer", "depth": "hidden layers",
            "steps": "the most optimiser steps", "batch_size": "pairs per optimiser step",
            "eval_every": "optimiser steps between validations"}
    for name, meaning in what.items():
        v = getattr(config, name)
        if v < 1:
            raise MetriplexError(
                f"--{name.replace('_', '-')} must be >= 1 ({meaning}); got {v}."
            )
    if not config.lr > 0:
        raise MetriplexError(f"--lr must be > 0; got {config.lr}.")
    if not config.weight_decay >= 0:
        raise MetriplexError(f"--weight-decay must be >= 0; got {config.weight_decay}.")
    if not 0 <= config.validation < 1:
        raise MetriplexError(f"--validation must lie in [0, 1); got {config.validation}.")
    for name in ("w_traj", "w_degeneracy_L", "w_degeneracy_M", "w_jacobi", "w_temperature"):
        if getattr(config, name) is not None and getattr(config, name) < 0:
            raise MetriplexError(f"--{name.replace('_', '-')} (a loss weight) must be >= 0; "
                                 f"got {getattr(config, name)}.")
    check_thermal_options(config)


#: The real-valued settings; each must be a finite number (``max_minutes`` may be left out).
FLOAT_FIELDS = ("w_traj", "w_degeneracy_L", "w_degeneracy_M", "w_jacobi", "w_temperature", "lr",
                "weight_decay", "validation", "max_minutes")

#: Seeds are the non-negative integers below this bound (what NumPy and JAX both accept).
SEED_BOUND = 2**32


def check_seed(seed: Any, option: str = "--seed") -> int:
    """A PRNG seed: an integer in ``[0, 2**32)``."""
    return expect_integer(seed, what=option, least=0, below=SEED_BOUND)


FEATURE_BLOCKS = ("energy", "entropy", "friction")

def _feature_blocks(config: RunConfig) -> tuple[str, ...]:
    blocks = tuple(b.strip() for b in config.features_for.split(",") if b.strip())
    bad = [b for b in blocks if b not in FEATURE_BLOCKS]
    if bad:
        hint = (" The entries of L are not invariant functions of the state, so invariant "
                "features do not apply to it." if "poisson" in bad else "")
        raise MetriplexError(
            f"--features-for lists the networks that see the features, from "
            f"{', '.join(FEATURE_BLOCKS)}; got {config.features_for!r}.{hint}"
        )
    if config.features == "none":
        return blocks
    values = {"energy": config.energy, "entropy": config.entropy, "friction": config.friction}
    for block in blocks:
        kind = option(values[block]).kind
        reads = STATE_READERS.get((block, kind))
        if reads is not None:
            raise MetriplexError(
                f"--{block} {kind} {reads}, not features; got --features {config.features} "
                f"--features-for {config.features_for}. Leave {block} out of --features-for.")
    return blocks


#: The learned blocks that read the state and cannot see ``--features``, and what they read.
STATE_READERS = {
    ("friction", "exchange"): "builds M from the energy's gradient by variable pairs, and its "
                              "rates read the state",
    ("energy", "local"): "reads each bond's own variables",
    ("friction", "local"): "reads each bond's own variables",
}


def _spelling(value: str, flag: str) -> Spelling:
    """The :class:`~metriplex.app._spellings.Spelling` of the structure option ``flag``'s
    ``value`` (refused, with the choices, where it has none)."""
    return SPELLINGS[flag][_choice(value, tuple(SPELLINGS[flag]), flag)]


#: The spellings of --poisson that learn L.
LEARNED_POISSON = tuple(k for k, v in SPELLINGS["--poisson"].items() if v.learned)


def _given(value: str, flag: str, n: int):
    spelling = _spelling(value, flag)
    return None if spelling.given is None else spelling.given(option(value).argument, n)


def _known_poisson(config: RunConfig, n: int):
    """The given Poisson bivector, or ``None`` when it is learned."""
    return _given(config.poisson, "--poisson", n)


def _known_friction(config: RunConfig, n: int):
    """The given friction matrix, or ``None`` when it is learned."""
    return _given(config.friction, "--friction", n)


def _known_entropy(config: RunConfig, n: int):
    """The given entropy, or ``None`` when it is learned."""
    return _given(config.entropy, "--entropy", n)


def preset(name: str, **overrides: Any) -> RunConfig:
    """The configuration of the preset ``name`` (:data:`PRESETS`), with the fields in ``overrides``
    replaced."""
    if name not in PRESETS:
        raise MetriplexError(f"unknown preset {name!r}; choose one of {sorted(PRESETS)}.")
    return RunConfig(**{**PRESETS[name], **overrides})

