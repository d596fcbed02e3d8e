"""From a :class:`~metriplex.app.config.RunConfig` to the objects the library works with: the
data's :class:`~metriplex.Units` (:func:`units_for`), the model (:func:`build_model`), the
stopping rule (:func:`stopping_for`), the settings every training stage shares
(:func:`fit_settings`) and the loss (:func:`build_loss`). The configuration's
strings are read in :mod:`metriplex.app.config`; this module turns checked settings into objects.
"""

from __future__ import annotations

from typing import Any, NamedTuple, TextIO

import jax
import jax.random as jr

from .._errors import MetriplexError
from .._model import GenericModel
from .._units import Units
from .config import (
    DEGENERACY_POINTS,
    FEATURE_BLOCKS,
    FEATURES,
    JACOBI_CHOICES,
    RunConfig,
    _feature_blocks,
    _indices,
    _known_entropy,
    _known_friction,
    _known_poisson,
    _spelling,
    entropy_variables,
    confine_margin,
    confine_on,
    exact_blocks,
    scheme_from_name,
    temperature_init_on,
    temperature_weight,
    validate,
)
from .._rollout_loss import RolloutWindow
from ..data import Trajectories, state_scale
from ..losses import (
    AbstractJacobiEstimator,
    ExactJacobi,
    FrictionDegeneracy,
    JacobiPenalty,
    Loss,
    NegativeTemperature,
    PoissonDegeneracy,
    SchemeResidual,
    StochasticJacobi,
)
from ..structure.masked import MaskedFriction, MaskedPoisson, check_constant
from ..structure.confinement import Confinement
from ..structure.potential import FeatureMap
from ._option import option
from ._spellings import Learn
from ..train import Average, Plateau

class Given(NamedTuple):
    """The blocks that ``config`` gives (``None`` for each one learned), made once: a
    ``file:`` L or M is read here, not again by every reader."""

    poisson: Any
    entropy: Any
    friction: Any

    @classmethod
    def of(cls, config: RunConfig, n: int) -> "Given":
        return cls(_known_poisson(config, n), _known_entropy(config, n),
                   _known_friction(config, n))


def units_for(config: RunConfig, data: Trajectories, given: Given | None = None) -> Units:
    """The data's :class:`~metriplex.Units` for the blocks that ``config`` gives (``given``,
    default :meth:`Given.of`)."""
    given = Given.of(config, data.n) if given is None else given
    return Units.from_data(data, poisson=given.poisson, entropy=given.entropy,
                           friction=given.friction)


def build_model(config: RunConfig, data: Trajectories, *, key: jax.Array,
                units: Units | None = None,
                constant: tuple[int, ...] | None = None,
                given: Given | None = None) -> GenericModel:
    """The untrained model that ``config`` describes, in the natural ``units`` of ``data``
    (default :func:`units_for`): networks see standardised states, and their outputs are scaled
    so that an untrained network gives rates of the data's order, whatever the units. The
    learned L and M hold the variables ``constant`` constant (default
    :func:`constant_variables`). ``given``: the given blocks, if already made."""
    n = data.n
    validate(config, n)
    given = Given.of(config, n) if given is None else given
    units = units_for(config, data, given) if units is None else units
    x = data.x
    kE, kS, kL, kM = jr.split(key, 4)
    net = dict(width=config.width, depth=config.depth, activation=config.activation)
    features = FEATURES.get(config.features)
    blocks = _feature_blocks(config)
    feats = {b: features if b in blocks else None for b in FEATURE_BLOCKS}
    exact_L, exact_M = exact_blocks(config)
    energy = _spelling(config.energy, "--energy").learned(Learn(
        n, net, x, kE, output_scale=units.energy, features=feats["energy"],
        quadratic=bool(config.quadratic),
        confinement=(Confinement.around(x, confine_margin(config)) if confine_on(config)
                     else None),
        linear=temperature_init_on(config),
        argument=option(config.energy).argument))
    poisson, entropy, friction = given
    if entropy is None:
        free = casimir_variables(config, poisson)
        if free is not None:  # S a Casimir of the given L by construction
            feats["entropy"] = FeatureMap(passthrough=free)
        entropy = _spelling(config.entropy, "--entropy").learned(Learn(
            n, net, x, kS, output_scale=units.entropy, features=feats["entropy"],
            quadratic=bool(config.quadratic)))
    if poisson is None:
        poisson = _spelling(config.poisson, "--poisson").learned(Learn(
            n, net, x, kL, scaling=units.poisson_scaling(), exact=exact_L,
            entropy_variables=entropy_variables(config)))
    if friction is None:
        friction = _spelling(config.friction, "--friction").learned(Learn(
            n, net, x, kM, scaling=units.friction_scaling(), exact=exact_M,
            features=feats["friction"], argument=option(config.friction).argument))
    constant = constant_variables(config, data) if constant is None else constant
    if constant:
        if _spelling(config.poisson, "--poisson").learned:
            poisson = MaskedPoisson(poisson, constant)
        if _spelling(config.friction, "--friction").learned:
            friction = MaskedFriction(friction, constant)
    return GenericModel(energy, entropy, poisson, friction)


