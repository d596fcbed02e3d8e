"""What every ground-truth system offers: its model, variable names, sampling and settings,
and what the systems share to build them: :func:`analytic_model` (a model from analytic
functions of the state and known blocks) and the two ways of drawing initial states, in a box
(:class:`BoxSampling`) or in a ball (:class:`BallSampling`)."""

from __future__ import annotations

import abc
import dataclasses
import functools
import typing
from typing import Any, Callable, ClassVar

import equinox as eqx
import numpy as np
from jaxtyping import Float

from .._errors import MetriplexError, expect_integer
from .._model import GenericModel
from .._types import State
from ..structure import Known, KnownFriction, KnownPoisson


@dataclasses.dataclass(frozen=True)
class Settings:
    """Published (or, where stated in ``source``, our) data settings of a reference experiment.

    ``steps`` time steps of size ``dt`` give ``steps + 1`` recorded states per trajectory.
    """

    dt: float
    steps: int
    trajectories: int
    source: str = ""

    @property
    def horizon(self) -> float:
        """The time that ``steps`` steps of size ``dt`` span."""
        return self.dt * self.steps


@dataclasses.dataclass(frozen=True)
class System(abc.ABC):
    """A ground-truth GENERIC system: a :class:`~metriplex.GenericModel` with analytic
    :math:`E, S, L, M`, the names of its variables and how its initial states are drawn.

    Concrete systems are frozen dataclasses holding one typed, frozen ``config``; use
    :meth:`with_params` (or :func:`metriplex.systems.get_system`) for other parameters. Where
    ``names``, ``max_substep`` or ``defaults`` do not depend on the config, a system gives them
    as plain class attributes.
    """

    name: ClassVar[str]
    description: ClassVar[str]

    config: Any

    @property
    @abc.abstractmethod
    def max_substep(self) -> float:
        """Largest inner step that :func:`~metriplex.systems.generate` takes by default."""

    @property
    @abc.abstractmethod
    def names(self) -> tuple[str, ...]:
        """The state variables, in order."""

    @functools.cached_property
    def model(self) -> GenericModel:
        """The analytic GENERIC model (built once per system)."""
        return self._build_model()

    @abc.abstractmethod
    def _build_model(self) -> GenericModel: ...

    @property
    def n(self) -> int:
        """The number of state variables."""
        return len(self.names)

    @property
    @abc.abstractmethod
    def defaults(self) -> Settings:
        """Published data settings (``dt``, ``steps``, ``trajectories``)."""

    @abc.abstractmethod
    def sample_initial(self, num: int, *, seed: int) -> Float[np.ndarray, "num n"]:
        """``num`` initial states drawn with ``numpy.random.default_rng(seed)``; float64."""

    # -- parameters -----------------------------------------------------------------------------
    def with_params(self, **params: Any) -> "System":
        """This system with some ``config`` fields replaced, each given as its type (numbers,
        not text: the command line parses ``--param``)."""
        return type(self)(_replace_config(self.config, params, self.name))

    def parameters(self) -> dict[str, Any]:
        """The current parameters, by field name."""
        return {f.name: getattr(self.config, f.name) for f in dataclasses.fields(self.config)}

    def parameter_summary(self) -> str:
        """One line ``name=value, ...`` of the current parameters."""
        return ", ".join(f"{k}={_format(v)}" for k, v in self.parameters().items())

    def help_text(self) -> str:
        """Description, parameters and published settings, for ``metriplex generate --help``."""
        d = self.defaults
        return (
            f"{self.name}: {self.description} Parameters: {self.parameter_summary()}. "
            f"Published settings: dt={d.dt:.6g}, steps={d.steps}, trajectories={d.trajectories}."
        )

    def _check_num(self, num: int) -> None:
        expect_integer(num, what="the number of initial states", least=1)


@dataclasses.dataclass(frozen=True)
class Bound:
    """``fn(params, x)`` with its parameters fixed: one analytic part of a system as a function
    of the state alone.

    Equal, and hashed alike, when ``fn`` is the same function and ``params`` are equal, as the
    static fields of the blocks that hold it must be: systems with equal configs build equal
    models, which share compiled code.
    """

    fn: Callable[[Any, State], Any]
    params: Any

    def __call__(self, x: State) -> Any:
        return self.fn(self.params, x)


