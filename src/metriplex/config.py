"""Run configuration: what is learned and what is given, as plain JSON-able settings.

The command line and the experiment presets describe a run with a :class:`RunConfig`;
:func:`build_model` and :func:`build_loss` turn it into the objects the library works with
(``GenericModel``, ``Loss``). Library code itself takes objects, never these strings.
"""

from __future__ import annotations

import dataclasses
import json
import math
import re
from pathlib import Path
from typing import Any, Sequence

import jax.random as jr
import numpy as np

from ._errors import MetriplexError
from ._model import GenericModel
from .data import Trajectories, Units
from .integrate import scheme_from_name
from .losses import (
    DEGENERACY_POINTS,
    FrictionDegeneracy,
    JacobiPenalty,
    Loss,
    PoissonDegeneracy,
    SchemeResidual,
)
from .structure import _registry
from .structure.constant import ConstantFriction, ConstantPoisson
from .structure.friction import CholeskyFriction, ProjectedCholeskyFriction, ZeroFriction
from .structure.lie_poisson import LiePoisson
from .structure.poisson import CanonicalPoisson, ZeroPoisson
from .structure.potential import FeatureMap, MLPPotential, SumOf, ZeroPotential
from .train import Plateau

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
    jacobi: str = "none"
    jacobi_probes: int = 1
    jacobi_samples: int | None = None
    features: str = "none"
    features_for: str = "energy,entropy"
    scheme: str = "cn"
    w_traj: float = 1.0
    w_degeneracy_L: float = 10.0
    w_degeneracy_M: float = 10.0
    w_jacobi: float = 1.0
    quadratic: bool = False
    width: int = 64
    depth: int = 2
    activation: str = "softplus"
    lr: float = 1e-2
    weight_decay: float = 0.0
    steps: int = 30_000
    batch_size: int = 256
    validation: float = 0.2
    eval_every: int = 100
    patience: int | None = None
    lr_cuts: int = 3
    schedule: str = "plateau"
    max_minutes: float | None = None
    seed: int = 0
    float64: bool = False
    checkpoint_every: int = 10
    data_parallel: bool = False
    lbfgs_steps: int = 0
    input_noise: float = 0.0

    def to_json(self) -> dict[str, Any]:
        return dataclasses.asdict(self)

    @classmethod
    def from_json(cls, obj: dict[str, Any]) -> "RunConfig":
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(obj) - known)
        if unknown:
            raise MetriplexError(
                f"unknown configuration key(s) {unknown}; known keys are {sorted(known)}."
            )
        return cls(**obj)


def _indices(text: str, n: int, option: str) -> tuple[int, ...]:
    try:
        idx = tuple(int(v) for v in text.split(",") if v.strip() != "")
    except ValueError:
        raise MetriplexError(
            f"{option} expects comma-separated integer indices such as `sum:8,9`; got {text!r}."
        ) from None
    bad = [i for i in idx if not 0 <= i < n]
    if not idx or bad:
        raise MetriplexError(
            f"{option} indices must lie in [0, {n - 1}] for data with {n} variables; got "
            f"{list(idx)}. Count state columns from 0 (after `trajectory` and `t`)."
        )
    return idx


# -- trajectory ids: --trajectories, --validation-ids, --split -------------------------------

#: How ``--trajectories`` and ``--validation-ids`` are written.
IDS_SYNTAX = "a comma list of trajectory ids and LO-HI ranges, such as 0,3,5-9"

_ID_ITEM = re.compile(r"^\s*([0-9]+)\s*(?:-\s*([0-9]+)\s*)?$")
_ID_BOUND = 2**62


