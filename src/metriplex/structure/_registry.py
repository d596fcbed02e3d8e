"""Name <-> class registry so that model files can rebuild a model from its JSON header.

Library users choose behaviour by passing objects (``SkewMLPPoisson(...)``); the registry
exists only at the boundary (model files, command line), where configuration is text.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Callable, TypeVar

from .._errors import MetriplexError

if TYPE_CHECKING:
    import jax

_T = TypeVar("_T")
REGISTRY: dict[str, dict[str, type]] = {"potential": {}, "poisson": {}, "friction": {}}


def register(family: str, kind: str) -> Callable[[_T], _T]:
    def wrap(cls: _T) -> _T:
        REGISTRY[family][kind] = cls  # type: ignore[assignment]
        cls.kind = kind  # type: ignore[attr-defined]
        return cls

    return wrap


#: Kinds that model files written before a block was renamed still carry: the network blocks
#: were ``mlp`` in files, ``neural`` on the command line; both now say ``neural``.
RENAMED = {"mlp": "neural", "projected-mlp": "projected-neural"}


def from_spec(family: str, spec: dict[str, Any], n: int, *, key: jax.Array) -> Any:
    kind = RENAMED.get(spec.get("kind"), spec.get("kind"))
    table = REGISTRY[family]
    if kind not in table:
        raise MetriplexError(
            f"unknown {family} kind {kind!r} in model configuration; known kinds are "
            f"{sorted(table)}. The file may come from a newer metriplex: upgrade it."
        )
    return table[kind].from_spec(spec, n, key=key)


class NotSerialisable(MetriplexError):
    pass


def not_serialisable(obj: object) -> NotSerialisable:
    return NotSerialisable(
        f"{type(obj).__name__} wraps a Python function and cannot be written to a model file "
        "(model files never store code). Save the learned blocks only, or rebuild the known "
        "block in code after `load`."
    )


def network_kwargs(spec: dict[str, Any]) -> dict[str, Any]:
    """Constructor arguments shared by the network blocks, from their saved spec."""
    from ._mlp import ACTIVATION
    from .scaling import Scaling

    return {
        "width": spec["width"],
        "depth": spec["depth"],
        "activation": spec.get("activation", ACTIVATION),
        "scaling": Scaling.from_json(spec.get("scaling")),
    }
