r"""The verdict: are these data consistent with a GENERIC model?

A fitted GENERIC model can only be as good as the data allow: noise and the time step leave a
residual floor that no model beats. We measure that floor with a **black box of the same
capacity**: an unconstrained MLP vector field :math:`\dot x = f_\theta(x)` trained with the same
Crank–Nicolson pair loss on the same trajectories. Both are then scored on the same held-out
trajectories:

.. math:: \rho = \frac{\text{residual of the GENERIC model}}{\text{residual of the black box}}.

The floor is the larger of the black box's residual and ``tolerance`` (default 1e-3) times the
power of the observed rates :math:`|\Delta x/\Delta t|^2`: below it, residual differences are
what training budgets, not structure, decide.

If :math:`\rho` is close to 1 the GENERIC structure costs nothing — the data are consistent with
it (**yes**). If the GENERIC model is much worse (:math:`\rho >` ``threshold``, default 3) the
structure cannot represent the dynamics (**no**), and we say which law the data break, using
the black box's vector field (which follows the data) and the learned :math:`E` and :math:`S`:

- first law: :math:`\nabla E\cdot f_\theta \neq 0` (energy not conserved);
- second law: :math:`\nabla S\cdot f_\theta < 0` (entropy would have to decrease);
- the variables whose residual the structure cannot remove.

The verdict holds for the structure that was fitted: with ``S = s`` given, data whose ``s``
decreases are not GENERIC, even though another entropy might exist.
"""

from __future__ import annotations

from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np

from ._model import GenericModel, Terms, float_dtype, with_dtype
from .data import Trajectories, state_scale
from .losses import CrankNicolsonResidual
from .structure._mlp import Hidden, standardise
from .structure.potential import ZeroPotential


class BlackBoxModel(eqx.Module):
    r"""An unconstrained vector field :math:`\dot x = f_\theta(x)` (an MLP), trainable with
    :func:`metriplex.fit` and the same pair losses. It is not GENERIC: it measures the residual
    floor of the data."""

    hidden: Hidden
    out: eqx.nn.Linear
    n: int = eqx.field(static=True)
    shift: tuple[float, ...] = eqx.field(static=True)
    scale: tuple[float, ...] = eqx.field(static=True)
    energy: ZeroPotential
    entropy: ZeroPotential

    def __init__(self, n, *, width=64, depth=2, data, key):
        from .structure._mlp import data_statistics

        k1, k2 = jr.split(key)
        self.n = n
        self.shift, self.scale = data_statistics(np.asarray(data))
        self.hidden = Hidden(n, width, depth, "softplus", key=k1)
        self.out = eqx.nn.Linear(width, n, key=k2)
        self.energy = ZeroPotential()
        self.entropy = ZeroPotential()

    def vector_field(self, x):
        z = standardise(x, self.shift, self.scale)
        return self.out(self.hidden(z)) * jnp.asarray(self.scale, x.dtype)

    def terms(self, x) -> Terms:
        # Expressed as Terms with L = I and grad E = f, so every pair loss applies unchanged.
        zero = jnp.zeros((), x.dtype)
        eye = jnp.eye(self.n, dtype=x.dtype)
        return Terms(zero, zero, self.vector_field(x), jnp.zeros_like(x), eye, 0.0 * eye)

    def poisson_matrix(self, x):
        return jnp.zeros((self.n, self.n), x.dtype)


def _residuals(model, pairs, scale, dtype) -> np.ndarray:
    """Per-pair, per-variable Crank–Nicolson residual in standardised units."""
    x0, x1, dt = (jnp.asarray(a, dtype) for a in pairs)
    f0 = jax.vmap(model.vector_field)(x0)
    f1 = jax.vmap(model.vector_field)(x1)
    r = (x1 - x0) / dt[:, None] - 0.5 * (f0 + f1)
    return np.asarray(r, dtype=np.float64) / scale[None, :]