@dataclasses.dataclass(frozen=True)
class TrajectoryIds:
    """A set of trajectory ids, kept as sorted, disjoint inclusive ranges (so ``0-999999999``
    costs nothing until it meets the data), and ``source``: how it was given, for messages."""

    ranges: tuple[tuple[int, int], ...]
    source: str

    @classmethod
    def of(cls, ids, source: str) -> "TrajectoryIds":
        """From integer ids (any order, repeats allowed)."""
        ranges: list[list[int]] = []
        for i in sorted({int(i) for i in ids}):
            if ranges and i == ranges[-1][1] + 1:
                ranges[-1][1] = i
            else:
                ranges.append([i, i])
        return cls(tuple((a, b) for a, b in ranges), source)

    def __len__(self) -> int:
        return sum(b - a + 1 for a, b in self.ranges)

    def union(self, other: "TrajectoryIds", source: str) -> "TrajectoryIds":
        return _merged(self.ranges + other.ranges, source)

    def common(self, other: "TrajectoryIds") -> "TrajectoryIds":
        """The ids in both sets."""
        out = [(max(a, c), min(b, d)) for a, b in self.ranges for c, d in other.ranges
               if max(a, c) <= min(b, d)]
        return _merged(tuple(out), f"{self.source} and {other.source}")

    def pick(self, available, where: str) -> np.ndarray:
        """The ids of ``available`` (the data's ids) in this set; every id of the set must be
        there, else a message names the first missing ones, ``where`` (the data) and its ids."""
        available = np.unique(np.asarray(available, dtype=np.int64))
        keep = np.zeros(len(available), bool)
        missing: list[int] = []
        n_missing = 0
        for lo, hi in self.ranges:
            a, b = np.searchsorted(available, [lo, hi + 1])
            keep[a:b] = True
            inside = available[a:b]
            if len(inside) == hi - lo + 1:
                continue
            n_missing += hi - lo + 1 - len(inside)
            v, j = lo, 0  # the first missing ids of this range: at most len(inside) + 5 looks
            while v <= hi and len(missing) < 5:
                if j < len(inside) and inside[j] == v:
                    j += 1
                else:
                    missing.append(v)
                v += 1
        if n_missing:
            shown = ", ".join(map(str, missing)) + (", ..." if n_missing > len(missing) else "")
            raise MetriplexError(
                f"{self.source} names {n_missing} trajectory id{'s' * (n_missing > 1)} that "
                f"{'are' if n_missing > 1 else 'is'} not in {where} ({shown}); the ids there "
                f"are {format_ids(available)} ({len(available)} trajectories). Choose ids among "
                "those."
            )
        return available[keep]


def _merged(ranges, source: str) -> TrajectoryIds:
    out: list[list[int]] = []
    for a, b in sorted(ranges):
        if out and a <= out[-1][1] + 1:
            out[-1][1] = max(out[-1][1], b)
        else:
            out.append([a, b])
    return TrajectoryIds(tuple((a, b) for a, b in out), source)


def format_ids(ids, limit: int = 8) -> str:
    """Ids (or a :class:`TrajectoryIds`) in the ``--trajectories`` syntax (``0-3,7,9-12``);
    past ``limit`` pieces the rest is elided, with a count."""
    ranges = ids.ranges if isinstance(ids, TrajectoryIds) else TrajectoryIds.of(
        np.asarray(ids).reshape(-1).tolist(), "").ranges
    if not ranges:
        return "none"
    pieces = [f"{a}" if a == b else f"{a}-{b}" for a, b in ranges]
    if len(pieces) > limit:
        count = sum(b - a + 1 for a, b in ranges)
        pieces = pieces[: limit - 1] + ["...", pieces[-1]]
        return ",".join(pieces) + f" ({count} ids)"
    return ",".join(pieces)


def parse_ids(text: str, option: str) -> TrajectoryIds:
    """``--trajectories``/``--validation-ids`` text (``0,3,5-9``) as a :class:`TrajectoryIds`."""
    source = f"{option} {text!r}"
    if not str(text).strip():
        raise MetriplexError(
            f"{option} expects {IDS_SYNTAX}; got an empty value. Give at least one id."
        )
    ranges = []
    for item in str(text).split(","):
        m = _ID_ITEM.match(item)
        if m is None:
            what = ("an empty item (two commas in a row, or a comma at an end)"
                    if not item.strip() else f"{item.strip()!r} is neither an id nor a range LO-HI"
                    + (" (ids are integers >= 0)" if item.strip().startswith("-") else ""))
            raise MetriplexError(f"{option} expects {IDS_SYNTAX}; got {text!r}, in which {what}.")
        lo = int(m[1])
        hi = lo if m[2] is None else int(m[2])
        if max(lo, hi) >= _ID_BOUND:
            raise MetriplexError(
                f"{option}: the id {max(lo, hi)} in {text!r} is too large (trajectory ids are "
                f"integers below 2**62); choose ids among those of the data."
            )
        if hi < lo:
            raise MetriplexError(
                f"{option}: the range {item.strip()!r} in {text!r} runs backwards; write it from "
                f"low to high ({hi}-{lo})."
            )
        ranges.append((lo, hi))
    return _merged(tuple(ranges), source)


