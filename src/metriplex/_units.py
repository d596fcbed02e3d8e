r"""The data's natural units (:class:`Units`): per-variable shift and scale, the time scale and
the scales of the two potentials, in which every network and every loss term works.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import numpy as np

from .data import Pairs, Trajectories, observed_rates, roughness, time_scale

if TYPE_CHECKING:
    from .structure._abstract import AbstractFriction, AbstractPoisson, AbstractPotential
    from .structure.scaling import Scaling


#: The most weight :meth:`Units.residual_metric` gives a combination of variables, relative to
#: the plain residual's: rates kept correlated to 1 part in 1 000 are fitted as if they moved as
#: much as their variables do, and data noise below that is not amplified further.
METRIC_CAP = 1000.0


@dataclasses.dataclass(frozen=True)
class Units:
    r"""The data's natural units, in which every network and every loss term works.

    - ``shift``, ``scale``: per-variable mean :math:`c_i` and standard deviation :math:`d_i`;
    - ``time``: the time scale :math:`\tau` (:func:`time_scale`);
    - ``energy``, ``entropy``: scales :math:`\sigma_E, \sigma_S` of the two potentials;
    - ``roughness``: how much of the data's rates changes from pair to pair as noise does
      (:func:`~metriplex.data.roughness`; ``None`` where unknown). The verdict compares it with
      the data a model is judged on: a model that learnt from rougher data than those is not
      refuted by fitting them less well than a field trained on them;
    - ``pairs``: how many pairs of consecutive samples the data hold (``None`` where unknown),
      which the verdict compares with the pairs its reference trains on;
    - ``low``, ``high``: each variable's least and greatest value in the data (``None`` where
      unknown), the extent beyond which judged data are extrapolation;
    - ``step``: the data's largest time step (``None`` where unknown): a model rolled out with
      much larger steps takes them in one step of its scheme each;
    - ``trajectories``: how many trajectories the data hold (``None`` where unknown): a model
      of one or two has seen as many curves of states, and elsewhere extrapolates.

    In these units a state is :math:`\tilde x = D^{-1}(x - c)`, time is :math:`t/\tau`, and
    :math:`E = \sigma_E\tilde E`, :math:`S = \sigma_S\tilde S`,
    :math:`L = D\tilde L D^\top/(\tau\sigma_E)`, :math:`M = D\tilde M D^\top/(\tau\sigma_S)`,
    so that :math:`\dot{\tilde x} = \tilde L\tilde\nabla\tilde E + \tilde M\tilde\nabla
    \tilde S` and the networks :math:`\tilde E, \tilde S, \tilde L, \tilde M` of order one give
    rates of the data's order. The loss terms are measured in the same units (a residual in
    units of :math:`d_i/\tau`), so their weights need no tuning to the data's units.
    """

    shift: tuple[float, ...]
    scale: tuple[float, ...]
    time: float = 1.0
    energy: float = 1.0
    entropy: float = 1.0
    roughness: float | None = None
    pairs: int | None = None
    low: tuple[float, ...] | None = None
    high: tuple[float, ...] | None = None
    step: float | None = None
    trajectories: int | None = None

    @classmethod
    def from_data(cls, data: "Trajectories", *, poisson: AbstractPoisson | None = None,
                  entropy: AbstractPotential | None = None,
                  friction: AbstractFriction | None = None) -> "Units":
        r"""The units of ``data``, with the potentials' scales chosen from the blocks that are
        **given** (pass the known ``poisson``, ``entropy`` or ``friction`` block; leave out
        those that are learned):

        - a learned energy that pairs with a given :math:`L` must supply the rates by itself:
          :math:`\sigma_E = 1/(\tau\,\operatorname{rms}(D^{-1}LD^{-\top}))`;
        - a given entropy sets :math:`\sigma_S = \operatorname{rms}(D\nabla S)` (for
          :math:`S = s_1 + s_2`, the scale of the :math:`s_i`); a given :math:`M` with a learned
          entropy sets :math:`\sigma_S = 1/(\tau\,\operatorname{rms}(D^{-1}MD^{-\top}))`;
        - where both partners are learned the scale is 1 (their common factor is not
          identifiable, so any choice is as good).

        ```python
        L, S = CanonicalPoisson(3, pairs=1), SumOf((2,))
        units = Units.from_data(data, poisson=L, entropy=S)
        energy = MLPPotential(3, data=data.x, output_scale=units.energy, key=key)
        ```
        """
        from .structure._mlp import data_statistics

        shift, scale = data_statistics(data.x)
        d = np.asarray(scale)
        tau = time_scale(data, d)
        x = data.x[np.linspace(0, len(data.x) - 1, min(256, len(data.x))).astype(int)]
        energy = entropy_scale = 1.0
        if poisson is not None:
            size = _bivector_size(poisson, x, d)
            if size is not None:
                energy = 1.0 / (tau * size)
        if entropy is not None:
            entropy_scale = _gradient_size(entropy, x, d) or 1.0
        elif friction is not None:
            size = _bivector_size(friction, x, d)
            if size is not None:
                entropy_scale = 1.0 / (tau * size)
        return cls(shift, scale, tau, float(energy), float(entropy_scale), roughness(data, d),
                   len(data.t) - len(data.ids), tuple(map(float, np.min(data.x, axis=0))),
                   tuple(map(float, np.max(data.x, axis=0))), largest_step(data),
                   len(data.ids))

    def farthest(self, x: np.ndarray) -> tuple[float, int, int]:
        """How far the states ``x`` (rows) reach from these units' data: the largest
        :math:`|x_i - c_i|/d_i` (non-finite entries left out), its row and its variable. Only
        values outside the data's extent count where it is known (``low``, ``high``): data
        gathered near one state (a reactor near equilibrium, 0.087 about 0.28) with a few
        trajectories from far out (1.06) were trained on up to 9 of their deviations, and a
        test state at 6.4 was no extrapolation (a new-user check's false "never trained on")."""
        x = np.asarray(x, dtype=np.float64)
        z = np.abs((x - np.asarray(self.shift)) / np.asarray(self.scale))
        if self.low is not None and self.high is not None:
            z = np.where((x < np.asarray(self.low)) | (x > np.asarray(self.high)), z, 0.0)
        z = np.where(np.isfinite(z), z, 0.0)
        if z.size == 0:
            return 0.0, 0, 0
        row, var = np.unravel_index(int(np.argmax(z)), z.shape)
        return float(z[row, var]), int(row), int(var)

    @property
    def rate(self) -> np.ndarray:
        r"""Per-variable rate scale :math:`d_i/\tau`: the unit of every residual."""
        return np.asarray(self.scale) / self.time

    def residual_metric(self, data: "Trajectories | Pairs", *,
                        cap: float = METRIC_CAP) -> np.ndarray:
        r"""The metric :math:`W` ``(n, n)`` in which the pair residual is measured:
        :math:`r^\top W r` for the residual :math:`r` in units of :attr:`rate`, instead of
        :math:`|r|^2`.

        It is the identity, plus weight on each combination of variables whose observed rates
        the data keep correlated: a combination that moves far less than its variables do
        (heat passed between two cells at nearly equal temperatures leaves the sum of their
        entropies almost still; a conserved energy ties the rates of its variables). With
        :math:`v = D^{-1}\dot x` the observed rates in standard deviations per unit of time,
        :math:`R` their correlation matrix (second moments about zero, so a rate that is
        never zero keeps its mean) and :math:`R = \sum_k \mu_k u_k u_k^\top`, each
        combination :math:`u_k` whose share :math:`\mu_k` is below 1 gets the extra weight
        :math:`1/(\mu_k + 1/\mathrm{cap}) - 1`, at most ``cap - 1``: in the residual it is
        the direction :math:`a_k \propto \operatorname{diag}(\operatorname{rms} v)^{-1}u_k`.
        Uncorrelated rates give the identity (the plain residual), and so does any variable
        alone, however slowly it moves; variables that do not move are left out.

        The metric depends on the data's rates only through their correlations, so it does
        not change with the unit of time, the units or offsets of the variables.
        """
        n = len(self.scale)
        squares, count = np.zeros((n, n)), 0
        d = np.asarray(self.scale, np.float64)
        for v in observed_rates(data):
            v = v / d[None, :]
            squares += v.T @ v
            count += len(v)
        second = squares / max(count, 1)
        rms = np.sqrt(np.maximum(np.diag(second), 0.0))
        live = np.flatnonzero(rms > 1e-12 * max(float(rms.max(initial=0.0)), 1e-300))
        metric = np.eye(n)
        if len(live) < 2 or not np.all(np.isfinite(second)):
            return metric
        share, combos = np.linalg.eigh(second[np.ix_(live, live)] / np.outer(rms[live], rms[live]))
        extra = np.maximum(1.0 / (np.maximum(share, 0.0) + 1.0 / cap) - 1.0, 0.0)
        directions = combos / rms[live][:, None]
        directions /= np.linalg.norm(directions, axis=0)[None, :]
        metric[np.ix_(live, live)] += (directions * extra) @ directions.T
        return metric

    def poisson_scaling(self) -> Scaling:
        r"""The :class:`~metriplex.Scaling` of a learned :math:`L`:
        :math:`L = D\tilde L D^\top/(\tau\sigma_E)`."""
        from .structure.scaling import Scaling

        return Scaling(self.shift, self.scale, 1.0 / (self.time * self.energy))

    def friction_scaling(self) -> Scaling:
        r"""The :class:`~metriplex.Scaling` of a learned :math:`M`:
        :math:`M = D\tilde M D^\top/(\tau\sigma_S)`."""
        from .structure.scaling import Scaling

        return Scaling(self.shift, self.scale, 1.0 / (self.time * self.entropy))

    def to_json(self) -> dict:
        """The units as a JSON-able dict of their fields."""
        return dataclasses.asdict(self)


def largest_step(data: "Trajectories") -> float | None:
    """The largest time step between neighbouring samples of one trajectory of ``data``."""
    same = data.trajectory[1:] == data.trajectory[:-1]
    steps = np.diff(np.asarray(data.t, dtype=np.float64))[same]
    return float(np.max(steps)) if steps.size else None


def _rms_nonzero(a: np.ndarray) -> float | None:
    """Root mean square of the entries that are not zero everywhere (``None`` if all are)."""
    a = np.asarray(a, dtype=np.float64).reshape(len(a), -1)
    live = np.any(a != 0, axis=0)
    if not np.any(live):
        return None
    return float(np.sqrt(np.mean(a[:, live] ** 2)))


def _bivector_size(block, x: np.ndarray, d: np.ndarray) -> float | None:
    """RMS of the live entries of :math:`D^{-1}B(x)D^{-\top}` over states ``x``."""
    import jax
    import jax.numpy as jnp

    xs = jnp.asarray(x)
    mats = np.asarray(jax.vmap(block)(xs, jnp.zeros_like(xs)))
    return _rms_nonzero(mats / np.outer(d, d)[None])


def _gradient_size(potential, x: np.ndarray, d: np.ndarray) -> float | None:
    """RMS of the live entries of :math:`D\nabla S(x)` over states ``x``."""
    import jax
    import jax.numpy as jnp

    grads = np.asarray(jax.vmap(jax.grad(potential))(jnp.asarray(x)))
    return _rms_nonzero(grads * d[None])
