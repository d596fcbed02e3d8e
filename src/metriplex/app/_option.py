"""A structure option's value, split once: ``--entropy sum:8,9`` is the kind ``sum`` with the
argument ``8,9``, ``--poisson canonical:4`` the kind ``canonical`` with ``4``, ``--friction
file:M.npy`` the kind ``file`` with ``M.npy``, and ``neural`` the kind ``neural`` with none.
Every reader of ``--energy``, ``--entropy``, ``--poisson`` and ``--friction`` goes through
:func:`option` (checking what the argument may be is :func:`metriplex.app.config.validate`'s)."""

from __future__ import annotations

from typing import NamedTuple


class Option(NamedTuple):
    """``kind`` (before the first colon) and ``argument`` (after it; ``""`` if none)."""

    kind: str
    argument: str


def option(value: str) -> Option:
    """The :class:`Option` that ``value`` (e.g. ``"sum:8,9"``) spells."""
    kind, _, argument = value.partition(":")
    return Option(kind, argument)


def entropy_variables(entropy: str) -> tuple[int, ...]:
    """The indices of ``--entropy sum:I,J,...``; ``()`` for another kind (checked against the
    data by :func:`metriplex.app.config.validate`)."""
    kind, argument = option(entropy)
    if kind != "sum":
        return ()
    return tuple(int(v) for v in argument.split(",") if v.strip())
