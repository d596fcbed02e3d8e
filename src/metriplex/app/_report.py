"""The report figures of a model on data: rollouts against the data, rollout errors, the
pair residuals and the learned E and S; what ``train``, ``evaluate`` and ``reproduce`` write
to ``figures/`` (public as :func:`metriplex.runs.report_figures`). Where the data come from a
known model (the reference experiments), a :class:`Truth` adds its curves to the same
figures."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from . import plots
from .._energy_along import energy_rounding
from .._errors import MetriplexError
from .config import scheme_from_name
from ..data import Trajectories, state_scale, state_statistics, time_scale
from ..diagnostics import energy_entropy_along, rollout_data
from .._standardised import standardised_error_over_time, standardised_errors
from .._progress import progress_bar
from .._model import float_dtype
from .._structure_check import _terms_at, identified, states_read
from ..structure import SumOf
from ._temperature_plot import fit_clause, temperatures

if TYPE_CHECKING:
    from .._model import GenericModel
    from ..integrate import AbstractScheme, Rollout


@dataclasses.dataclass(frozen=True)
class Truth:
    """What the report draws beside the learned model when the data come from a known model,
    for the report's trajectory ``k``: the true model's own rollout error under a reference
    scheme at the data's step (``reference_error``, shape ``(T,)``, named by
    ``reference_label``), and the true E and S along the data after their best affine fit to the
    learned ones (``energy``, ``entropy``, shape ``(T,)``; ``None`` where unknown). The data
    are then labelled ``data_label`` (in the legend and as their key in ``trajectories.npz``).
    ``grad_energy``: the true ∇E at states of shape ``(m, n)``, in the learned E's gauge (times
    the affine fit's slope), for the true temperatures beside the learned ones."""

    reference_error: np.ndarray | None = None
    reference_label: str = "ground truth"
    energy: np.ndarray | None = None
    entropy: np.ndarray | None = None
    data_label: str = "true"
    grad_energy: Callable[[np.ndarray], np.ndarray] | None = None


#: The error figure's axis: each trajectory's error in standard deviations at each time
#: (:func:`~metriplex._standardised.standardised_error_over_time`).
STANDARDISED_LABEL = ("error in standard deviations\n"
                      "|D⁻¹(x − x_data)| / rms |D⁻¹(x_data − mean)|")

#: The figures that :func:`report_figures` writes, each as PNG, PDF and NPZ; and the one it
#: adds where S is a sum of entropy variables (the learned temperatures).
REPORT_FIGURES = ("trajectories", "error", "residual", "energy_entropy")
TEMPERATURE_FIGURE = "temperatures"
FIGURE_SUFFIXES = (".png", ".pdf", ".npz")


def report_figures(model: GenericModel, data: Trajectories, folder: str | Path, *,
                   scheme: str | AbstractScheme = "cn", k: int | None = None,
                   solver: str | None = None,
                   rollout: tuple[Rollout, np.ndarray, np.ndarray] | None = None,
                   truth: Truth | None = None, progress: bool = False) -> None:
    """The report figure set: every trajectory's rollout error over time (failed rollouts
    marked, and counted in the title) beside the per-variable error of trajectory ``k``; for
    trajectory ``k``, its rollout against the data, the one-step residual of every observed pair
    over time, and the learned E and S along the rollout and along the data (each marks where
    the rollout failed, if it did). Residuals are in the data's rate units (data scale / time
    scale). ``k``: an index into the data's trajectories; by default the worst one
    (:func:`worst_trajectory`), so one bad trajectory among good ones is what the figures show;
    each figure names it.
    ``scheme``: a scheme, or its command-line name (with ``solver``). ``rollout``: what
    :func:`~metriplex.diagnostics.rollout_data` returned for this model, data and scheme, to
    reuse. ``truth``: the known model's curves, drawn beside the learned ones (:class:`Truth`).
    ``progress``: a bar over the figures (large data take a while to draw). Where S is a sum
    of entropy variables, a fifth: the learned temperatures at the data's states, with what
    the data determine of them (:data:`TEMPERATURE_FIGURE`)."""
    K, worst, folder = len(data.ids), k is None, Path(folder)
    if not worst and not (isinstance(k, (int, np.integer)) and 0 <= k < K):
        raise MetriplexError(f"report_figures' k is the position of a trajectory in the data, "
                             f"0 to {K - 1} (not its id); got {k!r}. None: the worst rollout.")
    sch = scheme_from_name(scheme, solver=solver) if isinstance(scheme, str) else scheme
    out, xs, lengths = rollout if rollout is not None else rollout_data(model, data, scheme=sch)
    k = worst_trajectory(out, xs, lengths) if worst else k
    which = f"trajectory {data.ids[k]}" + (
        "" if K == 1 else f", the worst of {K} rollouts" if worst else f" of {K}")
    with progress_bar(total=4 + isinstance(model.entropy, SumOf), disable=not progress,
                      desc="figures", unit="figure",
                      leave=False) as bar:
        _draw_report(model, data, folder, sch, k, which, out, xs, lengths, truth or Truth(
            data_label="observed"), bar)


