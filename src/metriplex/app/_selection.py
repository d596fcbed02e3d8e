"""Which trajectories train, validate and test: ``--trajectories``, ``--validation-ids`` and
``--split`` of the command line, parsed once into :class:`TrajectoryIds` and checked against
the data's ids before any work starts.
"""

from __future__ import annotations

import dataclasses
import json
import os
import re
from pathlib import Path
from typing import TYPE_CHECKING, Iterable

import numpy as np

from .._errors import MetriplexError

if TYPE_CHECKING:
    from numpy.typing import ArrayLike


#: How ``--trajectories`` and ``--validation-ids`` are written.
IDS_SYNTAX = "a comma list of trajectory ids and LO-HI ranges, such as 0,3,5-9"

# An id or a range LO-HI; ids may be negative (-3, -5--2, -1-4), as the data files allow.
_ID_ITEM = re.compile(r"^\s*(-?[0-9]+)\s*(?:-\s*(-?[0-9]+)\s*)?$")
_ID_BOUND = 2**62


@dataclasses.dataclass(frozen=True)
class TrajectoryIds:
    """A set of trajectory ids, kept as sorted, disjoint inclusive ranges (so ``0-999999999``
    costs nothing until it meets the data), and ``source``: how it was given, for messages."""

    ranges: tuple[tuple[int, int], ...]
    source: str

    @classmethod
    def of(cls, ids: Iterable[int], source: str) -> "TrajectoryIds":
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

    def pick(self, available: ArrayLike, where: str) -> np.ndarray:
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


def format_ids(ids: TrajectoryIds | ArrayLike, limit: int = 8) -> str:
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
                    if not item.strip()
                    else f"{item.strip()!r} is neither an id nor a range LO-HI")
            raise MetriplexError(f"{option} expects {IDS_SYNTAX}; got {text!r}, in which {what}.")
        lo = int(m[1])
        hi = lo if m[2] is None else int(m[2])
        if max(abs(lo), abs(hi)) >= _ID_BOUND:
            raise MetriplexError(
                f"{option}: the id {max(lo, hi, key=abs)} in {text!r} is too large (trajectory "
                f"ids are integers of magnitude below 2**62); choose ids among those of the data."
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


def read_split(path: str | os.PathLike,
               option: str = "--split") -> tuple[TrajectoryIds, TrajectoryIds]:
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
    data_ids: ArrayLike, where: str, selection: tuple[TrajectoryIds | None, TrajectoryIds | None],
) -> tuple[np.ndarray | None, np.ndarray | None]:
    """The ids that a :func:`check_selection` ``selection`` picks from the data's ids (``where``
    names the data in messages): ``(trajectories, validation_ids)`` for
    :func:`metriplex.app.runs.train_run`, each ``None`` when not chosen (all trajectories; the
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


def check_selection(*, trajectories: str | None = None, validation_ids: str | None = None,
                    split: str | os.PathLike | None = None, validation: float | None = None,
                    ) -> tuple[TrajectoryIds | None, TrajectoryIds | None]:
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
