r"""What float32 states lose of the data: a variable far from zero that moves little between
samples (an entropy saved as :math:`s + 10^4`) is rounded in float32 to a spacing that is
a fair share of its change over one step, and the residual
:math:`2(x_{n+1} - x_n)/\Delta t - \dots` turns that rounding into noise on the rates, which
training fits as data.

Measured on the zoo's damped oscillator with its bath entropy offset (defaults, standardised
rollout error; 1.4e-3 without the offset): at an offset of 1e4 (:func:`float32_rounding`
6.2e-2) float32 training reached 1.2e-2 and 9.8e-3 (two seeds), float64 2.2e-3 and 1.9e-3;
at 1e3 (3.9e-3) 4.0e-3 and 3.6e-3; the zoo's spinning satellite (2.9e-3) 1.49e-3 and
1.50e-3, its charged particle (1.1e-2) 1.90e-2 and 2.23e-2: no gain beyond the 2× that
separates one training from the next below :data:`FLOAT32_ROUNDING_LIMIT`, where float64's
slower steps only cost time (docs/measurements.md, *Float32 rounding of the states*).
``metriplex train`` therefore trains in float64 where the rounding exceeds it
(:func:`needs_float64`)."""

from __future__ import annotations

import numpy as np

from .data import Pairs, state_scale, time_scale

#: The float32 rounding of the states, as noise on the rates the training fits
#: (:func:`float32_rounding`), above which ``metriplex train`` trains in float64 by default.
FLOAT32_ROUNDING_LIMIT = 2e-2


def float32_rounding(pairs: Pairs) -> np.ndarray:
    r"""Per variable, the spacing of float32 numbers at its largest magnitude in the data,
    as a rate over a typical step, in the units every loss term is measured in: the spacing
    over the variable's standard deviation :math:`d_i`, times the data's time scale
    :math:`\tau` (:func:`~metriplex.data.time_scale`) over the median step
    :math:`\Delta t`. A rate of the data is of order 1 in these units, so this is the share
    of a typical rate that rounding the states to float32 can change. 0 for a variable whose
    values are float32 numbers already (stored so: float64 training would not restore what is
    lost) or that never changes."""
    x0, x1 = np.asarray(pairs.x0, np.float64), np.asarray(pairs.x1, np.float64)
    if x0.shape[0] == 0:
        return np.zeros(x0.shape[1:])
    d = state_scale(x0, x1)
    top = np.maximum(np.max(np.abs(x0), axis=0), np.max(np.abs(x1), axis=0))
    spacing = np.spacing(top.astype(np.float32)).astype(np.float64)
    per_step = time_scale(pairs, d) / float(np.median(pairs.dt))
    moving = np.any(x1 != x0, axis=0)
    stored = np.all(x0 == x0.astype(np.float32), axis=0) & np.all(
        x1 == x1.astype(np.float32), axis=0)
    return np.where(moving & ~stored, spacing / d * per_step, 0.0)


def needs_float64(pairs: Pairs, names: tuple[str, ...]) -> str | None:
    """Why ``pairs`` need float64 training, in a sentence that names the variable float32
    rounds most and by how much (``None`` where no variable's rounding exceeds
    :data:`FLOAT32_ROUNDING_LIMIT`)."""
    share = float32_rounding(pairs)
    if not share.size or share.max() <= FLOAT32_ROUNDING_LIMIT:
        return None
    i = int(np.argmax(share))
    top = float(max(np.max(np.abs(pairs.x0[:, i])), np.max(np.abs(pairs.x1[:, i]))))
    over = int(np.sum(share > FLOAT32_ROUNDING_LIMIT))
    others = f" (and {over - 1} more)" if over > 1 else ""
    return (f"float32 would round {names[i]!r}{others}, whose values reach {top:.3g}, to "
            f"{float(np.spacing(np.float32(top))):.2g}, noise of {100 * share[i]:.2g} % of a "
            "typical rate over one step, which the training would fit as data")