def analytic_model(
    config: Any, *, energy: Any, entropy: Any, poisson: Any, friction: Any
) -> GenericModel:
    """The :class:`~metriplex.GenericModel` of a system's analytic parts.

    Each part is a structure block (``SumOf((2,))``, ``CanonicalPoisson(3, 1)``,
    ``KnownPoisson(fn)``, ...), used as it is, or a function ``fn(config, x)``, which becomes
    its family's known block (:class:`~metriplex.structure.Known`,
    :class:`~metriplex.structure.KnownPoisson`, :class:`~metriplex.structure.KnownFriction`)
    around ``Bound(fn, config)``.
    """

    def block(part: Any, known: type) -> Any:
        return part if isinstance(part, eqx.Module) else known(Bound(part, config))

    return GenericModel(
        energy=block(energy, Known),
        entropy=block(entropy, Known),
        poisson=block(poisson, KnownPoisson),
        friction=block(friction, KnownFriction),
    )


class BoxSampling:
    """Initial states uniform in the config's box, ``x0_center + U(-1, 1) * x0_halfwidth`` per
    component (a mixin of :class:`System`)."""

    def sample_initial(self, num: int, *, seed: int) -> Float[np.ndarray, "num n"]:
        """``x0_center + U(-1, 1) * x0_halfwidth`` per component (see the config)."""
        self._check_num(num)
        return _sample_box(self.config.x0_center, self.config.x0_halfwidth, num, seed)


class BallSampling:
    r"""Initial states uniform by volume in the ball :math:`|x - c| \le r` of the config's
    ``center`` and ``radius`` (a mixin of :class:`System`)."""

    def sample_initial(self, num: int, *, seed: int) -> Float[np.ndarray, "num n"]:
        r"""Uniform by volume in the ball :math:`|x - c| \le r` (``config.radius``, ``center``)."""
        self._check_num(num)
        center = np.asarray(self.config.center, dtype=np.float64)
        rng = np.random.default_rng(seed)
        direction = rng.normal(size=(num, center.shape[0]))
        direction /= np.linalg.norm(direction, axis=1, keepdims=True)
        r = self.config.radius * rng.uniform(size=(num, 1)) ** (1.0 / center.shape[0])
        return center[None, :] + r * direction


def _format(v: Any) -> str:
    if isinstance(v, tuple):
        return "(" + ", ".join(_format(u) for u in v) + ")"
    if isinstance(v, float):
        return f"{v:.6g}"
    return str(v)


def _sample_box(
    center: tuple[float, ...], halfwidth: tuple[float, ...], num: int, seed: int
) -> np.ndarray:
    """``center + U(-1, 1) * halfwidth`` per component, shape ``(num, n)``."""
    return _uniform_box(np.random.default_rng(seed), center, halfwidth, num)


def _uniform_box(
    rng: np.random.Generator, center: Any, halfwidth: Any, num: int
) -> np.ndarray:
    """:func:`_sample_box` with a given generator (for samplers that draw more after it)."""
    c = np.asarray(center, dtype=np.float64)
    h = np.asarray(halfwidth, dtype=np.float64)
    return c[None, :] + rng.uniform(-1.0, 1.0, size=(num, c.shape[0])) * h[None, :]


def _replace_config(config: Any, params: dict[str, Any], system: str) -> Any:
    fields = {f.name: f for f in dataclasses.fields(config)}
    hints = typing.get_type_hints(type(config))
    changes = {}
    for key, value in params.items():
        if key not in fields:
            raise MetriplexError(
                f"system {system!r} has no parameter {key!r}; its parameters are "
                f"{sorted(fields)}."
            )
        changes[key] = _coerce(value, hints[key], key, getattr(config, key))
    return dataclasses.replace(config, **changes)


def _coerce(value: Any, hint: Any, key: str, current: Any) -> Any:
    """``value`` as the field's type: numbers for a tuple (a sequence, or one number where the
    field holds one), a number, a whole number or a name. Text for numbers is refused: the
    command line parses ``--param`` (:func:`metriplex.app._option.system_params`), not this."""
    try:
        if hint in (float, int) or typing.get_origin(hint) is tuple:
            if isinstance(value, (str, bytes, bool, np.bool_)):
                raise TypeError(f"{type(value).__name__}, not numbers")
        if typing.get_origin(hint) is tuple:
            out = tuple(float(v) for v in (value if np.iterable(value) else (value,)))
            if len(out) != len(current):
                raise ValueError(f"expected {len(current)} numbers")
            return out
        if hint is float:
            return float(value)
        if hint is int:
            if not float(value).is_integer():
                raise ValueError("not a whole number")
            return int(value)
        if hint is str:
            return str(value)
    except (TypeError, ValueError) as err:
        raise MetriplexError(
            f"parameter {key!r} must be {_describe(hint, current)}; got {value!r} ({err}). "
            f"Example: {key}={_format(current)}."
        ) from None
    return value


def _describe(hint: Any, current: Any) -> str:
    if typing.get_origin(hint) is tuple:
        return f"a sequence of {len(current)} numbers (--param: comma-separated)"
    return {float: "a number", int: "an integer", str: "a name"}.get(hint, str(hint))