def _split_list(value, key: str, where: str) -> TrajectoryIds:
    source = f"the {key!r} list of {where}"
    if isinstance(value, str):
        return parse_ids(value, source) if value.strip() else TrajectoryIds((), source)
    if not isinstance(value, list) or not all(
            isinstance(v, int) and not isinstance(v, bool) and abs(v) < _ID_BOUND
            for v in value):
        raise MetriplexError(
            f"{source} must be a list of integer trajectory ids (or a string such as "
            f"\"0,3,5-9\"); got {json.dumps(value)[:80]}."
        )
    return TrajectoryIds.of(value, source)


def read_split(path, option: str = "--split") -> tuple[TrajectoryIds, TrajectoryIds]:
    """``(train, validation)`` ids from a split file: a JSON object with lists ``train`` and
    ``validation`` (optionally ``test``, which must not overlap them), or a run folder (or its
    ``config.json``), whose ``train_trajectories`` and ``validation_trajectories`` are reused
    exactly. ``validation`` may be empty (no validation); ``train`` may not."""
    p = Path(path)
    if p.is_dir():
        if not (p / "config.json").is_file():
            raise MetriplexError(
                f"{option} {str(p)!r} is a folder without config.json; give a split file (JSON "
                "with \"train\" and \"validation\" lists of ids) or a run folder of `metriplex "
                "train`."
            )
        p = p / "config.json"
    where = f"{option} file {str(p)!r}"
    if not p.is_file():
        raise MetriplexError(
            f"{option} file {str(p)!r} does not exist; give a JSON file with \"train\" and "
            "\"validation\" lists of trajectory ids, or a run folder to reuse its split."
        )
    try:
        obj = json.loads(p.read_text(encoding="utf-8"))
    except (ValueError, UnicodeDecodeError) as e:
        raise MetriplexError(
            f"{where} is not valid JSON ({e}); write it as {{\"train\": [0, 1, 2], "
            "\"validation\": [3]}."
        ) from None
    if not isinstance(obj, dict):
        raise MetriplexError(
            f"{where} must hold a JSON object with \"train\" and \"validation\" lists of ids; "
            f"it holds a {type(obj).__name__}."
        )
    if "train_trajectories" in obj:  # a run folder's config.json
        names = ("train_trajectories", "validation_trajectories")
        train = _split_list(obj["train_trajectories"], names[0], where)
        valid = _split_list(obj.get("validation_trajectories", []), names[1], where)
        if len(train) == 1 and train.ranges == valid.ranges:
            # One trajectory whose last samples validated: reuse it, split by the fraction.
            return train, None  # type: ignore[return-value]
    else:
        keys = ("train", "validation", "test")
        unknown = sorted(set(obj) - set(keys))
        if "train" not in obj or unknown:
            found = ", ".join(sorted(obj)) or "no keys"
            raise MetriplexError(
                f"{where} must hold the lists \"train\" and \"validation\" (optionally "
                f"\"test\"), or be a run folder's config.json; found {found}. Rename the keys."
            )
        names = ("train", "validation")
        train = _split_list(obj["train"], "train", where)
        valid = _split_list(obj.get("validation", []), "validation", where)
        if "test" in obj:
            test = _split_list(obj["test"], "test", where)
            for key, other in zip(names, (train, valid)):
                _disjoint(other, test, key, "test", where, "a test trajectory must never train "
                          "or validate")
    if not len(train):
        raise MetriplexError(
            f"{where}: the {names[0]!r} list is empty; at least one trajectory must train."
        )
    _disjoint(train, valid, *names, where, "a trajectory either trains or validates")
    return train, valid


def _disjoint(a: TrajectoryIds, b: TrajectoryIds, key_a: str, key_b: str, where: str,
              rule: str) -> None:
    both = a.common(b)
    if len(both):
        raise MetriplexError(
            f"{where}: the {key_a!r} and {key_b!r} lists share {len(both)} trajectory "
            f"id{'s' * (len(both) > 1)} ({format_ids(both)}); {rule}. Remove "
            f"{'them' if len(both) > 1 else 'it'} from one list."
        )