def casimir_variables(config: RunConfig, poisson: Any) -> tuple[int, ...] | None:
    r"""The variables a learned S is made a function of, so that it is a Casimir of the given
    L, the block ``poisson`` (``None`` where L is learned): :math:`L\nabla S = 0` exactly. Or
    ``None`` to learn S of every variable.

    A constant L whose rows and columns are zero on some variables and nondegenerate on the
    others (``canonical:K`` beside extra variables, a ``file:`` L of that form) has exactly the
    functions of those variables as Casimirs; a learned S of all of them would leave
    :math:`L\nabla S = 0` to nothing (a given L gets no penalty), and the model's entropy could
    fall along its own flow. Applies with ``--degeneracy auto`` or ``exact`` and no
    ``--features`` for the entropy; ``None`` where L is learned, S is given, or the zero rows
    do not split L so (L = 0 among them: every function is its Casimir)."""
    if (poisson is None or config.entropy != "neural" or config.degeneracy == "soft"
            or (config.features != "none" and "entropy" in _feature_blocks(config))):
        return None
    import jax.numpy as jnp
    import numpy as np

    zero = jnp.zeros(poisson.n)
    L = np.asarray(poisson(zero, zero), dtype=np.float64)
    free = np.flatnonzero(np.all(L == 0, axis=0) & np.all(L == 0, axis=1))
    rest = np.setdiff1d(np.arange(poisson.n), free)
    if len(free) == 0 or len(rest) == 0 or \
            np.linalg.matrix_rank(L[np.ix_(rest, rest)]) < len(rest):
        return None
    return tuple(int(i) for i in free)


def constant_variables(config: RunConfig, data: Trajectories, *,
                       note: TextIO | None = None) -> tuple[int, ...]:
    """The variables whose rows and columns the learned :math:`L` and :math:`M` keep zero
    (``--constant``): by default (``auto``) those constant along every trajectory of ``data``
    (:meth:`~metriplex.Trajectories.constant_variables`), which are then named on ``note``
    (a text stream); ``none``; or the indices given."""
    if config.constant == "auto":
        constant = data.constant_variables()
        if constant and note is not None:
            print(_constant_note(constant, data.names), file=note)
        return constant
    if config.constant == "none":
        return ()
    return check_constant(_indices(config.constant, data.n, "--constant"), data.n)


