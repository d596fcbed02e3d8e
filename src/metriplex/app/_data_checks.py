"""What ``train`` says of its data before training: one line of what was read, and warnings
where the data cannot be what the user meant — time and variables swapped, two recordings
under one trajectory id, a variable recorded twice, a given entropy that falls or never
moves, nothing moving at all.
Each was found read without a word (docs/design.md, *Trajectory data*); none stops training.
And what data given to a trained model must be: its columns (:func:`check_names`)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ._option import entropy_variables
from ._warnings import casimir_note, listing, outlier_warning, still_validation_warning

if TYPE_CHECKING:
    from ..data import Trajectories

#: A step this many times its trajectory's median step is a gap: two recordings joined under one
#: id, or lost samples; the pair across it is fitted like any other.
GAP = 100.0

#: A given entropy falls along a trajectory when its net change is below minus this many times
#: the median size of its steps (noise alone does so on about 2 % of trajectories).
FALL = 3.0


def data_notes(train: Trajectories, valid: Trajectories | None, entropy: str,
               free: tuple[int, ...] | None = None) -> list[str]:
    """The summary line, every warning of this module and the data's warnings of
    :mod:`._warnings` (outliers, a validation part that does not move), for ``train``'s data
    (``entropy``: the ``--entropy`` option), then the note on an S learned of the variables
    ``free`` that a given L leaves free (:func:`._warnings.casimir_note`)."""
    parts = [train] if valid is None else [train, valid]
    return ([data_summary(train, valid)] + few_trajectories_note(train, valid)
            + swapped_axes_warning(parts) + gap_warning(parts) + repeated_column_warning(parts)
            + sample_warnings(train) + still_validation_warning(train, valid)
            + still_data_warning(parts) + entropy_warnings(parts, entropy)
            + temperature_named_warning(train.names, entropy) + casimir_note(free, train))


def temperature_named_warning(names: tuple[str, ...], entropy: str) -> list[str]:
    """A warning where ``--entropy sum:...`` names a variable called as a temperature is
    (``theta``, ``T``, ``temp``, ...): S must be a sum of entropies, and a temperature is none
    (a new-user check's theta, given so, trained to "temperatures dE/d(theta) = 1")."""
    import re

    hot = [f"{names[i]} (column {i})" for i in entropy_variables(entropy) if 0 <= i < len(names)
           and re.fullmatch(r"(theta|θ|t|temp|temperature)_?\d*", names[i].lower())]
    if not hot:
        return []
    return [f"warning: --entropy {entropy} names {', '.join(hot)}, named as a temperature: S "
            "is the sum of those variables, so they must be entropies, and a temperature is "
            "none (its entropy is c ln(theta) + const). If they are temperatures, leave "
            "--entropy out (S learned, as the (q, p, theta) pendulum: metriplex reproduce "
            "pendulum-temperature)."]


def _each(parts: list[Trajectories]):
    """(id, t, x) of every trajectory of every part (a trajectory split in time: both parts)."""
    for part in parts:
        yield from ((tid, t, x) for tid, (t, x) in zip(part.ids, part))


def _names(names) -> str:
    shown = ", ".join(names[:8])
    return shown + (f", ... ({len(names)} in all)" if len(names) > 8 else "")


def _span(values) -> str:
    lo, hi = float(np.min(values)), float(np.max(values))
    return f"{lo:.4g}" if np.isclose(lo, hi, rtol=1e-6) else f"{lo:.4g} to {hi:.4g}"


def split_in_time(train: Trajectories, valid: Trajectories | None) -> bool:
    """Whether the validation part is the end of the training trajectories themselves (a
    trajectory split in time), not trajectories of its own."""
    return valid is not None and set(valid.ids) == set(train.ids)


def data_summary(train: Trajectories, valid: Trajectories | None) -> str:
    """One line: trajectories (to train / to validate), samples each, variables and time steps."""
    k = len(train.ids)
    parts = [train] if valid is None else [train, valid]
    lengths = np.concatenate([p.lengths() for p in parts])
    if split_in_time(train, valid):
        split = (f"{k} trajector{'y' if k == 1 else 'ies'} split in time "
                 f"({_span(train.lengths())} samples to train, the last "
                 f"{_span(valid.lengths())} to validate)")
    else:
        both = "" if valid is None else f" ({k} to train, {len(valid.ids)} to validate)"
        split = f"{k + (0 if valid is None else len(valid.ids))} trajectories{both} of " \
                f"{_span(lengths)} samples"
    steps = np.concatenate([np.diff(t) for _, t, _ in _each(parts)])
    return (f"data: {split}; {train.n} variables ({_names(train.names)}); time steps "
            f"{_span(steps)}")


#: With at most this many training trajectories, train notes that the model learns only the
#: states they visit.
FEW_TRAJECTORIES = 2


def few_trajectories_note(train: Trajectories, valid: Trajectories | None) -> list[str]:
    """A note where training has one or two trajectories: a model learns the states they
    visit, and a held-out error on another one (or on their ends) says little of the states
    from other initial ones (a new-user check: one damped trajectory, held-out 1.6e-3 on its
    end, 0.91 on others)."""
    k = len(train.ids)
    if k > FEW_TRAJECTORIES:
        return []
    held = ("the training data themselves" if valid is None else
            "its validation part, the end of the same trajector" + ("y" if k == 1 else "ies")
            if split_in_time(train, valid) else "the validation trajectories")
    return [f"note: only {k} training trajector{'y' if k == 1 else 'ies'}: the model learns "
            f"the states {'it visits' if k == 1 else 'they visit'}, and from other initial "
            f"states it extrapolates; the error on {held} says little of those. Record more "
            "trajectories from other initial states where you can (evaluate warns where data "
            "reach beyond the training data)."]


def swapped_axes_warning(parts: list[Trajectories]) -> list[str]:
    """Fewer samples per trajectory than variables: most likely an array stored with time and
    variables swapped (a 10 x 100 x 3 array read as 100 variables of 3 samples)."""
    most, n = max(int(np.max(p.lengths())) for p in parts), parts[0].n
    if most >= n:
        return []
    return [f"warning: every trajectory has at most {most} samples but there are {n} "
            "variables: were time and variables swapped when the array was stored? A .mat "
            "array is read as trajectories x variables x snapshots, a .npz `x` as samples x "
            "variables; transpose it, or give the file a time vector of the snapshots' length "
            "(docs/design.md, *Trajectory data*)."]


def gap_warning(parts: list[Trajectories]) -> list[str]:
    """Steps of :data:`GAP` times their trajectory's median step."""
    found = []
    for tid, t, _ in _each(parts):
        if len(t) < 3:
            continue
        dt = np.diff(t)
        typical = float(np.median(dt))
        for k in np.nonzero(dt > GAP * typical)[0] if typical > 0 else ():
            found.append(f"trajectory {tid} from t = {t[k]:.6g} to {t[k + 1]:.6g} "
                         f"({dt[k] / typical:.3g}x its median step {typical:.3g})")
    return [f"warning: {len(found)} time step(s) of more than {GAP:g}x their trajectory's median "
            f"step: {listing(found, 4)}. Two recordings under one trajectory id, or lost "
            "samples? Give each recording its own id: the pair across a gap is fitted like any "
            "other."] if found else []


#: A full turn of an angle in radians and in degrees.
TURNS = {"2 pi": 2.0 * np.pi, "360": 360.0}


def sample_warnings(data: Trajectories, what: str = "training data") -> list[str]:
    """The warnings on samples that are not motion: outliers
    (:func:`._warnings.outlier_warning`) and an angle stored modulo a turn
    (:func:`wrapped_angle_warning`)."""
    return outlier_warning(data, what) + wrapped_angle_warning(data, what)


def wrapped_angle_warning(data: Trajectories, what: str = "training data") -> list[str]:
    """A variable that stays within one turn (2 pi, or 360 for degrees) and jumps by more than
    half a turn in one step, from near one end of its range to near the other, the steps
    beside the jump going the other way, where its median step is under a twentieth of a turn:
    an angle stored modulo a turn. Those jumps are not motion (a resolved motion turns less
    than half a turn a sample), and no smooth field fits the pairs across them."""
    found = []
    for j, name in enumerate(data.names):
        lo, hi = float(np.min(data.x[:, j])), float(np.max(data.x[:, j]))
        median_step = float(np.median(np.abs(np.diff(data.x[:, j]))))
        for label, turn in TURNS.items():
            if not 0.75 * turn <= hi - lo <= turn * (1.0 + 1e-6) or median_step >= turn / 20:
                continue
            jumps = []
            for tid, (t, x) in zip(data.ids, data):
                a, b = x[:-1, j], x[1:, j]
                d = b - a
                wrap = ((np.abs(d) > turn / 2) & (np.minimum(a, b) < lo + turn / 4)
                        & (np.maximum(a, b) > hi - turn / 4))  # one end of the turn to the other
                # ... and the motion goes on the other way round, as it does across a wrap,
                # not on the jump's way, as after a stiff fall.
                sign = np.sign(d)[:, None]
                near = np.sign(np.c_[np.r_[0.0, d[:-1]], np.r_[d[1:], 0.0]])
                wrap &= np.any(near == -sign, axis=1) & ~np.any(near == sign, axis=1)
                jumps += [f"trajectory {tid} at t = {t[k + 1]:.6g}" for k in np.nonzero(wrap)[0]]
            if jumps:
                found.append(f"{name} stays within {lo:.4g} to {hi:.4g} and jumps by more than "
                             f"half a turn ({label}) in {len(jumps)} step(s) "
                             f"({listing(jumps, 3)})")
                break
    return [f"warning: in the {what}, {'; '.join(found)}: an angle stored modulo a full turn? "
            "Such a jump is not motion, and no smooth vector field fits the pairs across it "
            "(a model trained on them is poor everywhere). Unwrap it along each trajectory "
            "before training (numpy.unwrap(q), or numpy.unwrap(q, period=360) in degrees)."
            ] if found else []


def repeated_column_warning(parts: list[Trajectories]) -> list[str]:
    """Two columns with the same values in every sample (not constant): one variable recorded
    twice, which a structure must then keep equal."""
    x = np.concatenate([p.x for p in parts])
    names, found, seen = parts[0].names, [], {}
    for j, key in enumerate(zip(x[0], x[-1], x.sum(axis=0))):  # compared in full only if alike
        same = [i for i in seen.get(key, []) if np.array_equal(x[:, i], x[:, j])]
        if same and np.ptp(x[:, j]) > 0:
            found.append(f"{names[j]} repeats {names[same[0]]}")
        seen.setdefault(key, []).append(j)
    if not found:
        return []
    return [f"warning: {'; '.join(found[:4])} (the same values in every sample): a variable "
            "recorded twice? Drop the copy: the model has to learn to keep the two equal."]


def still_data_warning(parts: list[Trajectories]) -> list[str]:
    """No variable changes along any trajectory: there is no motion to learn."""
    if any(np.ptp(x, axis=0).max() > 0 for _, _, x in _each(parts) if len(x) > 1):
        return []
    return ["warning: no variable changes along any trajectory: there is no motion to learn, "
            "and every model predicts these data exactly. Check that the file holds the "
            "states, not a constant."]


def entropy_warnings(parts: list[Trajectories], entropy: str) -> list[str]:
    """An entropy given as a sum of variables (``--entropy sum:...``) that never changes over
    the data (then M grad S = 0: no friction can act), or that falls along most trajectories
    (a flipped sign; GENERIC's S never decreases)."""
    names = parts[0].names
    idx = [i for i in entropy_variables(entropy) if 0 <= i < len(names)]
    if not idx:
        return []
    what = f"--entropy {entropy} ({', '.join(names[i] for i in idx)})"
    x = np.concatenate([p.x[:, idx] for p in parts])
    if np.all(np.ptp(x, axis=0) == 0):
        return [f"warning: the entropy of {what} does not change anywhere in the data, so S is "
                "constant, M grad S = 0 and the model can have no friction. Name the entropy "
                "variables that move (or --entropy zero for a system without dissipation)."]
    falls, net = 0, []
    for _, _, x in _each(parts):
        s = x[:, idx].sum(axis=1)
        if len(s) < 3:
            continue
        net.append(s[-1] - s[0])
        falls += net[-1] < -FALL * float(np.median(np.abs(np.diff(s))))
    if not net or falls <= len(net) / 2:
        return []
    return [f"warning: the entropy of {what} falls along {falls} of {len(net)} trajectories "
            f"(net change {np.median(net):.3g}, the median), where GENERIC's S never decreases. "
            "Is its sign flipped, or is it not an entropy? No GENERIC model fits that."]


def check_names(run_dir: str | Path, data: Trajectories) -> None:
    """The data must have the columns the model was trained on, in the same order."""
    from ..io import read_header
    from .._errors import MetriplexError

    header = read_header(run_dir)
    n, names = header.get("n"), list(header.get("names", []))
    if n is not None and n != data.n:
        raise MetriplexError(
            f"the data have {data.n} state variables but the model in {str(run_dir)!r} was "
            f"trained on {n} ({', '.join(names)}). Pass data with the same columns."
        )
    if names and list(data.names) != names:
        unknown = [c for c in data.names if c not in names]
        raise MetriplexError(
            f"the data's columns ({', '.join(data.names)}) differ from the model's "
            f"({', '.join(names)})" + (f"; unknown: {', '.join(unknown)}" if unknown else
                                       "; same names in another order") +
            ". Rename or reorder the columns to match the training data."
        )


def operators_note(path: str | Path, poisson: str, friction: str) -> list[str]:
    """A note where a ``.mat`` file holds a constant L or M beside its trajectories (as the
    published GENERIC datasets do) that the run learns instead (``poisson``, ``friction``: the
    run's ``--poisson`` and ``--friction``)."""
    from .._errors import MetriplexError
    from ..io import read_mat_operators

    if Path(path).suffix.lower() != ".mat":
        return []
    try:
        ops = read_mat_operators(path)
    except MetriplexError:
        return []
    unused = [(k, f) for k, f, given in (("L", "--poisson", poisson), ("M", "--friction", friction))
              if k in ops and not given.startswith("file:")]
    if not unused:
        return []
    return [f"note: {str(path)!r} also holds a constant {' and '.join(k for k, _ in unused)}, "
            "which this run learns instead; "
            + " ".join(f"{f} file:{path}" for _, f in unused) + " would use "
            + ("them" if len(unused) > 1 else "it") + " as given."]


#: Above this roughness of clean training pairs (about omega dt = 0.14, 45 samples a period),
#: over the whole trajectories and their second halves, the steps are coarse and train takes
#: the Hermite step: 0.013-0.032 on the zoo's data; outside it, two systems at 0.086 and 0.089
#: were 2.4x and 1.4x more accurate with it, two at 0.07 no more (1.0x, 0.9x); a new-user
#: check's adaptive solver steps (0.16) 22x, another's chain at uneven steps (0.19) 3.5x.
COARSE_STEPS = 0.08
#: Below this noise level (a fraction of each variable's spread) the pairs' roughness is the
#: motion's, not the noise's.
CLEAN = 0.002


#: The training schemes of fourth order, whose error at a coarse step is far smaller.
FOURTH_ORDER = ("rk4", "hermite")
_SCHEME_NAMES = {"cn": "Crank-Nicolson", "midpoint": "implicit-midpoint"}


def coarse_steps(data: Trajectories, spacing: int = 1, scheme: str = "cn") -> float | None:
    """The roughness of ``data``'s pairs ``spacing`` samples apart where their steps are
    coarse for the motion (above ``COARSE_STEPS`` on data with no noise to speak of, over the
    whole trajectories and over their second halves) for a second-order training ``scheme``,
    else ``None``. Motion that stays coarse is what a fourth-order scheme learns better; a
    fast transient that has relaxed by the second half (stiff: a new-user check's 40-cell heat
    rod, roughness 0.28 over the whole, 0.035 over the second halves) is none of its gain."""
    from .._roughness import _spread
    from ..data import noise_level, roughness

    if scheme in FOURTH_ORDER:
        return None
    scale = _spread(data.x)  # the whole data's, for the second halves too
    near = roughness(data, scale, spacing=spacing)
    if near is None or near <= COARSE_STEPS or noise_level(data) >= CLEAN:
        return None
    late = roughness(_second_halves(data), scale, spacing=spacing)
    return near if late is not None and late > COARSE_STEPS else None


def _second_halves(data: Trajectories) -> Trajectories:
    """Each trajectory of ``data`` from its middle sample on."""
    from ..data import Trajectories

    lengths = data.lengths()
    keep = data._positions() >= np.repeat(lengths // 2, lengths)  # place in its trajectory
    return Trajectories(data.trajectory[keep], data.t[keep], data.x[keep], data.names)


def chosen_scheme(coarse: float | None) -> str:
    """The training scheme where none is given: Crank–Nicolson, or the implicit fourth-order
    Hermite step where the training pairs are coarse for their motion (``coarse``: their
    roughness from :func:`coarse_steps`, ``None`` where they are not). On a new-user check's
    adaptive-solver steps (roughness 0.16) a Crank–Nicolson model erred 3.7e-2 on a finer grid,
    a Hermite one 1.7e-3."""
    return "cn" if coarse is None else "hermite"


def coarse_note(coarse: float | None, scheme: str = "cn", chosen: bool = False) -> list[str]:
    """The note that the training pairs' steps are coarse for the motion (``coarse``: their
    roughness from :func:`coarse_steps`, ``None`` where they are not), trained with ``scheme``,
    which the data ``chosen`` (:func:`chosen_scheme`) or the user gave."""
    if coarse is None or (scheme in FOURTH_ORDER and not chosen):
        return []
    said = (f"note: the training pairs' steps are coarse for the motion they record "
            f"(roughness {coarse:.2g}: about {np.sqrt(3.0) * coarse:.2g} radians of its "
            "fastest motion per step, where the data show no noise): ")
    if scheme in FOURTH_ORDER:
        return [said + "training uses the implicit fourth-order Hermite step, whose own error "
                f"at such steps, about {coarse**4 / 0.8:.1g}% of each rate ((omega dt)^4/720), "
                "is learned into the field where Crank-Nicolson's would be "
                f"{coarse * coarse / 4:.1%}; each step costs about three of Crank-Nicolson's "
                "(--scheme cn to train with that; README, Coarse steps)."]
    return [said + f"{_SCHEME_NAMES.get(scheme, scheme)} pairs this far apart fit the map of "
            f"such a step more than the dynamics (the scheme's own error, about "
            f"{coarse * coarse / 4:.1%} of each rate, (omega dt)^2/12, is learned into the "
            "field), so rollouts at these steps can be far more accurate than at finer ones. "
            "--scheme hermite (implicit, fourth order; the default where no --scheme is given) "
            "learns the dynamics at such steps; else sample more finely (README, Coarse "
            "steps)."]


def spacing_note(train: Trajectories, spacing: int, given: int | None) -> list[str]:
    """The note on pairs ``spacing`` samples apart that the data chose (``--every`` not
    ``given``; :func:`metriplex.data.pair_spacing`): their rates are rough as noise makes
    them."""
    from ..data import noise_level, roughness, state_scale

    if given is not None or spacing == 1:
        return []
    d = state_scale(train.x)
    near, apart = roughness(train, d), roughness(train, d, spacing=spacing)
    noise = noise_level(train)
    cause = ("as noise on the states makes them" if noise >= CLEAN else "with no noise on the "
             "states to speak of: motion faster than the samples resolve, such as modes that "
             "relax or turn within a step")  # a new-user check's 40-cell heat rod
    return [f"note: the training data's rates change from one pair to the next {cause} "
            f"(roughness {near:.2g} between neighbouring samples, where noise "
            f"gives 1; {apart:.2g} between samples {spacing} apart; the noise is about "
            f"{noise:.1%} of a variable's standard deviation over the training data, the "
            "median over the variables): "
            f"training uses pairs "
            f"{spacing} samples apart (each trajectory as {spacing} interleaved ones, every "
            "sample still used; README, Noisy data). --every 1 trains on neighbouring samples."]