def choose_trajectories(
    data_ids, where: str, selection: tuple[TrajectoryIds | None, TrajectoryIds | None],
) -> tuple[np.ndarray | None, np.ndarray | None]:
    """The ids that a :func:`check_selection` ``selection`` picks from the data's ids (``where``
    names the data in messages): ``(trajectories, validation_ids)`` for
    :func:`metriplex.runs.train_run`, each ``None`` when not chosen (all trajectories; the
    ``--validation`` fraction of them). An empty ``validation_ids``: no validation."""
    chosen, held = selection
    selected = None if chosen is None else chosen.pick(data_ids, where)
    if held is None:
        return selected, None
    if selected is None:
        pool, pool_name = np.unique(np.asarray(data_ids, dtype=np.int64)), where
    else:
        pool, pool_name = selected, f"the selection of {chosen.source}"
    valid = held.pick(pool, pool_name)
    if len(valid) == len(pool):
        raise MetriplexError(
            f"{held.source} takes every selected trajectory ({format_ids(pool)}) for "
            "validation, which leaves none to train on; leave at least one out of it."
        )
    return selected, valid


def check_selection(*, trajectories=None, validation_ids=None, split=None, validation=None):
    """The selection options parsed and checked against each other, before any data are
    read: ``(selected, validation)`` :class:`TrajectoryIds`, each ``None`` when not given."""
    if split is not None:
        given = [o for o, v in (("--trajectories", trajectories),
                                ("--validation-ids", validation_ids),
                                ("--validation", validation)) if v is not None]
        if given:
            raise MetriplexError(
                f"--split {str(split)!r} chooses the training and validation trajectories, and "
                f"so does {' and '.join(given)}; got both. Give --split alone, or drop it."
            )
        train, valid = read_split(split)
        if valid is None:  # a run that validated on the last samples of its one trajectory
            return train, None
        return train.union(valid, f"--split {str(split)!r}"), valid
    chosen = None if trajectories is None else parse_ids(trajectories, "--trajectories")
    held = None if validation_ids is None else parse_ids(validation_ids, "--validation-ids")
    if held is not None and validation is not None:
        raise MetriplexError(
            f"--validation-ids {validation_ids!r} names the validation trajectories and "
            f"--validation {validation} takes a random fraction of them; got both. Give one of "
            "them."
        )
    return chosen, held


def _choice(value: str, allowed: tuple[str, ...], option: str) -> str:
    head = value.split(":", 1)[0]
    if head not in allowed:
        raise MetriplexError(
            f"{option} must be one of {', '.join(allowed)}; got {value!r}."
        )
    return head


def validate(config: RunConfig, n: int) -> None:
    """Check that every structure option fits data with ``n`` variables."""
    _choice(config.energy, ("neural",), "--energy")
    head = _choice(config.entropy, ("neural", "sum", "zero"), "--entropy")
    if head == "sum":
        _indices(config.entropy.partition(":")[2], n, "--entropy sum:I,J,...")
    head = _choice(config.poisson, POISSON_CHOICES, "--poisson")
    if head == "file":
        _known_poisson(config, n)
    if head == "canonical":
        try:
            K = int(config.poisson.partition(":")[2])
        except ValueError:
            raise MetriplexError(
                f"--poisson canonical:K needs an integer K (the number of position/momentum "
                f"pairs); got {config.poisson!r}."
            ) from None
        if n < 2:
            raise MetriplexError(
                f"--poisson canonical:{K} needs at least one position and one momentum (n >= 2 "
                f"variables), but the data have n={n}. Use --poisson zero (no reversible part) "
                "or give data with more variables."
            )
        if K < 1:
            raise MetriplexError(
                f"--poisson canonical:K needs K >= 1 position/momentum pairs; got K={K}. Use "
                f"canonical:K with 1 <= K <= {n // 2} for these n={n} variables."
            )
        if 2 * K > n:
            raise MetriplexError(
                f"--poisson canonical:{K} needs 2K <= n (K positions then K momenta), but the data "
                f"have n={n} variables. Use canonical:K with 1 <= K <= {n // 2}."
            )
    if head == "casimir3" and n != 3:
        raise MetriplexError(f"--poisson casimir3 is for 3 state variables; the data have {n}.")
    if _choice(config.friction, FRICTION_CHOICES, "--friction") == "file":
        _known_friction(config, n)
    _choice(config.degeneracy, DEGENERACY_MODES, "--degeneracy")
    _choice(config.degeneracy_at, DEGENERACY_POINTS, "--degeneracy-at")
    _choice(config.jacobi, ("none", "exact", "stochastic"), "--jacobi")
    if config.features not in ("none", *FEATURES):
        raise MetriplexError(
            f"--features must be 'none' or one of {sorted(FEATURES)}; got {config.features!r}."
        )
    if config.features != "none":
        FEATURES[config.features].check(n)
    _feature_blocks(config)
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
    if config.lbfgs_steps < 0:
        raise MetriplexError(
            f"--lbfgs-steps must be >= 0 (iterations of the L-BFGS finish; 0 for none); got "
            f"{config.lbfgs_steps}."
        )
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
    for name in ("w_traj", "w_degeneracy_L", "w_degeneracy_M", "w_jacobi"):
        if getattr(config, name) < 0:
            raise MetriplexError(f"loss weight {name} must be >= 0; got {getattr(config, name)}.")


