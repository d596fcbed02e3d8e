"""Trajectories in MATLAB ``.mat`` files: the observations of the long table of
docs/design.md, 'Trajectory data' (rows of ``trajectory``, ``t``, ``x``), laid out the way
MATLAB users already store them. Read from v4/v5/v7 (via :func:`scipy.io.loadmat`) and v7.3
(via ``h5py``; both in :mod:`metriplex.io._mat_load`) in two layouts, written as v5; shapes
are MATLAB's ``size()``:

1. *Snapshots* — the layout of the published structure-preserving-network (SPNN) datasets
   (``Z``, ``t_vec``, ``dt``, ``L``, ``M``): one array of trajectories × variables × snapshots,
   ``(K, n, T)``, or variables × snapshots ``(n, T)`` for one trajectory, named one of
   ``Z, z, X, x, data, states, yout`` (stored the other way round, ``(K, T, n)`` or ``(T, n)``, it
   is read so where its time vector's length says so). Times come from a vector named one of
   ``t_vec, tvec, t, time, times, ts, tout`` (Simulink's ``tout`` and ``yout`` read as they
   are) — shared ``(T,)``/``(1, T)``/``(T, 1)`` or per trajectory
   ``(K, T)`` — or from a step named one of ``dt, Dt, DT, delta_t`` (scalar, or ``(K,)`` per
   trajectory; times are then ``0, dt, 2 dt, ...``). With both, the vector is used and the step
   must match its spacing (to 0.1 %). ``dt=STEP`` (the command line's ``--dt``) replaces all of
   these by ``0, STEP, 2 STEP, ...``: for a file without times, or whose time vector does not
   fit its snapshots (e.g. 1 × 150 for 300 snapshots). Optional: ``trajectory_ids`` ``(K,)``;
   constant operators ``L`` and ``M`` ``(n, n)``, dense or sparse (see
   :func:`read_mat_operators`).
2. *Long table* — the layout of docs/design.md, 'Trajectory data': ``trajectory`` ``(N,)``,
   ``t`` ``(N,)``, ``x`` ``(N, n)``; ragged lengths allowed (with ``dt``, ``t`` is not read).

In both, variable names are an optional cell array of strings (or a char matrix) named one of
``names, var_names, variables, labels``. When the file's top level holds none of these
variables but exactly one struct, its fields are read instead (``data.Z``, ``data.dt``, ...).
:func:`write_mat` writes the snapshot layout when all trajectories have the same length and the
long table otherwise, so both round-trip exactly.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from .._errors import MetriplexError
from ..data import Trajectories, uniform_times
from ._checks import (STEP_KEYS, _build, _check_file, _found, _q, _real, _shape, _strings,
                      _vector)
from ._files import atomic_write
from ._mat_load import _load_mat

STATE_KEYS = ("Z", "z", "X", "x", "data", "states", "yout")
TIME_KEYS = ("t_vec", "tvec", "t", "time", "times", "ts", "tout")
NAME_KEYS = ("names", "var_names", "variables", "labels")
OPERATOR_KEYS = ("L", "M")


def read_mat(
    path: str | os.PathLike,
    *,
    states: str | None = None,
    time: str | None = None,
    dt: float | None = None,
) -> Trajectories:
    """Read trajectories from a MATLAB ``.mat`` file (layouts in this module's docstring).

    ``states`` and ``time`` name the variables to use when the file's names are not among the
    accepted ones or are ambiguous. ``dt`` gives every trajectory the uniform grid
    ``t = k * dt`` instead of the file's times, which are then not read: for a file that stores
    none, or a time vector that does not fit the snapshots (the command line's ``--dt``).

    ```python
    data = mx.read("database_double_pendulum.mat")
    data = read_mat("sim.mat", states="Y", time="tout")
    ```
    """
    path = _check_file(path, "MAT")
    scope, where = _mat_scope(_load_mat(path), path, states)
    traj, t, x, names = _mat_table(scope, where, states=states, time=time, dt=dt)
    return _build(path, "MAT", traj, t, x, names)


def read_mat_operators(
    path: str | os.PathLike, *, states: str | None = None
) -> dict[str, np.ndarray]:
    r"""The constant GENERIC operators stored beside the data: ``{"L": (n, n), "M": (n, n)}``.

    Published SPNN datasets store the Poisson matrix ``L`` and friction matrix ``M`` of
    :math:`\dot z = L\nabla E + M\nabla S`. Keys are present only for the operators in the
    file; the dict is empty when there are none. Shapes are checked against the state array.

    ```python
    ops = read_mat_operators("database_double_pendulum.mat")
    L = ops.get("L")
    ```
    """
    path = _check_file(path, "MAT")
    scope, where = _mat_scope(_load_mat(path), path, states)
    _, _, x, _ = _mat_table(scope, where, states=states, time=None, dt=1.0)
    n = x.shape[1]
    out = {}
    for key in OPERATOR_KEYS:
        if key not in scope:
            continue
        a = _real(scope[key], f"operator `{key}`", where)
        if a.shape != (n, n):
            raise MetriplexError(
                f"operator `{key}` in {where} is {_shape(a)}; with {n} state variables it must "
                f"be {n}×{n}."
            )
        if not np.all(np.isfinite(a)):
            raise MetriplexError(
                f"operator `{key}` in {where} holds NaN or inf; it must be finite."
            )
        out[key] = a
    return out


def write_mat(
    path: str | os.PathLike,
    data: Trajectories,
    *,
    L: np.ndarray | None = None,
    M: np.ndarray | None = None,
) -> None:
    """Write ``data`` as a MATLAB v5 ``.mat`` file (atomically).

    Equal-length trajectories are written in the SPNN snapshot layout — ``Z`` (K, n, T),
    ``t_vec`` (1, T) when all share one grid (plus ``dt`` when it is uniform) or ``t`` (K, T)
    otherwise — so MATLAB scripts and SPNN code can read them; ragged ones as the long table.
    Both carry ``names`` (cell array) and are read back exactly by :func:`read_mat`.
    """
    import scipy.io

    out: dict[str, Any] = {"names": np.array(list(data.names), dtype=object).reshape(1, -1)}
    lengths = data.lengths()
    if np.all(lengths == lengths[0]):
        # Rows are sorted by trajectory id (Trajectories guarantees it): reshape, no copy loop.
        K, T = len(lengths), int(lengths[0])
        ts, xs = data.t.reshape(K, T), data.x.reshape(K, T, data.n)
        out["Z"] = np.ascontiguousarray(xs.transpose(0, 2, 1))
        out["trajectory_ids"] = data.ids.astype(np.float64).reshape(1, -1)
        if np.all(ts == ts[0]):
            out["t_vec"] = ts[:1]
            steps = np.diff(ts[0])
            if np.all(np.abs(steps - steps.mean()) <= 1e-12 * abs(steps.mean())):
                out["dt"] = np.array([[steps.mean()]])
        else:
            out["t"] = ts
    else:
        out["trajectory"] = data.trajectory.astype(np.float64).reshape(-1, 1)
        out["t"] = data.t.reshape(-1, 1)
        out["x"] = data.x
    n = data.n
    for key, op in (("L", L), ("M", M)):
        if op is not None:
            op = np.asarray(op, dtype=np.float64)
            if op.shape != (n, n):
                raise MetriplexError(
                    f"operator `{key}` must be {n}×{n} for {n} state variables; got "
                    f"{_shape(op)}."
                )
            out[key] = op
    with atomic_write(path, "wb") as f:
        scipy.io.savemat(f, out, format="5", do_compression=True, oned_as="row")


def _mat_scope(variables: dict, path: Path, states: str | None) -> tuple[dict, str]:
    """The variables holding the data: the top level, or the fields of its only struct."""
    where = f"MAT file {_q(path)}"
    if not variables:
        raise MetriplexError(f"{where} holds no variables; it holds no trajectories.")
    wanted = (states,) if states else STATE_KEYS + ("trajectory",)
    if any(k in variables and not isinstance(variables[k], dict) for k in wanted):
        return variables, where
    structs = [k for k, v in variables.items() if isinstance(v, dict)]
    if len(structs) == 1:
        return variables[structs[0]], f"struct `{structs[0]}` of {where}"
    return variables, where


def _pick(
    scope: dict, keys: Sequence[str], override: str | None, what: str, where: str,
    option: str | None = None,
):
    """The one variable among ``keys`` present in ``scope`` (or ``override``), or None.

    ``option`` is the read_mat keyword that names the variable, suggested when several are
    present.
    """
    if override is not None:
        if override not in scope:
            raise MetriplexError(
                f"{where} has no variable {override!r} (asked for as {what}); it holds "
                f"{_found(scope)}."
            )
        return override
    present = [k for k in keys if k in scope and not isinstance(scope[k], dict)]
    if len(present) > 1:
        fix = (
            f"Name the one to use, e.g. read_mat(path, {option}={present[0]!r}) in Python; for "
            f"the command line keep one under that name (MATLAB: save(file, {present[0]!r}, "
            "...) with the others left out)."
            if option else "Rename or remove all but one."
        )
        raise MetriplexError(f"{where} holds several candidates for {what}: {present}. {fix}")
    return present[0] if present else None


def _mat_table(scope: dict, where: str, *, states, time, dt):
    """``(trajectory, t, x, names)`` rows from the variables of a MAT file."""
    names_key = _pick(scope, NAME_KEYS, None, "the variable names", where)
    names = _strings(scope[names_key], f"`{names_key}`", where) if names_key else []
    if states is None and "trajectory" in scope:
        return (*_mat_long_table(scope, where, dt), names)
    key = _pick(scope, STATE_KEYS, states, "the state array", where, "states")
    if key is None:
        cells = [k for k, v in scope.items() if getattr(v, "dtype", None) == object]
        fix = ("Rename the variable (MATLAB: Z = NAME; save(file, 'Z', 't')) or, in Python, "
               "pass read_mat(path, states='NAME')")
        if cells:  # renaming a cell array only moves the refusal
            fix = (f"`{cells[0]}` is a cell array, which is not read: stack it into one numeric "
                   "trajectories × variables × snapshots array (MATLAB, for cells of snapshots "
                   f"× variables: Z = permute(cat(3, {cells[0]}{{:}}), [3 2 1]); save(file, 'Z', "
                   "'t'))")
        raise MetriplexError(
            f"{where} holds no state array: expected a trajectories × variables × snapshots "
            f"array named one of {', '.join(STATE_KEYS)} (or the long table `trajectory`, `t`, "
            f"`x`); it holds {_found(scope)}. {fix}."
        )
    Z = _real(scope[key], f"state array `{key}`", where)
    one = Z.ndim == 2
    if one:
        Z = Z[None]
    if Z.ndim != 3:
        raise MetriplexError(
            f"state array `{key}` in {where} is {_shape(Z)}; it must be trajectories × "
            "variables × snapshots (K×n×T), or variables × snapshots (n×T) for one trajectory."
        )
    if _snapshots_first(scope, Z, time=time, dt=dt):
        Z = Z.transpose(0, 2, 1)
    elif Z.shape[1] > Z.shape[2] > 1 and (dt is not None
                                          or not any(k in scope for k in TIME_KEYS)):
        # Times from a step alone cannot tell the layouts apart, and more variables than
        # snapshots is what trajectories × snapshots × variables gives when read as documented
        # (a new-user check: 201 "variables" of 3 samples, and train then asked for 6 GB).
        K, a, b = Z.shape
        shape, layout, fix = ((f"{a}×{b}", "variables × snapshots", f"Z = {key}.'") if one else
                              (f"{K}×{a}×{b}", "trajectories × variables × snapshots",
                               f"Z = permute({key}, [1 3 2])"))
        raise MetriplexError(
            f"state array `{key}` in {where} is {shape} with times from a step alone: read as "
            f"{layout} it has {a} variables and only {b} snapshots, which is what the other "
            f"order (snapshots before variables) looks like. Store it as {layout} (MATLAB: "
            f"{fix}), or add a time vector `t` of its snapshots (then its length tells the "
            "layouts apart)."
        )
    K, n, T = Z.shape
    t = _mat_times(scope, where, key, Z.shape, time=time, dt=dt)
    ids = np.arange(K, dtype=np.float64)
    if "trajectory_ids" in scope:
        ids = _vector(_real(scope["trajectory_ids"], "`trajectory_ids`", where),
                      "`trajectory_ids`", where, K)
    traj = np.repeat(ids, T)
    x = Z.transpose(0, 2, 1).reshape(K * T, n)
    if names and len(names) != n:
        raise MetriplexError(
            f"`{names_key}` in {where} lists {len(names)} names {names} but state array `{key}` "
            f"has {n} variables (its second dimension); give one name per variable."
        )
    return traj, t.reshape(-1), x, names


def _snapshots_first(scope, Z, *, time, dt) -> bool:
    """Whether ``Z`` is stored trajectories × snapshots × variables (numpy's habit), as its
    time vector says: one that fits the second dimension and not the third (with ``dt`` or a
    step alone nothing tells, and ``train``'s data summary warns where the snapshots are
    fewer than the variables)."""
    K, a, b = Z.shape
    key = time if time is not None else next((k for k in TIME_KEYS if k in scope), None)
    if dt is not None or a == b or key not in scope:
        return False
    tv = np.asarray(scope[key])
    if tv.dtype.kind not in "iuf" or tv.size == 0:
        return False

    def fits(T):
        return (tv.size == T and sum(s != 1 for s in tv.shape) <= 1) or tv.shape == (K, T)

    return fits(a) and not fits(b)


#: The way out when a file's times do not fit its states, in the words of both front ends.
DT_FIX = ("pass --dt STEP on the command line (read(path, dt=STEP) or read_mat(path, dt=STEP) "
          "in Python) to use the uniform grid t = k*STEP instead of the file's times")


def _mat_times(scope, where, key, shape, *, time, dt):
    K, n, T = shape
    if dt is not None:  # replaces whatever times the file holds, which are not read
        if time is not None:
            raise MetriplexError(
                f"time={time!r} names the time vector of {where} and dt={dt!r} replaces the "
                "file's times by a uniform grid; got both. Give one of them."
            )
        step = float(dt)
        if not np.isfinite(step) or step <= 0:
            raise MetriplexError(f"dt must be positive and finite; got {dt!r}.")
        return np.broadcast_to(step * np.arange(T), (K, T))
    t_key = _pick(scope, TIME_KEYS, time, "the time vector", where, "time")
    step_key = _pick(scope, STEP_KEYS, None, "the time step", where)
    step = None
    if step_key is not None:
        step = _vector(_real(scope[step_key], f"time step `{step_key}`", where),
                       f"time step `{step_key}`", where)
        if len(step) not in (1, K):
            raise MetriplexError(
                f"time step `{step_key}` in {where} has {len(step)} entries; give one step, or "
                f"one per trajectory ({K})."
            )
        if not np.all(np.isfinite(step)) or np.any(step <= 0):
            raise MetriplexError(
                f"time step `{step_key}` in {where} must be positive and finite; got "
                f"{step.tolist()[:5]}."
            )
    if t_key is None:
        if step is None:
            raise MetriplexError(
                f"{where} gives no times for state array `{key}`: expected a time vector named "
                f"one of {', '.join(TIME_KEYS)} or a time step named one of "
                f"{', '.join(STEP_KEYS)}; it holds {_found(scope)}. Add one, or {DT_FIX}."
            )
        return np.broadcast_to(step.reshape(-1, 1) * np.arange(T), (K, T))
    tv = _real(scope[t_key], f"time vector `{t_key}`", where)
    if tv.size == T and sum(s != 1 for s in tv.shape) <= 1:
        t = np.broadcast_to(tv.reshape(1, T), (K, T))
    elif tv.shape == (K, T):
        t = tv
    elif tv.size == K and K != T and sum(s != 1 for s in tv.shape) <= 1:
        # The stack of ode45 outputs, X(:, :, k) = [q p s]: snapshots × variables ×
        # trajectories. --dt would read it as K trajectories of the K states at one time.
        raise MetriplexError(
            f"time vector `{t_key}` in {where} has {tv.size} entries, the first dimension of "
            f"state array `{key}` ({K}×{n}×{T}): it seems stored snapshots × variables × "
            f"trajectories (MATLAB's X(:, :, k) = [...] for trajectory k). Store it as "
            f"trajectories × variables × snapshots (MATLAB: Z = permute({key}, [3 2 1]); "
            "save(file, 'Z', 't'))."
        )
    else:
        raise MetriplexError(
            f"time vector `{t_key}` in {where} is {_shape(tv)}; state array `{key}` "
            f"({K}×{n}×{T}) has {T} snapshots, so it must have {T} entries (shared) or be "
            f"{K}×{T} (one row per trajectory); a vector of {n} entries would have read it as "
            f"trajectories × snapshots × variables. If the snapshots are evenly spaced, "
            f"{DT_FIX}."
        )
    if step is not None and T > 1:
        steps = np.diff(t, axis=1)
        expect = np.broadcast_to(step.reshape(-1, 1), steps.shape)
        bad = np.abs(steps - expect) > 1e-3 * np.abs(expect)
        if np.all(np.isfinite(steps)) and np.any(bad):
            k, j = np.argwhere(bad)[0]
            raise MetriplexError(
                f"time step `{step_key}`={float(expect[k, j])!r} in {where} disagrees with time "
                f"vector `{t_key}`, whose step {j} in trajectory {k} is {float(steps[k, j])!r}. "
                "Remove the wrong one (the time vector is used when both are present), or "
                f"{DT_FIX}."
            )
    return t


def _mat_long_table(scope: dict, where: str, dt: float | None = None):
    missing = [k for k in ("t", "x") if k not in scope and (dt is None or k != "t")]
    if missing:
        raise MetriplexError(
            f"{where} holds `trajectory`, so it is read as the long table, which needs "
            f"`trajectory` (N), `t` (N) and `x` (N×n); `{'`, `'.join(missing)}` is missing. It "
            f"holds {_found(scope)}."
        )
    traj = _real(scope["trajectory"], "`trajectory`", where)
    traj = _vector(traj, "`trajectory`", where)
    if dt is None:
        t = _vector(_real(scope["t"], "`t`", where), "`t`", where, len(traj))
    else:
        t = uniform_times(traj, dt)
    x = _real(scope["x"], "`x`", where)
    if x.ndim == 1 or (x.shape == (1, len(traj)) and len(traj) > 1):
        x = x.reshape(-1, 1)  # one variable stored as a row vector
    if x.ndim != 2 or x.shape[0] != len(traj):
        hint = " It looks transposed: store x.'." if x.ndim == 2 and x.shape[1] == len(traj) else ""
        raise MetriplexError(
            f"`x` in {where} is {_shape(x)}; with {len(traj)} rows in `trajectory` it must be "
            f"{len(traj)}×n, one row per observed state.{hint}"
        )
    return traj, t, x
