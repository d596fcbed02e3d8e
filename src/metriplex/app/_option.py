"""A structure option's value, split once: ``--entropy sum:8,9`` is the kind ``sum`` with the
argument ``8,9``, ``--poisson canonical:4`` the kind ``canonical`` with ``4``, ``--friction
file:M.npy`` the kind ``file`` with ``M.npy``, and ``neural`` the kind ``neural`` with none.
Every reader of ``--energy``, ``--entropy``, ``--poisson`` and ``--friction`` goes through
:func:`option` (checking what the argument may be is :func:`metriplex.app.config.validate`'s).
``metriplex generate``'s ``--param NAME=VALUE`` are parsed here too (:func:`system_params`)."""

from __future__ import annotations

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


def system_params(items: list[str] | None) -> dict[str, Any]:
    """``--param NAME=VALUE`` as keyword arguments: comma-separated numbers as a tuple of
    floats, a number as an int or a float, anything else as the text (a name; the system
    checks each against its field and says what it takes)."""
    params = {}
    for item in items or []:
        key, sep, value = item.partition("=")
        if not sep:
            raise MetriplexError(f"--param expects NAME=VALUE; got {item!r}.")
        params[key.replace("-", "_")] = _param_value(value)
    return params


def _param_value(text: str) -> Any:
    """One ``--param`` value: see :func:`system_params`."""
    if "," in text:
        try:
            return tuple(float(v) for v in text.strip("()[] ").split(",") if v.strip())
        except ValueError:
            return text
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text