#: The real-valued settings; each must be a finite number (``max_minutes`` may be left out).
FLOAT_FIELDS = ("w_traj", "w_degeneracy_L", "w_degeneracy_M", "w_jacobi", "lr", "weight_decay",
                "validation", "max_minutes")

#: Seeds are the non-negative integers below this bound (what NumPy and JAX both accept).
SEED_BOUND = 2**32


def check_seed(seed, option: str = "--seed") -> int:
    """A PRNG seed: an integer in ``[0, 2**32)``."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) \
            or not 0 <= seed < SEED_BOUND:
        raise MetriplexError(
            f"{option} must be an integer from 0 to {SEED_BOUND - 1}; got {seed!r}."
        )
    return int(seed)


FEATURE_BLOCKS = ("energy", "entropy", "friction")

#: ``--degeneracy``: ``auto`` makes a learned L exactly degenerate when S is given (then
#: L grad S = 0 costs one projection with a known gradient, and the learned entropy can never
#: decrease in a rollout) and keeps the other conditions as penalties; ``exact`` makes every
#: learned L and M exactly degenerate; ``soft`` uses penalties only.
DEGENERACY_MODES = ("auto", "soft", "exact")


def exact_blocks(config: RunConfig) -> tuple[bool, bool]:
    """Whether the learned ``(L, M)`` are built exactly degenerate (see ``DEGENERACY_MODES``)."""
    if config.degeneracy == "exact":
        return True, True
    if config.degeneracy == "soft":
        return False, False
    return config.poisson == "neural" and config.entropy.startswith("sum"), False


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
    return blocks


#: ``--poisson`` and ``--friction`` choices (``file:PATH`` reads a constant matrix).
POISSON_CHOICES = ("neural", "canonical", "zero", "casimir3", "lie-poisson", "file")
FRICTION_CHOICES = ("neural", "zero", "file")
LEARNED_POISSON = ("neural", "casimir3", "lie-poisson")


def read_matrix(path: str, key: str, n: int) -> np.ndarray:
    """A constant ``n x n`` operator from ``.npy`` (the array), ``.npz`` or ``.mat`` (the
    variable ``key``, i.e. ``L`` or ``M``, as published GENERIC datasets store them)."""
    from pathlib import Path

    p = Path(path)
    option = "--poisson" if key == "L" else "--friction"
    if not p.is_file():
        raise MetriplexError(
            f"{option} file:PATH needs an existing file; {str(p)!r} does not exist. Give the "
            f"path of a .npy, .npz or .mat file holding the {n}x{n} matrix {key}."
        )
    try:
        if p.suffix == ".npy":
            a = np.load(p, allow_pickle=False)
        elif p.suffix == ".npz":
            with np.load(p, allow_pickle=False) as z:
                names = list(z.files)
                if key not in names and len(names) != 1:
                    raise MetriplexError(
                        f"{str(p)!r} holds the arrays {names}; name the matrix {key!r} or store "
                        "it alone."
                    )
                a = z[key] if key in names else z[names[0]]
        elif p.suffix == ".mat":
            import scipy.io

            scope = scipy.io.loadmat(p)
            if key not in scope:
                found = sorted(k for k in scope if not k.startswith("__"))
                raise MetriplexError(
                    f"{str(p)!r} has no variable {key!r} (found {found}); store the matrix as "
                    f"{key}."
                )
            a = scope[key]
        else:
            raise MetriplexError(
                f"{option} file:PATH reads .npy, .npz or .mat files; got {p.suffix or 'no'} "
                "suffix. Save the matrix with numpy.save."
            )
    except (OSError, ValueError, NotImplementedError) as err:
        raise MetriplexError(f"cannot read the matrix {key} from {str(p)!r}: {err}.") from None
    a = np.asarray(a, dtype=np.float64)
    if a.shape != (n, n):
        raise MetriplexError(
            f"the matrix {key} in {str(p)!r} has shape {a.shape}; the data have {n} variables, "
            f"so it must be {n}x{n}."
        )
    return a


def _known_poisson(config: RunConfig, n: int):
    """The given Poisson bivector, or ``None`` when it is learned."""
    if config.poisson in LEARNED_POISSON:
        return None
    if config.poisson == "zero":
        return ZeroPoisson(n)
    if config.poisson.startswith("file:"):
        return ConstantPoisson(read_matrix(config.poisson.partition(":")[2], "L", n))
    return CanonicalPoisson(n, int(config.poisson.partition(":")[2]))


def _known_friction(config: RunConfig, n: int):
    """The given friction matrix, or ``None`` when it is learned."""
    if config.friction == "neural":
        return None
    if config.friction == "zero":
        return ZeroFriction(n)
    return ConstantFriction(read_matrix(config.friction.partition(":")[2], "M", n))


def _known_entropy(config: RunConfig, n: int):
    """The given entropy, or ``None`` when it is learned."""
    if config.entropy == "neural":
        return None
    if config.entropy == "zero":
        return ZeroPotential()
    return SumOf(_indices(config.entropy.partition(":")[2], n, "--entropy"))


def units_for(config: RunConfig, data: Trajectories) -> Units:
    """The data's :class:`~metriplex.data.Units` for the blocks that ``config`` gives."""
    n = data.n
    return Units.from_data(data, poisson=_known_poisson(config, n),
                           entropy=_known_entropy(config, n),
                           friction=_known_friction(config, n))


