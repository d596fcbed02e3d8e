"""The learned energy along a model's rollouts and along the data, in
:func:`metriplex.evaluate`'s report: how far it moves (``energy_relative_drift``,
``energy_drift_over_data_spread``, ``energy_change_along_data_over_spread``), and whether its
values resolve such moves at all (``energy_rounding_over_data_spread``)."""

from __future__ import annotations

from typing import Any

import numpy as np

from ._roughness import range_beyond_noise

_TINY = 1e-300

#: Above this float rounding of the learned E's values, in units of its spread over the data,
#: E is constant to rounding there: its moves cannot be measured, and the figures that divide
#: by its spread are null. A new-user check's E with L = 0 and S given had collapsed to a
#: spread of about 1e-9 at values near 0.08 (float32 rounding 7e-9, so about 7 spreads): the
#: figure read "moves by 0" beside a warning that E changed by 0.89 of its spread. A trained
#: model's E spans its spread at values of the same order: about 1e-7 in float32.
ENERGY_ROUNDING_LIMIT = 1e-2


def _size_and_spread(values: np.ndarray) -> tuple[float, float] | None:
    """The largest magnitude and the spread of the finite ``values`` (``None``: none is)."""
    finite = values[np.isfinite(values)]
    if finite.size == 0:
        return None
    return float(np.max(np.abs(finite))), float(np.ptp(finite))


def energy_rounding(E_data: np.ndarray, dtype: Any) -> float:
    """The float rounding (``dtype``'s spacing) of the learned energy at its largest value over
    the data ``E_data``, in units of its spread there; inf where E is the same number
    everywhere, 0 included (values that are not finite are ignored)."""
    measured = _size_and_spread(E_data)
    if measured is None:
        return float("nan")
    size, spread = measured
    return float(np.finfo(dtype).eps) * size / spread if spread > 0 else float("inf")


def energy_figures(E: np.ndarray, E_data: np.ndarray, ts: np.ndarray, lengths: np.ndarray,
                   failed: np.ndarray, dtype: Any, null_reasons: dict[str, str],
                   no_steps: str) -> dict[str, float | None]:
    """The report's energy figures from the learned E along the rollouts ``E`` and along the
    data ``E_data`` (both ``(K, T)``, at times ``ts``; ``lengths`` and ``failed``: each
    trajectory's length and failed step, -1 where it completed), computed in ``dtype``. A
    figure that cannot be given is ``None``, with its reason in ``null_reasons`` (``no_steps``
    where no rollout ran two steps)."""
    data = np.concatenate([E_data[k, :T] for k, T in enumerate(lengths)])
    spread = float(np.ptp(data))
    drifts, drifts_gauge = [], []
    for k, T in enumerate(lengths):
        if failed[k] >= 0:
            T = min(int(failed[k]), int(T))
        if T < 2:
            continue
        e = E[k, :T]
        d = float(np.max(np.abs(e - e[0])))
        # Relative to |E(x0)|, but never to less than E's spread over the data: the learned
        # energy's offset is arbitrary, and an exact model starting near E = 0 read as 85.
        drifts.append(d / max(abs(float(e[0])), spread, _TINY))
        drifts_gauge.append(d / max(spread, _TINY))
    rounding = energy_rounding(data, dtype)
    figures: dict[str, float | None] = {
        "energy_relative_drift": max(drifts) if drifts else None,
        "energy_drift_over_data_spread": max(drifts_gauge) if drifts_gauge else None,
        # The most the learned E moves along an observed trajectory beyond noise, over its
        # spread.
        "energy_change_along_data_over_spread": float(max(
            range_beyond_noise(E_data[k, :T], ts[k, :T]) for k, T in enumerate(lengths))
            / max(spread, _TINY)),
    }
    reasons = {"energy_relative_drift": no_steps, "energy_drift_over_data_spread": no_steps,
               "energy_change_along_data_over_spread": "the learned E is not finite at the data"}
    if rounding > ENERGY_ROUNDING_LIMIT:  # finite: so some values are
        size, spread = _size_and_spread(data)
        why = (f"the learned E is constant over the data to {np.dtype(dtype).name} rounding "
               f"(it spans {spread:.2g} at values up to {size:.2g}, rounded to "
               f"{float(np.finfo(dtype).eps) * size:.2g}): how far it moves cannot be measured")
        reasons = dict.fromkeys(reasons, why)
        figures = dict.fromkeys(figures)
    # The float rounding of E's values in units of its spread over the data (about 1e-7 in
    # float32 for a trained E; inf for a constant E): above ENERGY_ROUNDING_LIMIT the figures
    # above are null.
    figures["energy_rounding_over_data_spread"] = rounding
    reasons["energy_rounding_over_data_spread"] = (
        "the learned E is not finite at the data" if np.isnan(rounding)
        else "the learned E is the same number at every state of the data")  # inf
    for key, value in figures.items():
        if value is None or not np.isfinite(value):
            null_reasons[key] = reasons[key]
        figures[key] = None if value is None else float(value)
    return figures