def verdict(
    model: GenericModel,
    data: Trajectories,
    *,
    width: int = 64,
    depth: int = 2,
    steps: int = 3000,
    learning_rate: float = 3e-3,
    batch_size: int = 256,
    threshold: float = 3.0,
    tolerance: float = 1e-3,
    validation: float = 0.2,
    seed: int = 0,
    progress: bool = False,
) -> dict[str, Any]:
    """Is ``data`` consistent with the GENERIC ``model``? See the module docstring.

    Trains a black box on ``1 - validation`` of the trajectories of ``data`` and scores both
    models on the rest. Returns a JSON-able dict with ``consistent`` (bool), ``ratio``, the two
    residuals, per-variable excess and the violated laws.
    """
    from .train import fit

    train, valid = data.split(validation, seed=seed)
    held = valid if valid is not None else train
    scale = state_scale(train.x)
    dtype = float_dtype(model)
    box = BlackBoxModel(data.n, width=width, depth=depth, data=train.x, key=jr.key(seed))
    box = with_dtype(box, dtype)
    box, _ = fit(box, train, loss=CrankNicolsonResidual(), steps=steps, batch_size=batch_size,
                 learning_rate=learning_rate, validation=None, scale=scale, dtype=dtype,
                 progress=progress, key=jr.key(seed + 1))
    pairs = held.pairs()
    r_gen = _residuals(model, pairs, scale, dtype)
    r_box = _residuals(box, pairs, scale, dtype)
    res_gen = float(np.mean(np.sum(r_gen**2, axis=1)))
    res_box = float(np.mean(np.sum(r_box**2, axis=1)))
    # Power of the observed rates, in the same standardised units: residuals below
    # `tolerance` of it are at the level of what a short training reaches on any model.
    rates = (pairs.x1 - pairs.x0) / pairs.dt[:, None] / scale[None, :]
    signal = float(np.mean(np.sum(rates**2, axis=1)))
    floor = max(res_box, tolerance * signal)
    ratio = res_gen / max(floor, 1e-300)
    consistent = bool(ratio <= threshold)

    # Which law do the data break? Judge the black box's field with the learned E and S.
    x = jnp.asarray(held.x, dtype)
    f = np.asarray(jax.vmap(box.vector_field)(x), dtype=np.float64)
    gE = np.asarray(jax.vmap(jax.grad(model.energy))(x), dtype=np.float64)
    gS = np.asarray(jax.vmap(jax.grad(model.entropy))(x), dtype=np.float64)
    fs = f / scale[None, :]
    dE = np.sum(gE * f, axis=1) / np.maximum(
        np.linalg.norm(gE * scale[None, :], axis=1) * np.linalg.norm(fs, axis=1), 1e-300)
    dS = np.sum(gS * f, axis=1)
    dS_scale = np.maximum(np.linalg.norm(gS * scale[None, :], axis=1) * np.linalg.norm(fs, axis=1),
                          1e-300)
    dS_rel = dS / dS_scale
    has_S = bool(np.any(np.abs(gS) > 0))
    excess = np.mean(r_gen**2, axis=0) - np.mean(r_box**2, axis=0)
    per_var = {name: float(v) for name, v in zip(data.names, excess)}
    violations = []
    if not consistent:
        if float(np.median(np.abs(dE))) > 0.05:
            violations.append(
                f"first law: the observed flow changes the learned energy (median |dE/dt| = "
                f"{float(np.median(np.abs(dE))):.2g} of its largest possible rate)"
            )
        if has_S and float(np.mean(dS_rel < -0.01)) > 0.1:
            violations.append(
                f"second law: along {100 * float(np.mean(dS_rel < -0.01)):.0f}% of the states the "
                "observed flow decreases the entropy"
            )
        worst = sorted(per_var, key=per_var.get, reverse=True)[:3]
        violations.append(f"the structure cannot fit the variables {', '.join(worst)}")
    sentence = (
        f"consistent with GENERIC: the structured model's residual is {ratio:.2g}x the floor "
        f"(the larger of an unconstrained model's of the same capacity and {tolerance:g} of the "
        f"rates' power; threshold {threshold:g})."
        if consistent
        else f"NOT consistent with GENERIC (as fitted): the structured model's residual is "
        f"{ratio:.2g}x the floor (the larger of an unconstrained model's of the same capacity "
        f"and {tolerance:g} of the rates' power; threshold {threshold:g}); "
        + "; ".join(violations) + "."
    )
    return {
        "consistent": consistent,
        "statement": sentence,
        "ratio": ratio,
        "threshold": threshold,
        "residual_generic": res_gen,
        "residual_black_box": res_box,
        "residual_generic_relative": res_gen / max(signal, 1e-300),
        "residual_black_box_relative": res_box / max(signal, 1e-300),
        "tolerance": tolerance,
        "excess_residual_per_variable": per_var,
        "energy_rate_relative_median": float(np.median(np.abs(dE))),
        "entropy_decreasing_fraction": float(np.mean(dS_rel < -0.01)) if has_S else 0.0,
        "violations": violations,
        "held_out_trajectories": int(len(held)),
    }