def input_noise_of(config: RunConfig, data: Trajectories,
                   constant: tuple[int, ...]) -> float | tuple[float, ...]:
    """fit's ``input_noise``: ``--input-noise`` on every variable, and with
    ``--jitter-constants`` on each variable held ``constant`` that takes several values across
    the trajectories (a recorded parameter), at least the median gap between neighbouring
    values, in units of its standard deviation: the model is known only at those values, and
    noise across the gaps makes it vary smoothly between them rather than fit each
    trajectory's value on its own. At most a quarter of its standard deviation: with a few
    far-apart values, more would average their dynamics together."""
    import numpy as np

    if not config.jitter_constants or not constant:
        return config.input_noise
    noise = np.full(data.n, float(config.input_noise))
    d = state_scale(data.x)
    for i in constant:
        values = np.unique(np.asarray([x[0, i] for _, x in data]))
        if len(values) > 2 and d[i] > 0:
            noise[i] = max(noise[i], min(float(np.median(np.diff(values))) / d[i], 0.25))
    return tuple(float(v) for v in noise)


def _constant_note(constant: tuple[int, ...], names: tuple[str, ...]) -> str:
    """What ``train`` says when it holds the variables ``constant`` by default."""
    listed = ", ".join(f"{names[i]} (column {i})" for i in constant)
    one = len(constant) == 1
    return (f"note: {listed} {'is' if one else 'are'} constant along every training "
            f"trajectory; the learned L and M hold {'it' if one else 'them'} constant "
            f"(--constant none learns {'its rate' if one else 'their rates'}).")


#: Learning-rate schedules by name: what ``--schedule`` means.
def stopping_for(config: RunConfig) -> Plateau | None:
    """The ``stopping`` argument of :func:`~metriplex.fit` that ``config.schedule`` names
    (``None``: exactly ``config.steps`` steps of a cosine schedule, no early stop)."""
    if config.schedule != "plateau":
        return None
    if config.patience is None:
        return Plateau(cuts=config.lr_cuts)
    return Plateau(patience=config.patience, cuts=config.lr_cuts)


def fit_settings(config: RunConfig) -> dict[str, Any]:
    """The arguments of :func:`~metriplex.fit` that every training stage of ``config`` shares:
    the optimiser, the step budget, the batches, the evaluations and the schedule."""
    return dict(
        learning_rate=config.lr, weight_decay=config.weight_decay, steps=config.steps,
        batch_size=config.batch_size, eval_every=config.eval_every,
        consecutive=max(config.consecutive, 1), stopping=stopping_for(config),
        average=Average(config.average_steps) if config.average_steps else None,
    )


def build_loss(config: RunConfig, units: Units | None = None,
               data: Trajectories | None = None) -> Loss:
    r"""Scheme residual plus the penalties that the structure needs (none where exact).

    The trainer measures residuals in units of the data's rates (:attr:`Units.rate`). With
    ``units``, the penalties are measured in the same dimensionless units as the residual
    (:math:`L\nabla S` scaled by :math:`\sigma_E/\sigma_S`, :math:`M\nabla E` by
    :math:`\sigma_S/\sigma_E`, the Jacobi tensor by :math:`\sigma_E^2/\tau`), so a weight
    means the same on any data. With ``units`` and the training ``data``, ``--residual-metric
    correlated`` measures the residual in :meth:`~metriplex.Units.residual_metric`.
    """
    e, s, tau = (1.0, 1.0, 1.0) if units is None else (units.energy, units.entropy, units.time)
    scheme = scheme_from_name(config.scheme or "cn")  # train_run gives the data's choice
    metric = None
    if residual_metric_of(config) == "correlated" and data is not None and units is not None:
        metric = units.residual_metric(data)
    loss = config.w_traj * SchemeResidual(scheme, metric=metric)
    if config.window_steps > 0:
        loss = loss + config.w_traj * RolloutWindow(scheme, steps=config.window_steps)
    exact_L, exact_M = exact_blocks(config)
    learned_L = _spelling(config.poisson, "--poisson").learned is not None
    learned_M = _spelling(config.friction, "--friction").learned is not None
    at_midpoints = _at_midpoints(config)
    if not exact_L and learned_L and config.entropy != "zero" and config.w_degeneracy_L > 0:
        loss = loss + config.w_degeneracy_L * (e / s) ** 2 * PoissonDegeneracy(
            at_midpoints=at_midpoints)
    if not exact_M and learned_M and config.w_degeneracy_M > 0:
        loss = loss + config.w_degeneracy_M * (s / e) ** 2 * FrictionDegeneracy(
            at_midpoints=at_midpoints)
    w_temperature = temperature_weight(config)
    if w_temperature > 0:
        loss = loss + w_temperature * NegativeTemperature(entropy_variables(config))
    if jacobi_of(config) != "none" and config.poisson in ("neural", "lie-poisson") \
            and config.w_jacobi > 0:
        loss = loss + config.w_jacobi * (e**4 / tau**2) * JacobiPenalty(
            _jacobi_estimator(config), samples=config.jacobi_samples
        )
    return loss


