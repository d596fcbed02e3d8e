"""A structure option's value, split once: ``--entropy sum:8,9`` is the kind ``sum`` with the
argument ``8,9``, ``--poisson canonical:4`` the kind ``canonical`` with ``4``, ``--friction
file:M.npy`` the kind ``file`` with ``M.npy``, and ``neural`` the kind ``neural`` with none.
Every reader of ``--energy``, ``--entropy``, ``--poisson`` and ``--friction`` goes through
:func:`option` (checking what the argument may be is :func:`metriplex.app.config.validate`'s).
``metriplex generate``'s ``--param NAME=VALUE`` are parsed here too (:func:`system_params`)."""

from __future__ import annotations

import typing
from typing import Any, NamedTuple

from .._errors import MetriplexError


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


def system_params(items: list[str] | None, config: Any) -> dict[str, Any]:
    """``--param NAME=VALUE`` as keyword arguments for a system whose configuration is
    ``config`` (a dataclass), each value parsed as its field's type: comma-separated numbers
    for a tuple, a number, a whole number, else the text (a name). Text that is not of its
    field's type, or names no field, is passed on as written, for the system to refuse with
    what it takes."""
    hints = typing.get_type_hints(type(config))
    params = {}
    for item in items or []:
        key, sep, value = item.partition("=")
        if not sep:
            raise MetriplexError(f"--param expects NAME=VALUE; got {item!r}.")
        key = key.replace("-", "_")
        params[key] = _param_value(value, hints.get(key))
    return params


def _param_value(text: str, hint: Any) -> Any:
    """One ``--param`` value as the type ``hint`` (see :func:`system_params`)."""
    try:
        if typing.get_origin(hint) is tuple:
            return tuple(float(v) for v in text.strip("()[] ").split(",") if v.strip())
        if hint is float:
            return float(text)
        if hint is int:  # a fraction is passed on as a number, which the system refuses
            number = float(text)
            return int(number) if number.is_integer() else number
    except ValueError:
        pass
    return text