def worst_trajectory(out: Rollout, xs: np.ndarray, lengths: np.ndarray) -> int:
    """The index of the worst rollout: the one that failed first, if any did, else the one
    with the largest standardised error over its trajectory, which no offset of a variable
    shrinks (``xs``, ``lengths``: the padded data, as
    :func:`~metriplex.diagnostics.rollout_data` returns them)."""
    failed = np.asarray(out.failed_step, dtype=np.int64)  # int32 from JAX: the sentinel below
    if np.any(failed >= 0):                                 # would wrap to -1 in it
        return int(np.argmin(np.where(failed >= 0, failed, np.iinfo(np.int64).max)))
    pred = np.asarray(out.xs, dtype=np.float64)
    error = standardised_errors(pred, xs, np.asarray(lengths), _states(xs, lengths))
    return int(np.nanargmax(error)) if not np.isnan(error).all() else 0


def _states(xs: np.ndarray, lengths: Sequence[int] | np.ndarray) -> np.ndarray:
    """Every trajectory's states, without the padding."""
    return np.concatenate([xs[j, :T] for j, T in enumerate(lengths)])


def _named(fig, which: str):
    """``fig`` with the trajectory it shows (``which``) at the head of its title."""
    title = fig.get_suptitle()
    fig.suptitle(which + ("; " + title if title else ""), fontsize=9)
    return fig