def residual_metric_of(config: RunConfig) -> str:
    """``--residual-metric``; ``auto`` (the default) is ``correlated`` where the model has a
    friction (M learned or given) and ``diagonal`` where M = 0.

    Where heat passes between cells, or matter between species, the data keep combinations of
    variables nearly still (a sum of entropies, a conserved energy or mass) that the plain
    residual cannot see, and weighing them was measured to help: 1.6-15x on the four such
    systems measured (docs/zoo.md, *The residual's metric*). Where M = 0 the nearly still
    combinations measured were momenta that only an exactly symmetric learned E conserves,
    and weighing them cost 1.7-5x on three vortices."""
    if config.residual_metric != "auto":
        return config.residual_metric
    return "diagonal" if config.friction == "zero" else "correlated"


def _at_midpoints(config: RunConfig) -> bool:
    """The degeneracy penalties' ``at_midpoints`` from ``--degeneracy-at states | midpoints``."""
    if config.degeneracy_at not in DEGENERACY_POINTS:
        raise MetriplexError(f"--degeneracy-at must be one of {', '.join(DEGENERACY_POINTS)}; "
                             f"got {config.degeneracy_at!r}.")
    return config.degeneracy_at == "midpoints"


def jacobi_of(config: RunConfig) -> str:
    """``--jacobi``; ``auto`` (the default) is ``exact`` with ``--poisson lie-poisson`` and
    ``none`` otherwise.

    A Lie-Poisson L is linear in the state, so its Jacobi residual is too, and the exact
    penalty costs little. The data fix only the structure constants that the states they
    visit reach: two spins (n = 7, 128 trajectories) were learned to 7.1e-3 with a Jacobi
    residual of 0.35 (not Poisson; the verdict "cannot tell"), and with the penalty to 6.5e-3
    with 1.6e-5 ("consistent"). A learned network L keeps no penalty by default: on the zoo
    it did not bring L under the Jacobi check's limit (docs/zoo.md)."""
    if config.jacobi != "auto":
        return config.jacobi
    return "exact" if option(config.poisson).kind == "lie-poisson" else "none"


def _jacobi_estimator(config: RunConfig) -> AbstractJacobiEstimator:
    """The Jacobi penalty's estimator from ``--jacobi exact | stochastic`` (or ``auto``,
    :func:`jacobi_of`) and ``--jacobi-probes``."""
    jacobi = jacobi_of(config)
    if jacobi == "exact":
        return ExactJacobi()
    if jacobi == "stochastic":
        return StochasticJacobi(probes=config.jacobi_probes)
    raise MetriplexError(f"--jacobi must be one of {', '.join(JACOBI_CHOICES)}; got "
                         f"{config.jacobi!r}.")


# Adam at 1e-2 (cosine-decayed, see train.default_optimizer) with batches of 256 pairs: a sweep
# on the pendulum and gas data reached 3-5x lower validation residuals in the same wall time
# than 2e-3 with batches of 512 (docs/experiments.md). The pendulum presets train and roll out
# with the discrete-gradient scheme, which conserves the learned energy exactly.
