r"""The reference experiments of "Learning the GENERIC evolution", end to end.

Each experiment generates ground-truth training data and **unseen** test trajectories (other
initial conditions), trains with its preset structure, evaluates on the test trajectories and
writes the run folder with ``metrics.json`` and figures (each with its raw data):

```bash
metriplex reproduce pendulum-energetic --out runs/pendulum-energetic
```

``--quick`` runs a reduced version (small data, short training) in well under two minutes.
"""

from __future__ import annotations

import dataclasses
import math
import sys
import time
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from .. import plots
from ..._errors import MetriplexError
from ..._model import weights, with_dtype
from .._presets import EXPERIMENTS, Experiment, Size
from ..config import PRESETS, RunConfig, preset, scheme_from_name

#: The settings that describe what is learned and what is given (``run_experiment(defaults=True)``
#: keeps only these from a preset).
STRUCTURE_KEYS = ("energy", "entropy", "poisson", "friction", "jacobi")
from ...data import state_statistics
from ...diagnostics import (energy_entropy_along, evaluate, potential_along, rollout_data,
                             time_to_error)
from ..._standardised import standardised_error_over_time
from ...integrate import CrankNicolson
from ...io import write, write_json
from .._warnings import structure_warnings
from .._report import Truth, report_figures
from ..._structure_check import _terms_at
from ..runs import run_config, run_verdict, train_run, trained_scheme


def _check_name(name: str) -> Experiment:
    if name not in EXPERIMENTS:
        raise MetriplexError(
            f"unknown experiment {name!r}; choose one of {', '.join(EXPERIMENTS)}."
        )
    return EXPERIMENTS[name]


def affine_fit(true_vals: np.ndarray, learned: np.ndarray) -> dict[str, float]:
    """Best ``learned ~ a * true + b`` (least squares): slope, offset, R^2, relative residual."""
    A = np.c_[true_vals, np.ones_like(true_vals)]
    coef, *_ = np.linalg.lstsq(A, learned, rcond=None)
    resid = learned - A @ coef
    ss = float(np.sum((learned - learned.mean()) ** 2))
    return {
        "slope": float(coef[0]),
        "offset": float(coef[1]),
        "r2": float(1 - np.sum(resid**2) / ss) if ss > 0 else float("nan"),
        "residual_relative": float(np.sqrt(np.mean(resid**2)) / max(np.std(learned), 1e-300)),
    }


def default_out(name: str, *, quick: bool = False, defaults: bool = False) -> Path:
    """The run folder of ``reproduce`` without ``--out``: ``runs/NAME[-defaults][-quick]``."""
    return Path("runs") / (name + ("-defaults" if defaults else "") + ("-quick" if quick else ""))


def _fmt(value: float | None) -> str:
    """A figure for the summary lines; ``null`` where it could not be computed (see
    ``null_reasons`` in metrics.json)."""
    return "null" if value is None else f"{value:.3e}"


