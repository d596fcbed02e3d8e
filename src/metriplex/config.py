"""Run configuration: what is learned and what is given, as plain JSON-able settings.

The command line and the experiment presets describe a run with a :class:`RunConfig`;
:func:`build_model` and :func:`build_loss` turn it into the objects the library works with
(``GenericModel``, ``Loss``). Library code itself takes objects, never these strings.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import jax.random as jr

from ._errors import MetriplexError
from ._model import GenericModel
from .data import Trajectories
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
from .structure.friction import CholeskyFriction, ProjectedCholeskyFriction, ZeroFriction
from .structure.poisson import CanonicalPoisson, ZeroPoisson
from .structure.potential import FeatureMap, MLPPotential, SumOf, ZeroPotential
from .structure.scaling import Scaling

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
    degeneracy: str = "soft"
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
    width: int = 64
    depth: int = 2
    activation: str = "softplus"
    lr: float = 1e-3
    steps: int = 5000
    batch_size: int = 256
    validation: float = 0.2
    eval_every: int = 100
    patience: int | None = None
    seed: int = 0
    float64: bool = False
    checkpoint_every: int = 10
    data_parallel: bool = False

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
    head = _choice(config.poisson, ("neural", "canonical", "zero", "casimir3"), "--poisson")
    if head == "canonical":
        try:
            K = int(config.poisson.partition(":")[2])
        except ValueError:
            raise MetriplexError(
                f"--poisson canonical:K needs an integer K (the number of position/momentum "
                f"pairs); got {config.poisson!r}."
            ) from None
        if K < 1 or 2 * K > n:
            raise MetriplexError(
                f"--poisson canonical:{K} needs 2K <= n (K positions then K momenta), but the data "
                f"have n={n} variables. Use canonical:K with 1 <= K <= {n // 2}."
            )
    if head == "casimir3" and n != 3:
        raise MetriplexError(f"--poisson casimir3 is for 3 state variables; the data have {n}.")
    _choice(config.friction, ("neural", "zero"), "--friction")
    _choice(config.degeneracy, ("soft", "exact"), "--degeneracy")
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
    for name in ("width", "depth", "steps", "batch_size", "eval_every"):
        v = getattr(config, name)
        if v < (0 if name == "steps" else 1):
            raise MetriplexError(f"--{name.replace('_', '-')} must be positive; got {v}.")
    if not config.lr > 0:
        raise MetriplexError(f"--lr must be > 0; got {config.lr}.")
    if not 0 <= config.validation < 1:
        raise MetriplexError(f"--validation must lie in [0, 1); got {config.validation}.")
    for name in ("w_traj", "w_degeneracy_L", "w_degeneracy_M", "w_jacobi"):
        if getattr(config, name) < 0:
            raise MetriplexError(f"loss weight {name} must be >= 0; got {getattr(config, name)}.")


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
    return blocks


def build_model(config: RunConfig, data: Trajectories, *, key) -> GenericModel:
    """The untrained model that ``config`` describes, normalised to ``data``'s scales."""
    n = data.n
    validate(config, n)
    x = data.x
    kE, kS, kL, kM = jr.split(key, 4)
    net = dict(width=config.width, depth=config.depth, activation=config.activation)
    features = FEATURES.get(config.features)
    blocks = _feature_blocks(config)
    feats = {b: features if b in blocks else None for b in FEATURE_BLOCKS}
    energy = MLPPotential(n, features=feats["energy"], data=x, key=kE, **net)
    if config.entropy == "neural":
        entropy = MLPPotential(n, features=feats["entropy"], data=x, key=kS, **net)
    elif config.entropy == "zero":
        entropy = ZeroPotential()
    else:
        entropy = SumOf(_indices(config.entropy.partition(":")[2], n, "--entropy"))
    scaling = Scaling.from_data(x)
    exact = config.degeneracy == "exact"
    if config.poisson == "neural":
        spec = {"kind": "projected-mlp" if exact else "mlp", **net, "scaling": scaling.to_json()}
        poisson = _registry.from_spec("poisson", spec, n, key=kL)
    elif config.poisson == "casimir3":
        spec = {"kind": "casimir3", **net, "scaling": scaling.to_json()}
        poisson = _registry.from_spec("poisson", spec, n, key=kL)
    elif config.poisson == "zero":
        poisson = ZeroPoisson(n)
    else:
        poisson = CanonicalPoisson(n, int(config.poisson.partition(":")[2]))
    if config.friction == "neural":
        cls = ProjectedCholeskyFriction if exact else CholeskyFriction
        friction = cls(n, **net, scaling=scaling, features=feats["friction"], data=x, key=kM)
    else:
        friction = ZeroFriction(n)
    return GenericModel(energy, entropy, poisson, friction)


def build_loss(config: RunConfig) -> Loss:
    """Scheme residual plus the penalties that the structure needs (none where exact)."""
    loss = config.w_traj * SchemeResidual(scheme_from_name(config.scheme))
    soft = config.degeneracy == "soft"
    learned_L = config.poisson in ("neural", "casimir3")
    if soft and learned_L and config.entropy != "zero" and config.w_degeneracy_L > 0:
        loss = loss + config.w_degeneracy_L * PoissonDegeneracy(config.degeneracy_at)
    if soft and config.friction == "neural" and config.w_degeneracy_M > 0:
        loss = loss + config.w_degeneracy_M * FrictionDegeneracy(config.degeneracy_at)
    if config.jacobi != "none" and config.poisson == "neural" and config.w_jacobi > 0:
        loss = loss + config.w_jacobi * JacobiPenalty(
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
    "gas-containers": dict(
        energy="neural", entropy="sum:2,3", poisson="canonical:1", friction="neural",
        width=64, depth=2, lr=1e-2, batch_size=256, w_degeneracy_M=1.0,
    ),
}


def preset(name: str, **overrides) -> RunConfig:
    if name not in PRESETS:
        raise MetriplexError(f"unknown preset {name!r}; choose one of {sorted(PRESETS)}.")
    return RunConfig(**{**PRESETS[name], **overrides})