def build_model(config: RunConfig, data: Trajectories, *, key,
                units: Units | None = None) -> GenericModel:
    """The untrained model that ``config`` describes, in the natural ``units`` of ``data``
    (default :func:`units_for`): networks see standardised states, and their outputs are scaled
    so that an untrained network gives rates of the data's order, whatever the units."""
    n = data.n
    validate(config, n)
    units = units_for(config, data) if units is None else units
    x = data.x
    kE, kS, kL, kM = jr.split(key, 4)
    net = dict(width=config.width, depth=config.depth, activation=config.activation)
    features = FEATURES.get(config.features)
    blocks = _feature_blocks(config)
    feats = {b: features if b in blocks else None for b in FEATURE_BLOCKS}
    energy = MLPPotential(n, features=feats["energy"], data=x, output_scale=units.energy,
                          quadratic=bool(config.quadratic), key=kE, **net)
    entropy = _known_entropy(config, n)
    if entropy is None:
        entropy = MLPPotential(n, features=feats["entropy"], data=x,
                               output_scale=units.entropy, quadratic=bool(config.quadratic),
                               key=kS, **net)
    poisson_scaling = units.poisson_scaling()
    friction_scaling = units.friction_scaling()
    exact_L, exact_M = exact_blocks(config)
    poisson = _known_poisson(config, n)
    if config.poisson == "neural":
        spec = {"kind": "projected-mlp" if exact_L else "mlp", **net,
                "scaling": poisson_scaling.to_json()}
        poisson = _registry.from_spec("poisson", spec, n, key=kL)
    elif config.poisson == "casimir3":
        spec = {"kind": "casimir3", **net, "scaling": poisson_scaling.to_json()}
        poisson = _registry.from_spec("poisson", spec, n, key=kL)
    elif config.poisson == "lie-poisson":
        poisson = LiePoisson(n, scaling=poisson_scaling, key=kL)
    if config.friction == "neural":
        cls = ProjectedCholeskyFriction if exact_M else CholeskyFriction
        friction = cls(n, **net, scaling=friction_scaling, features=feats["friction"], data=x,
                       key=kM)
    else:
        friction = _known_friction(config, n)
    return GenericModel(energy, entropy, poisson, friction)


#: Learning-rate schedules by name: what ``--schedule`` means.
SCHEDULES = {
    "plateau": "cut the rate when the validation loss stops improving, stop after --lr-cuts "
               "cuts; --steps is a cap (default)",
    "cosine": "exactly --steps steps, the rate decayed by a cosine to 1%",
}