def experiment_config(name: str, size: Size, *, quick: bool = False, defaults: bool = False,
                      degeneracy: str | None = None, **overrides: Any) -> RunConfig:
    """The :class:`~metriplex.app.config.RunConfig` that :func:`run_experiment` trains with
    (its arguments of the same names)."""
    exp = _check_name(name)
    if defaults:
        structure = {k: v for k, v in PRESETS[name].items() if k in STRUCTURE_KEYS}
        config = RunConfig(**structure)
        if quick:
            config = dataclasses.replace(config, steps=size.train_steps)
        if degeneracy is not None:
            config = dataclasses.replace(config, degeneracy=degeneracy)
    else:
        config = preset(name, steps=size.train_steps, degeneracy=degeneracy or "soft",
                        eval_every=max(size.train_steps // 50, 10), **exp.overrides)
    return dataclasses.replace(config, **overrides)


def run_experiment(
    name: str,
    *,
    quick: bool = False,
    out: str | Path | None = None,
    overwrite: bool = False,
    degeneracy: str | None = None,
    progress: bool = True,
    size: Size | None = None,
    defaults: bool = False,
    verdict: bool | None = None,
    **overrides: Any,
) -> dict[str, Any]:
    """Run experiment ``name`` end to end; return its metrics (also in ``out/metrics.json``).

    ``degeneracy`` (``"soft"`` or ``"exact"``) replaces how the degeneracies are imposed;
    ``None`` keeps the preset's (soft) or, with ``defaults=True``, the default (``auto``).
    ``size`` replaces the experiment's data and training sizes (e.g. to study coverage);
    ``overrides`` replace fields of its :class:`~metriplex.app.config.RunConfig`. With
    ``defaults=True`` the run uses only the preset's structure (what is learned and what is
    given, and the Jacobi penalty for a learned L) and every other setting at its default, as a
    user without the preset would: no features, default learning rate, steps and schedule.
    ``verdict``: also ask whether the test data are consistent with the learned structure, as
    ``metriplex evaluate`` does (:func:`metriplex.verdict.verdict`; a black-box reference
    trains on the test data, seconds to a minute), printed and kept in ``metrics.json``;
    ``None``: for full runs only (a quick run's training is a step budget, which the verdict
    would report as not converged).
    """
    from ...systems import generate, get_system

    exp = _check_name(name)
    if degeneracy not in (None, "soft", "exact"):
        raise MetriplexError(f"--degeneracy must be soft or exact; got {degeneracy!r}.")
    size = size if size is not None else exp.quick if quick else exp.full
    verdict = not quick if verdict is None else verdict
    out = Path(out) if out is not None else default_out(name, quick=quick, defaults=defaults)
    jax.config.update("jax_enable_x64", True)  # ground truth in float64; training in float32
    system = get_system(exp.system, **exp.system_params)
    t0 = time.perf_counter()
    data = generate(system, trajectories=size.trajectories, steps=size.steps, dt=exp.dt, seed=0)
    test = generate(system, trajectories=size.test_trajectories, steps=size.test_steps,
                    dt=exp.dt, seed=10_000)
    gen_seconds = time.perf_counter() - t0
    config = experiment_config(name, size, quick=quick, defaults=defaults,
                               degeneracy=degeneracy, **overrides)
    model, history, train, valid, seconds = train_run(
        data, config, out, overwrite=overwrite, progress=progress
    )
    write(out / "train_data.npz", data)
    write(out / "test_data.npz", test)
    rollout_scheme = trained_scheme(run_config(out)) if defaults else exp.rollout_scheme
    scheme = scheme_from_name(rollout_scheme)
    horizon = exp.horizon
    # Each model's test rollouts are computed once, for its metrics and for the figures.
    rollout = rollout_data(model, test, scheme=scheme)
    truth_rollout = rollout_data(system.model, test, scheme=CrankNicolson())
    metrics = evaluate(model, test, scheme=scheme, horizon=horizon, rollout=rollout)
    # Of the truth's report only the four figures below are kept: no step check (one more
    # compiled rollout, with a 4x finer step).
    truth = evaluate(jax.tree_util.tree_map(lambda a: a, system.model), test,
                     scheme=CrankNicolson(), horizon=horizon, rollout=truth_rollout,
                     step_check=False)
    metrics["ground_truth_cn"] = {
        k: truth[k] for k in ("rollout_error_mean", "energy_relative_drift", "entropy_min_step",
                              "rollout_error_to_horizon_mean") if k in truth
    }
    metrics.update(
        experiment=name, quick=quick, defaults=defaults,
        degeneracy=config.degeneracy, train_seconds=seconds,
        data_seconds=gen_seconds, train_trajectories=len(train),
        validation_trajectories=0 if valid is None else len(valid),
        test_trajectories=len(test), dt=exp.dt, stopped=history.stopped,
        size=dataclasses.asdict(size), rollout_scheme=rollout_scheme,
        best_step=history.best_step,
    )
    untrained = _untrained_error(config, train, test, scheme, horizon)
    metrics["untrained_rollout_error"] = untrained
    metrics.update(_figures_and_gauge(exp, system, model, test, out / "figures", scheme,
                                      rollout, truth_rollout))
    metrics["bars"] = {
        k: {"target": v, "value": metrics.get(k),
            "met": _met(k, metrics.get(k), v, metrics.get("entropy_step_rounding"))}
        for k, v in exp.bars.items()
    }
    if verdict:
        metrics["verdict"] = run_verdict(out, model, test, metrics, progress=progress)
    write_json(out / "metrics.json", metrics)
    key = "rollout_error_to_horizon_mean" if horizon else "rollout_error_mean"
    still = metrics[key.replace("rollout_error", "constant_prediction_error")]
    print(f"{name}{' (quick)' if quick else ''}: test rollout error {_fmt(metrics[key])} "
          f"(untrained {_fmt(untrained)}; x(t) = x(0) {_fmt(still)}; ground-truth CN "
          f"{_fmt(truth[key])}), learned-energy drift "
          f"{_fmt(metrics['energy_relative_drift_gauge_fixed'])} (gauge-fixed), training "
          f"{seconds:.0f} s -> {out}")
    fit = metrics["energy_gauge_fit"]
    given_L = not weights(model.poisson)  # then E is fixed up to a constant: slope 1
    print(f"  learned E against the true E along the test data: slope {fit['slope']:.3g}"
          f"{' (1 for the exact E: L is given)' if given_L else ''}, r^2 {fit['r2']:.3g}"
          " (figures/energy_fit.png)")
    if quick:
        print("  (the accuracy bars are for full runs; a --quick run only has to beat the "
              "untrained model by a wide margin)")
    for k, b in metrics["bars"].items():
        value = "null (" + metrics.get("null_reasons", {}).get(k, "not computed") + ")" \
            if b["value"] is None else _fmt(b["value"])
        if k == "entropy_min_step" and b["value"] is not None and b["value"] < 0:
            value += f" (rounding of S: {_fmt(metrics.get('entropy_step_rounding'))})"
        print(f"  {k}: {value} vs {'full-run ' if quick else ''}target "
              f"{b['target']:.0e}: {'met' if b['met'] else 'NOT met'}")
    for line in structure_warnings(metrics):
        print(line, file=sys.stderr)
    if verdict:
        print(f"verdict: {metrics['verdict']['statement']}")
    elif quick:
        print(f"  no verdict for a quick run (its training is a step budget); run without "
              f"--quick, or: metriplex evaluate {out} {out / 'test_data.npz'}")
    return metrics


def _met(key, value, target, rounding=None):
    if value is None:
        return False
    if key == "entropy_min_step":  # never decreasing, beyond the rounding of S
        return value >= -(1e-12 if rounding is None else rounding)
    return value <= target


def _untrained_error(config: RunConfig, train, test, scheme, horizon) -> float:
    import jax.random as jr

    from .._build import build_model

    model = build_model(config, train, key=jr.split(jr.key(config.seed))[0])
    model = with_dtype(model, jnp.float32)
    # Only the rollout error is kept: no step check.
    r = evaluate(model, test, scheme=scheme, horizon=horizon, step_check=False)
    v = r["rollout_error_to_horizon_mean"] if horizon else r["rollout_error_mean"]
    return float(v) if math.isfinite(v) else float("inf")


def _energy_drifts(system, model, out, xs, lengths, fit) -> dict[str, float]:
    r"""Energy drift along the learned rollouts, in units that can be compared with the truth.

    The learned :math:`\hat E` is known only up to :math:`\hat E \approx aE + b` (only
    :math:`L\nabla E` is observed), so its raw relative drift :math:`\max|\Delta\hat E| /
    |\hat E(x_0)|` depends on the arbitrary offset :math:`b`. The gauge-fixed drift
    :math:`\max_t|\hat E(x_t) - \hat E(x_0)| / |a| / |E(x_0)|` converts it to true-energy
    units with the slope :math:`a` of the best affine fit; the true energy's drift along the
    learned rollout, :math:`\max_t|E(x_t) - E(x_0)| / |E(x_0)|`, needs no gauge at all.
    """
    pred = np.asarray(out.xs, dtype=np.float64)
    failed = np.asarray(out.failed_step)
    slope = abs(fit["slope"])
    # Both energies at every state of every rollout at once, each one compiled call (op by
    # op, each operation of the model would compile on its own for every length).
    E_learned = potential_along(model, model.energy, pred)
    E_true = potential_along(system.model, system.model.energy, pred)
    E_start = potential_along(system.model, system.model.energy, np.asarray(xs)[:, 0])
    gauge, true = [], []
    for k, T in enumerate(lengths):
        T = int(failed[k]) if failed[k] >= 0 else int(T)
        if T < 2:
            gauge.append(float("inf"))
            true.append(float("inf"))
            continue
        E_l, E_t = E_learned[k, :T], E_true[k, :T]
        E0 = max(abs(float(E_start[k])), 1e-300)
        # Up to a failed step, like evaluate()'s raw drift; failures are counted separately.
        gauge.append(float(np.max(np.abs(E_l - E_l[0]))) / max(slope, 1e-300) / E0)
        true.append(float(np.max(np.abs(E_t - E_t[0]))) / E0)
    return {"energy_relative_drift_gauge_fixed": float(np.max(gauge)),
            "true_energy_relative_drift": float(np.max(true))}


def _figures_and_gauge(exp, system, model, test, folder: Path, scheme, rollout,
                       truth_rollout) -> dict[str, Any]:
    """The figures, the energy and entropy gauge fits and the gauge-fixed drifts, from the
    learned model's and the truth's test rollouts (what ``rollout_data`` returned): the report
    figures of ``train`` and ``evaluate`` with the truth's curves in them
    (:func:`~metriplex.runs.report_figures`), and the figures only a known model allows (the
    gauge fits; the pendulum's positions)."""
    out, xs, lengths = rollout
    k = 0
    T = int(lengths[k])
    ts = np.asarray(out.ts, dtype=np.float64)[k, :T]
    pred = np.asarray(out.xs, dtype=np.float64)[k, :T]
    obs = xs[k, :T]
    result: dict[str, Any] = {}
    if exp.system.startswith("pendulum"):
        upto = None
        if exp.horizon is not None:
            upto = int(np.searchsorted(ts, ts[0] + exp.horizon, side="right"))
        plots.save_figure(
            plots.positions(pred, obs, upto=upto, horizon_label=f"t ≤ {exp.horizon:g}"),
            folder / "positions", learned=pred[:, :4], true=obs[:, :4], t=ts,
        )
        result["time_to_10pct_error"] = [
            time_to_error(np.asarray(out.ts, dtype=np.float64)[j, : lengths[j]],
                          np.asarray(out.xs, dtype=np.float64)[j, : lengths[j]],
                          xs[j, : lengths[j]])
            for j in range(len(lengths))
        ]
    # Learned E and S against the true ones along the test trajectories, after the best
    # affine fit (only L grad E and M grad S are observed: E, S are known up to this gauge).
    x_all = np.asarray(test.x)
    E_l, S_l = energy_entropy_along(model, x_all)
    E_t, S_t = energy_entropy_along(system.model, x_all)
    result["energy_gauge_fit"] = affine_fit(E_t, E_l)
    result.update(_energy_drifts(system, model, out, xs, lengths, result["energy_gauge_fit"]))
    plots.save_figure(plots.gauge_fit(E_t, E_l, label="E"), folder / "energy_fit", true=E_t,
                      learned=E_l)
    if np.std(S_t) > 0:
        result["entropy_gauge_fit"] = affine_fit(S_t, S_l)
        plots.save_figure(plots.gauge_fit(S_t, S_l, label="S"), folder / "entropy_fit",
                          true=S_t, learned=S_l)
    m = test.trajectory == test.ids[k]
    fe, fs = result["energy_gauge_fit"], result.get("entropy_gauge_fit")
    truth_out = truth_rollout[0]
    truth = Truth(
        reference_error=standardised_error_over_time(
            np.asarray(truth_out.xs, dtype=np.float64)[k, :T], obs,
            *state_statistics(np.asarray(test.x))[:2]),
        reference_label="ground truth, Crank–Nicolson at the same dt",
        energy=fe["slope"] * E_t[m] + fe["offset"],
        entropy=None if fs is None else fs["slope"] * S_t[m] + fs["offset"],
        grad_energy=lambda x: fe["slope"] * np.asarray(
            _terms_at(system.model, jnp.asarray(x, jnp.float64)).grad_energy, dtype=np.float64),
    )
    report_figures(model, test, folder, scheme=scheme, k=k, rollout=rollout, truth=truth)
    return result