def _draw_report(model, data, folder, sch, k, which, out, xs, lengths, truth: Truth,
                 bar) -> None:
    all_ts = np.asarray(out.ts, dtype=np.float64)
    all_pred = np.asarray(out.xs, dtype=np.float64)
    failed = np.asarray(out.failed_step)
    T = int(lengths[k])
    ts, pred, obs = all_ts[k, :T], all_pred[k, :T], xs[k, :T]
    failed_at = float(ts[min(int(failed[k]), T - 1)]) if failed[k] >= 0 else None
    names = list(data.names)
    plots.save_figure(_named(plots.trajectories(ts, pred, obs, names,
                                                truth_label=truth.data_label,
                                                failed_at=failed_at), which),
                      folder / "trajectories", t=ts, learned=pred, names=np.array(names),
                      failed_step=failed[k], trajectory=data.ids[k], **{truth.data_label: obs})
    bar.update()
    # Errors of every trajectory, standardised as evaluate's rollout_error_standardised (which
    # no offset shrinks): NaN after a failure (never a number standing for it).
    errors = np.full(all_pred.shape[:2], np.nan)
    mean, d, _ = state_statistics(data.x)  # the states rolled out, as evaluate's figure
    for j, Tj in enumerate(lengths):
        errors[j, :Tj] = standardised_error_over_time(all_pred[j, :Tj], xs[j, :Tj], mean, d)
    scale = state_scale(data.x)
    per_var = np.abs(pred - obs) / scale[None, :]
    reference = ({} if truth.reference_error is None
                 else {"reference_error": truth.reference_error})
    plots.save_figure(
        _named(plots.rollout_errors(all_ts, errors, failed_step=failed,
                                    per_variable=dict(zip(names, per_var.T)), trajectory=k,
                                    ids=list(data.ids), reference=truth.reference_error,
                                    reference_label=truth.reference_label,
                                    ylabel=STANDARDISED_LABEL), which),
        folder / "error", t=all_ts, error=errors, failed_step=failed, trajectory=data.ids,
        error_per_variable=per_var, shown=data.ids[k], names=np.array(names), **reference)
    bar.update()
    # The residual of each observed pair under the scheme, in the data's rate units d_i / tau.
    rate = scale / time_scale(data, scale)
    tk, xk = data.select([data.ids[k]]).t[:T], obs
    dtype = out.xs.dtype
    x0, x1 = jnp.asarray(xk[:-1], dtype), jnp.asarray(xk[1:], dtype)
    dt = jnp.asarray(np.diff(tk), dtype)
    res = np.asarray(_pair_residuals(model, sch, x0, x1, dt), dtype=np.float64) / rate[None, :]
    plots.save_figure(_named(plots.residual_over_time(tk[1:], res, names), which),
                      folder / "residual",
                      t=tk[1:], residual=res, names=np.array(names))
    bar.update()
    # Along the rollout and the observed trajectory, and at every trajectory's first and last
    # observed states (the potentials' spread over the data, for the axes), in one call (one
    # program to compile, little work after training). NaN after a failure: the potentials
    # stop there too.
    E_all, S_all = energy_entropy_along(model, np.concatenate([pred, obs, xs[:, 0], xs[:, -1]]))
    E, S, E_data, S_data = E_all[:T], S_all[:T], E_all[T:2 * T], S_all[T:2 * T]
    spreads = tuple(float(np.ptp(v[finite])) if (finite := np.isfinite(v)).any() else None
                    for v in (E_all[T:], S_all[T:]))
    fitted = {name: v for name, v in (("energy_true_fitted", truth.energy),
                                      ("entropy_true_fitted", truth.entropy)) if v is not None}
    plots.save_figure(_named(plots.energy_entropy(ts, E, S, E_true=truth.energy,
                                                  S_true=truth.entropy, E_data=E_data,
                                                  S_data=S_data, spreads=spreads,
                                                  failed_at=failed_at,
                                                  energy_rounding=energy_rounding(
                                                      E_all[T:], float_dtype(model))), which),
                      folder / "energy_entropy", t=ts, energy=E, entropy=S,
                      energy_along_data=E_data, entropy_along_data=S_data, **fitted)
    bar.update()
    if isinstance(model.entropy, SumOf):
        x = states_read(data.x)  # structure_residuals' states: its compiled program serves
        gE = np.asarray(_terms_at(model, jnp.asarray(x, float_dtype(model))).grad_energy,
                        dtype=np.float64)
        idx = list(model.entropy.indices)
        entropies = [names[i] for i in idx]
        true = ({} if truth.grad_energy is None
                else {"temperature_true_fitted": np.asarray(truth.grad_energy(x))[:, idx]})
        plots.save_figure(temperatures(x[:, idx], gE[:, idx], entropies,
                                       gauge=identified(model)["temperatures"],
                                       true=true.get("temperature_true_fitted"),
                                       fit=fit_clause(errors, failed)),
                          folder / TEMPERATURE_FIGURE, entropy_variables=x[:, idx],
                          temperature=gE[:, idx], names=np.array(entropies), **true)
        bar.update()


@eqx.filter_jit
def _pair_residuals(model, scheme, x0, x1, dt):
    """The scheme's residual of every pair (compiled once: op by op, each operation of the
    model would compile on its own)."""
    t0, t1 = jax.vmap(model.terms)(x0), jax.vmap(model.terms)(x1)
    return jax.vmap(scheme.residual, in_axes=(None, 0, 0, 0, 0, 0))(model, x0, x1, dt, t0, t1)