def stopping_for(config: RunConfig) -> Plateau | None:
    """The ``stopping`` argument of :func:`~metriplex.fit` that ``config.schedule`` names
    (``None``: exactly ``config.steps`` steps of a cosine schedule, no early stop)."""
    if config.schedule != "plateau":
        return None
    if config.patience is None:
        return Plateau(cuts=config.lr_cuts)
    return Plateau(patience=config.patience, cuts=config.lr_cuts)


def build_loss(config: RunConfig, units: Units | None = None) -> Loss:
    r"""Scheme residual plus the penalties that the structure needs (none where exact).

    The trainer measures residuals in units of the data's rates (:attr:`Units.rate`). With
    ``units``, the penalties are measured in the same dimensionless units as the residual
    (:math:`L\nabla S` scaled by :math:`\sigma_E/\sigma_S`, :math:`M\nabla E` by
    :math:`\sigma_S/\sigma_E`, the Jacobi tensor by :math:`\sigma_E^2/\tau`), so a weight
    means the same on any data.
    """
    e, s, tau = (1.0, 1.0, 1.0) if units is None else (units.energy, units.entropy, units.time)
    loss = config.w_traj * SchemeResidual(scheme_from_name(config.scheme))
    exact_L, exact_M = exact_blocks(config)
    learned_L = config.poisson in LEARNED_POISSON
    if not exact_L and learned_L and config.entropy != "zero" and config.w_degeneracy_L > 0:
        loss = loss + config.w_degeneracy_L * (e / s) ** 2 * PoissonDegeneracy(
            config.degeneracy_at)
    if not exact_M and config.friction == "neural" and config.w_degeneracy_M > 0:
        loss = loss + config.w_degeneracy_M * (s / e) ** 2 * FrictionDegeneracy(
            config.degeneracy_at)
    if config.jacobi != "none" and config.poisson in ("neural", "lie-poisson") \
            and config.w_jacobi > 0:
        loss = loss + config.w_jacobi * (e**4 / tau**2) * JacobiPenalty(
            config.jacobi, probes=config.jacobi_probes, samples=config.jacobi_samples
        )
    return loss


# Adam at 1e-2 (cosine-decayed, see train.default_optimizer) with batches of 256 pairs: a sweep
# on the pendulum and gas data reached 3-5x lower validation residuals in the same wall time
# than 2e-3 with batches of 512 (docs/experiments.md). The pendulum presets train and roll out
# with the discrete-gradient scheme, which conserves the learned energy exactly.
PRESETS: dict[str, dict[str, Any]] = {
    "rigid-body": dict(
        energy="neural", entropy="zero", poisson="neural", friction="zero", jacobi="exact",
        w_jacobi=1.0, width=64, depth=2, lr=1e-2, batch_size=256,
    ),
    "pendulum-energetic": dict(
        energy="neural", entropy="sum:8,9", poisson="canonical:4", friction="neural",
        features="pendulum", features_for="energy,friction", width=64, depth=2, lr=1e-2,
        batch_size=256, degeneracy_at="midpoints",
        scheme="discrete-gradient",
    ),
    "pendulum-temperature": dict(
        energy="neural", entropy="neural", poisson="neural", friction="neural",
        jacobi="stochastic", jacobi_probes=2, features="pendulum", width=64, depth=2, lr=1e-2,
        batch_size=256, scheme="discrete-gradient", degeneracy_at="midpoints",
    ),
    # w_degeneracy_M = 1, not 10: early in training any M != 0 violates M grad E = 0 for the
    # still-wrong E, and a strong penalty holds M near 0 while E is learned (gas, 10 000 steps,
    # test error: weight 100 -> 0.34, 10 -> 0.085, 1 -> 0.043, 0.1 -> 0.013; 30 000 steps,
    # weight 1 -> 0.012 with a 10x smaller degeneracy residual than weight 0.1).
    # schedule "cosine": with the current units the fixed 30 000-step cosine schedule reaches
    # test error 2.6e-2, the plateau schedule (evaluations every 600 steps) 3.5e-2 at the same
    # cap (1.2e-2 was reached before losses were measured in the data's units).
    "gas-containers": dict(
        energy="neural", entropy="sum:2,3", poisson="canonical:1", friction="neural",
        width=64, depth=2, lr=1e-2, batch_size=256, w_degeneracy_M=1.0, schedule="cosine",
    ),
}


def preset(name: str, **overrides) -> RunConfig:
    if name not in PRESETS:
        raise MetriplexError(f"unknown preset {name!r}; choose one of {sorted(PRESETS)}.")
    return RunConfig(**{**PRESETS[name], **overrides})

