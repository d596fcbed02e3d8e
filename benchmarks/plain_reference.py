"""`metriplex train` against a plain JAX step of the same loss (issue #16, deliverable 2).

    .venv/bin/python benchmarks/plain_reference.py --out benchmarks/plain_reference.json
    .venv/bin/python benchmarks/plain_reference.py --quick       # smoke test (one tiny row)
    .venv/bin/python benchmarks/plain_reference.py --configs fully-learned --batches 1024

For every configuration and batch size, in one process and interleaved:

- **metriplex**: the per-step WALL time of ``metriplex train`` as a user runs it, in a
  subprocess: one run of ``--steps 20`` and one of ``--steps 20 + span`` with otherwise
  identical settings (``--eval-every`` equal to the step count, so each run validates exactly
  twice, at step 0 and at its end, and writes one checkpoint; ``--quiet``); per-step time
  ``(t_long - t_short) / span``, so start-up, compilation, the validations, the final
  evaluation and the figures cancel. The issue's method is ``--span 200`` (220 vs 20 steps);
  the default ``--span auto`` takes at least 200 steps, and more where 200 steps take under
  ``--seconds`` (90 s; estimated from metriplex's own compiled chunk in this process), since
  on a loaded machine two process times differ by ten seconds of noise. The data: the double
  thermoelastic pendulum (n = 10), 40 training trajectories of 250 steps (10 000 pairs, so
  batch 8192 is a true batch) and one validation trajectory of 40 steps (``--validation
  0.02`` holds out exactly that one).
- **plain JAX**: the same loss written without tricks, in this process: E, S scalar MLPs and
  the nets of L (n(n-1)/2 outputs, antisymmetric matrix assembled by scatter) and M (B B^T,
  B lower-triangular, assembled by scatter), width 64, depth 2, ``jax.nn.softplus``;
  ``jax.grad`` for every input gradient; the Crank-Nicolson residual
  ``2 (x1 - x0)/dt - f(x0) - f(x1)`` plus the degeneracy penalties |L grad S|^2 and
  |M grad E|^2 at both states of each pair, and the exact Jacobi penalty by ``jax.jacfwd`` of
  L where it applies; ``optax.adam``; one jitted step (random minibatch drawn inside it) called
  in a Python loop, ``block_until_ready`` at the end. Its weights and constants (input
  standardisation, output scales, loss weights, the residual's units) are taken from the model
  and loss that ``metriplex train`` builds for the same data and options, and the script checks
  that both losses agree on a batch before timing, so the two time the same function.

Order per row: compile the plain step (and, as a diagnostic, ``fit``'s own compiled chunk in
this process), metriplex's short run, plain steps (and chunk steps), metriplex's long run,
plain steps (and chunk steps) again; so load changes on a shared machine hit both. Also
reported: the same difference taken on ``train_seconds`` of the runs' metrics.json (fit only,
without start-up and the final evaluation), and the in-process chunk against the plain step.
The machine's load average is printed before and after, and with each row.

The code measured is a snapshot taken at start (``--code head``: the committed ``HEAD``,
default; ``--code tree``: the working tree), used by this process and by every ``metriplex
train`` subprocess, so edits made to the working tree during the run do not change it. Default
XLA threading in both (``XLA_FLAGS`` and the compilation-cache variables are cleared).
"""

from __future__ import annotations

import argparse
import os
import sys

# Parsed before JAX or metriplex are imported: the code snapshot goes first on sys.path.
CONFIG_NAMES = ("fully-learned", "fully-learned+jacobi", "pendulum-energetic",
                "fully-learned+runs", "pendulum-energetic+runs")
DEFAULT_CONFIGS = CONFIG_NAMES[:3]  # the rows; "+runs": the option --consecutive 8


def _parse(argv):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true",
                    help="tiny smoke test: fully-learned, batch 256, 2 vs 7 steps, tiny data")
    ap.add_argument("--configs", default=None,
                    help=f"comma list of configurations from {','.join(CONFIG_NAMES)} (default "
                         f"{','.join(DEFAULT_CONFIGS)})")
    ap.add_argument("--batches", default=None, help="comma list of batch sizes "
                    "(default 256,1024,8192)")
    ap.add_argument("--short", type=int, default=None, help="steps of the short run (default 20)")
    ap.add_argument("--span", default=None,
                    help="steps of the long run minus the short one: a number (200 is the "
                         "issue's 220 - 20), or auto (default): at least 200, and enough that "
                         "the span's steps take --seconds (on a loaded machine the difference "
                         "of two process times is noisy by seconds)")
    ap.add_argument("--seconds", type=float, default=90.0,
                    help="with --span auto: seconds that the span's steps take, as metriplex's "
                         "own chunk runs them in this process (default 90)")
    ap.add_argument("--plain-steps", type=int, default=None,
                    help="plain JAX steps timed in each of its two measurements of a row, at "
                         "least (default 100, and at least 10 s of steps)")
    ap.add_argument("--repeats", type=int, default=1,
                    help="repeat each row's interleaved measurement; medians are reported")
    ap.add_argument("--code", choices=("head", "tree"), default="head",
                    help="measure the committed HEAD (default) or the working tree, as a "
                         "snapshot taken at start")
    ap.add_argument("--out", default=None, help="write the rows and the machine to this JSON")
    ap.add_argument("--keep", default=None,
                    help="keep the data and the run folders in this folder (default: a "
                         "temporary folder, removed at the end)")
    args = ap.parse_args(argv)
    args.configs = [c.strip() for c in args.configs.split(",")] if args.configs else (
        ["fully-learned"] if args.quick else list(DEFAULT_CONFIGS))
    bad = [c for c in args.configs if c not in CONFIG_NAMES]
    if bad:
        ap.error(f"unknown configuration(s) {bad}; choose from {', '.join(CONFIG_NAMES)}")
    args.batches = ([int(b) for b in args.batches.split(",")] if args.batches
                    else ([256] if args.quick else [256, 1024, 8192]))
    args.short = args.short or (2 if args.quick else 20)
    args.span = args.span or ("5" if args.quick else "auto")
    if args.span != "auto":
        try:
            args.span = int(args.span)
        except ValueError:
            ap.error(f"--span takes a number of steps or auto; got {args.span!r}")
        if args.span < 1:
            ap.error("--span must be >= 1")
    args.plain_steps = args.plain_steps or (5 if args.quick else 100)
    args.plain_seconds = 0.0 if args.quick else 10.0
    if args.short < 1:
        ap.error("--short must be >= 1")
    return args


ARGS = _parse(sys.argv[1:]) if __name__ == "__main__" else None

import shutil  # noqa: E402
import subprocess  # noqa: E402
import tempfile  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
CLEARED_ENV = ("XLA_FLAGS", "JAX_COMPILATION_CACHE_DIR",
               "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS",
               "JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES", "JAX_ENABLE_X64")


def snapshot_code(mode: str, dest: Path) -> str:
    """Copy the ``metriplex`` package (HEAD or the working tree) to ``dest/metriplex``;
    return a description of what was copied."""
    dest.mkdir(parents=True, exist_ok=True)
    if mode == "head":
        sha = subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, check=True,
                             capture_output=True, text=True).stdout.strip()
        archive = subprocess.run(["git", "archive", "--format=tar", sha, "src/metriplex"],
                                 cwd=ROOT, check=True, capture_output=True).stdout
        subprocess.run(["tar", "-x", "-C", str(dest), "--strip-components=1"], input=archive,
                       check=True)
        return f"HEAD {sha[:12]}"
    shutil.copytree(ROOT / "src" / "metriplex", dest / "metriplex",
                    ignore=shutil.ignore_patterns("__pycache__"))
    dirty = subprocess.run(["git", "status", "--porcelain", "src/metriplex"], cwd=ROOT,
                           capture_output=True, text=True).stdout.strip()
    sha = subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True,
                         text=True).stdout.strip()
    return f"working tree at HEAD {sha[:12]}" + (" with uncommitted changes" if dirty else "")


if ARGS is not None:
    for _k in CLEARED_ENV:
        os.environ.pop(_k, None)
    _WORK = Path(ARGS.keep) if ARGS.keep else Path(tempfile.mkdtemp(prefix="plain-ref-"))
    _WORK.mkdir(parents=True, exist_ok=True)
    CODE = snapshot_code(ARGS.code, _WORK / "code")
    sys.path.insert(0, str(_WORK / "code"))

import json  # noqa: E402
import math  # noqa: E402
import platform  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402

import equinox as eqx  # noqa: E402
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import jax.random as jr  # noqa: E402
import numpy as np  # noqa: E402
import optax  # noqa: E402

from metriplex.app._commands import _config_from_args  # noqa: E402
from metriplex.cli import build_parser  # noqa: E402
from metriplex.app._build import build_loss, build_model, units_for  # noqa: E402
from metriplex.data import Trajectories  # noqa: E402
from metriplex.io import read, write  # noqa: E402
from metriplex.losses import Batch, NegativeTemperature  # noqa: E402
from metriplex._model import with_dtype  # noqa: E402
from metriplex._pairs import PairRows, PairStore  # noqa: E402
from metriplex._optimizers import adjustable_optimizer  # noqa: E402
from metriplex._train import make_chunk  # noqa: E402
from metriplex.structure.poisson import CanonicalPoisson, SkewMLPPoisson  # noqa: E402
from metriplex.structure.potential import MLPPotential, SumOf  # noqa: E402
from metriplex.structure.friction import (  # noqa: E402
    CholeskyFriction, ProjectedCholeskyFriction)
from metriplex.structure._projection import default_eps  # noqa: E402
from metriplex.systems import generate  # noqa: E402

# name -> (options of `metriplex train`, whether the exact Jacobi penalty is on, description)
CONFIGS = {
    "fully-learned": ([], False, "n = 10, E, S, L, M all networks, no Jacobi penalty"),
    "fully-learned+jacobi": (["--jacobi", "exact"], True,
                             "n = 10, E, S, L, M all networks, exact Jacobi penalty"),
    "pendulum-energetic": (["--poisson", "canonical:4", "--entropy", "sum:8,9"], False,
                           "n = 10, L canonical:4, S = s1 + s2 (indices 8, 9), E and M "
                           "learned; L is given, so no Jacobi penalty applies"),
    # The option that shares states between consecutive pairs (not a default: it costs
    # accuracy, docs/zoo.md); against the same plain step of independent pairs.
    "fully-learned+runs": (["--consecutive", "8"], False,
                           "fully-learned with --consecutive 8 (batches as runs of 8 pairs)"),
    "pendulum-energetic+runs": (["--poisson", "canonical:4", "--entropy", "sum:8,9",
                                 "--consecutive", "8"], False,
                                "pendulum-energetic with --consecutive 8"),
}
TARGET = {False: 0.5, True: 0.45}  # issue #16: metriplex / plain
SYSTEM, DT = "pendulum-energetic", 0.1
VALID_FRACTION = 0.02  # of 41 (quick: 4) trajectories: one


# ------------------------------------------------------------------------------------------
# Data: the pendulum, training trajectories plus one short validation trajectory (so the
# validations and the final evaluation, which cancel in t220 - t20 anyway, stay small).


def make_data(folder: Path, quick: bool) -> Path:
    train_traj, steps, valid_len = (3, 100, 11) if quick else (40, 250, 41)
    data = generate(SYSTEM, trajectories=train_traj + 1, steps=steps, dt=DT, seed=0)
    # The trajectory that `--validation VALID_FRACTION` holds out (data.split depends on the ids
    # and the seed only), cut short.
    _, valid = data.split(VALID_FRACTION, seed=0)
    assert valid is not None and len(valid.ids) == 1
    valid_id = int(valid.ids[0])
    k = np.zeros(len(data.trajectory), np.int64)
    for i in data.ids:  # the sample index within each trajectory
        rows = np.flatnonzero(data.trajectory == i)
        k[rows] = np.arange(len(rows))
    keep = (data.trajectory != valid_id) | (k < valid_len)
    data = Trajectories(data.trajectory[keep], data.t[keep], data.x[keep], data.names)
    path = folder / "pendulum.npz"
    write(path, data)
    return path


def cli_options(data: Path, name: str, batch: int, steps: int, out: Path) -> list[str]:
    # --no-reversible-first: by default these configurations first train L grad E alone, and
    # --steps caps each stage, so a run of N steps would time N steps of both stages. Without
    # it the one stage is the configuration's whole training (M grad E = 0 as a penalty, as
    # before the first stage was a default), and the plain step is built from that model.
    # --starts 1: where L is learned, training first tries three initialisations for a tenth
    # of --steps each, which the difference of two runs would count as steps.
    # --residual-metric diagonal: the plain step's residual is |r|^2, as the issue defines it
    # (the default's r^T W r costs n^2 more per pair, under 0.1 % of the step here).
    return ["train", str(data), "--out", str(out), "--quiet", "--steps", str(steps),
            "--eval-every", str(steps), "--batch-size", str(batch),
            "--validation", str(VALID_FRACTION), "--no-reversible-first", "--starts", "1",
            "--residual-metric", "diagonal", *CONFIGS[name][0]]


# ------------------------------------------------------------------------------------------
# The plain JAX reference


def mlp(layers, z):
    for W, b in layers[:-1]:
        z = jax.nn.softplus(W @ z + b)
    W, b = layers[-1]
    return W @ z + b


def plain_loss_fn(c: dict):
    """The loss of one batch, written plainly; ``c`` holds the constants (see
    :func:`plain_setup`)."""
    n = c["n"]
    iu = np.triu_indices(n, k=1)
    il = np.tril_indices(n)

    def energy(p, x):
        return c["E_out"] * mlp(p["E"], (x - c["E_shift"]) / c["E_scale"])[0]

    def entropy(p, x):
        if "S" in p:
            return c["S_out"] * mlp(p["S"], (x - c["S_shift"]) / c["S_scale"])[0]
        return jnp.sum(x[np.asarray(c["S_sum"])])

    def poisson(p, x):
        if "L" not in p:
            return jnp.asarray(c["L_const"], x.dtype)
        a = mlp(p["L"], (x - c["L_shift"]) / c["L_scale"])
        A = jnp.zeros((n, n), x.dtype).at[iu].set(a)  # strict upper triangle, by scatter
        return c["L_congruence"] * (A - A.T)

    def friction(p, x, gE):
        b = mlp(p["M"], (x - c["M_shift"]) / c["M_scale"])
        B = jnp.zeros((n, n), x.dtype).at[il].set(b) * c["M_rows"][:, None]  # by scatter
        if c["M_projected"]:  # M grad E = 0: B projected against grad E (standardised)
            d = c["M_scale"]
            r = jax.lax.rsqrt(jnp.sum((d * gE) ** 2) + c["M_eps2"])
            B = B - jnp.outer(d * d * gE * r, (gE * r) @ B)
        return B @ B.T

    def per_state(p, x):
        gE = jax.grad(energy, argnums=1)(p, x)
        gS = jax.grad(entropy, argnums=1)(p, x)
        L, M = poisson(p, x), friction(p, x, gE)
        return L @ gE + M @ gS, L @ gS, M @ gE, gE

    def jacobi(p, x):
        L = poisson(p, x)
        dL = jax.jacfwd(poisson, argnums=1)(p, x)  # dL[i, j, k] = d_k L^{ij}
        T = jnp.einsum("ijk,kl->ijl", dL, L)
        return T + jnp.transpose(T, (1, 2, 0)) + jnp.transpose(T, (2, 0, 1))

    w = c["weights"]
    rate = c["rate"]

    def msq(v):
        return jnp.mean(jnp.sum((v / rate[None, :]) ** 2, axis=-1))

    def cold(gE):  # the hinge on negative temperatures: relu(-d_i dE/ds_i)^2 / |D grad E|^2
        g = gE * c["T_scale"][None, :]
        hot = jnp.mean(jnp.sum(jax.nn.relu(-g[:, np.asarray(c["T_index"])]) ** 2, axis=-1))
        return hot / (jnp.mean(jnp.sum(g**2, axis=-1)) + jnp.finfo(g.dtype).tiny)

    def loss(p, x0, x1, dt):
        f0, LgS0, MgE0, gE0 = jax.vmap(per_state, in_axes=(None, 0))(p, x0)
        f1, LgS1, MgE1, gE1 = jax.vmap(per_state, in_axes=(None, 0))(p, x1)
        r = 2.0 * (x1 - x0) / dt[:, None] - f0 - f1
        total = w["residual"] * 0.25 * msq(r)
        if "temperature" in w:
            total = total + w["temperature"] * 0.5 * (cold(gE0) + cold(gE1))
        if "degeneracy_L" in w:
            total = total + w["degeneracy_L"] * 0.5 * (msq(LgS0) + msq(LgS1))
        if "degeneracy_M" in w:
            total = total + w["degeneracy_M"] * 0.5 * (msq(MgE0) + msq(MgE1))
        if "jacobi" in w:
            J = jax.vmap(jacobi, in_axes=(None, 0))(p, x0)
            inv = 1.0 / rate
            w3 = inv[:, None, None] * inv[None, :, None] * inv[None, None, :]
            penalty = jnp.mean(jnp.sum((J * w3[None]) ** 2, axis=(1, 2, 3)))
            total = total + w["jacobi"] * penalty
        return total

    return loss


def _layers(hidden, out_weight, out_bias):
    return [(l.weight, l.bias) for l in hidden.layers] + [(out_weight, out_bias)]


def plain_setup(model, loss, units):
    """Plain parameters and constants with the weights of metriplex's ``model``."""
    n = len(units.shift)
    dtype = jnp.float32
    f = lambda v: jnp.asarray(np.asarray(v, np.float64), dtype)  # noqa: E731
    p, c = {}, {"n": n, "rate": f(units.rate)}
    E = model.energy
    assert isinstance(E, MLPPotential) and E.features is None and E.quadratic is None
    p["E"] = _layers(E.hidden, E.out.weight, E.out.bias)
    c.update(E_shift=f(E.shift), E_scale=f(E.scale), E_out=E.output_scale)
    S = model.entropy
    if isinstance(S, MLPPotential):
        assert S.features is None and S.quadratic is None
        p["S"] = _layers(S.hidden, S.out.weight, S.out.bias)
        c.update(S_shift=f(S.shift), S_scale=f(S.scale), S_out=S.output_scale)
    else:
        assert isinstance(S, SumOf)
        c["S_sum"] = tuple(S.indices)
    L = model.poisson
    if isinstance(L, SkewMLPPoisson):
        p["L"] = _layers(L.hidden, L.head.weight, L.head.bias)
        c.update(L_shift=f(L.scaling.shift), L_scale=f(L.scaling.scale),
                 L_congruence=f(L.scaling.congruence()))
    else:
        assert isinstance(L, CanonicalPoisson)
        c["L_const"] = L.matrix()
    M = model.friction
    c["M_projected"] = type(M) is ProjectedCholeskyFriction  # the default: M grad E = 0 exact
    if c["M_projected"]:
        eps = default_eps(M.eps, dtype)
        c["M_eps2"] = max(eps * eps, float(jnp.finfo(dtype).tiny))
        M = M.base
    assert type(M) is CholeskyFriction and M.features is None
    p["M"] = _layers(M.hidden, M.head.weight, M.head.bias)
    d = np.asarray(M.scaling.scale)
    c.update(M_shift=f(M.scaling.shift), M_scale=f(d),
             M_rows=f(np.sqrt(M.scaling.factor) * d))
    c["weights"] = dict(zip(loss.names, loss.weights))
    for term in loss.terms:
        if isinstance(term, NegativeTemperature):
            c.update(T_index=tuple(term.indices), T_scale=f(units.rate))
    unknown = set(c["weights"]) - {"residual", "degeneracy_L", "degeneracy_M", "jacobi",
                                   "temperature"}
    assert not unknown, unknown
    p = jax.tree_util.tree_map(lambda a: jnp.asarray(a, dtype), p)
    return p, c


class PlainStep:
    """The plain reference: one jitted Adam step on a random minibatch, in a Python loop."""

    def __init__(self, params, consts, pairs, batch: int, lr: float):
        self.loss = plain_loss_fn(consts)
        opt = optax.adam(lr)
        loss = self.loss

        def step(p, s, key, X0, X1, DT):
            key, sub = jr.split(key)
            idx = jr.randint(sub, (batch,), 0, X0.shape[0])
            value, grads = jax.value_and_grad(loss)(p, X0[idx], X1[idx], DT[idx])
            with jax.numpy_dtype_promotion("standard"):  # optax mixes int and float
                updates, s = opt.update(grads, s, p)
                return optax.apply_updates(p, updates), s, key, value

        self.step = jax.jit(step)
        self.data = tuple(jnp.asarray(a, jnp.float32) for a in (pairs.x0, pairs.x1, pairs.dt))
        self.state = (params, opt.init(params), jr.key(1))

    def run(self, steps: int) -> float:
        """Wall seconds of ``steps`` steps."""
        p, s, k = self.state
        jax.block_until_ready((p, s))
        t0 = time.perf_counter()
        for _ in range(steps):
            p, s, k, v = self.step(p, s, k, *self.data)
        jax.block_until_ready((p, s, v))
        wall = time.perf_counter() - t0
        if not bool(jnp.isfinite(v)):
            raise RuntimeError(f"plain reference: non-finite loss {v}")
        self.state = (p, s, k)
        return wall


class FitChunk:
    """metriplex's own compiled step in this process (a diagnostic beside the CLI): the chunk
    that ``fit`` runs (``make_chunk``: ``length`` steps in one compiled loop), with fit's
    optimiser, on the same pairs, for the same model and loss."""

    def __init__(self, model, loss, pairs, rate, batch: int, lr: float, length: int = 10,
                 consecutive: int = 1):
        params, static = eqx.partition(model, eqx.is_inexact_array)
        opt = adjustable_optimizer(lr)
        self.length = length
        self.fn = eqx.filter_jit(make_chunk(loss, opt, static, batch, consecutive=consecutive))
        self.full = PairStore.of(PairRows.of(pairs, None, "benchmark"),
                                 np.asarray(rate, np.float64), jnp.float32)
        self.state = (params, opt.init(params), jr.key(2))

    def run(self, steps: int) -> tuple[float, int]:
        """Wall seconds of at least ``steps`` steps (whole chunks), and the steps run."""
        p, s, k = self.state
        chunks = max(1, math.ceil(steps / self.length))
        jax.block_until_ready((p, s))
        t0 = time.perf_counter()
        for _ in range(chunks):
            k, sub = jr.split(k)
            p, s, v, _ = self.fn(p, s, sub, self.length, self.full)
        jax.block_until_ready((p, s, v))
        wall = time.perf_counter() - t0
        if not bool(jnp.isfinite(v)):
            raise RuntimeError(f"metriplex chunk: non-finite loss {v}")
        self.state = (p, s, k)
        return wall, chunks * self.length


def setup(name: str, data_path: Path, batch: int):
    """metriplex's model and loss for this row, as ``metriplex train`` builds them, the plain
    reference's weights and constants made from them, the training trajectories and the
    configuration."""
    args = build_parser().parse_args(cli_options(data_path, name, batch, 1, Path("unused")))
    config = _config_from_args(args)
    data = read(data_path)
    train, _ = data.split(config.validation, seed=config.seed)  # as `metriplex train` does
    model_key, _ = jr.split(jr.key(config.seed))
    units = units_for(config, train)
    model = build_model(config, train, key=model_key, units=units)
    model = with_dtype(model, jnp.float32)
    loss = build_loss(config, units)
    params, consts = plain_setup(model, loss, units)
    return model, loss, params, consts, train, config


def check_same_loss(model, loss, params, consts, pairs, units_rate) -> tuple[float, float]:
    """(metriplex loss, plain loss) on the first 64 training pairs; raise if they differ."""
    idx = np.arange(min(64, len(pairs)))
    x0, x1, dt = (jnp.asarray(a[idx], jnp.float32) for a in (pairs.x0, pairs.x1, pairs.dt))
    ours = float(jax.jit(lambda m, b: loss(m, b, key=jr.key(0))[0])(
        model, Batch(x0, x1, dt, jnp.asarray(units_rate, jnp.float32))))
    plain = float(jax.jit(plain_loss_fn(consts))(params, x0, x1, dt))
    if not abs(ours - plain) <= 1e-4 * max(abs(ours), 1e-12):
        raise RuntimeError(f"the plain loss ({plain!r}) is not metriplex's ({ours!r})")
    return ours, plain


# ------------------------------------------------------------------------------------------
# metriplex train, in a subprocess


def _metriplex_command() -> list[str]:
    exe = Path(sys.executable).with_name("metriplex")
    return [str(exe)] if exe.exists() else [sys.executable, "-m", "metriplex"]


def run_cli(options: list[str], env: dict) -> dict:
    out = Path(options[options.index("--out") + 1])
    t0 = time.perf_counter()
    proc = subprocess.run(_metriplex_command() + options, env=env, capture_output=True,
                          text=True)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise RuntimeError(f"metriplex {' '.join(options)} failed ({proc.returncode}):\n"
                           f"{proc.stderr[-3000:]}")
    metrics = json.loads((out / "metrics.json").read_text())
    history = json.loads((out / "history.json").read_text())
    shutil.rmtree(out, ignore_errors=True)
    return {"wall_s": wall, "fit_s": metrics["train_seconds"], "eval_times_s": history["time"],
            "steps": history["step"][-1]}


# ------------------------------------------------------------------------------------------


def _load():
    try:
        return tuple(round(v, 2) for v in os.getloadavg())
    except OSError:
        return None


def _cpu_name() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def measure_row(name, batch, data_path, args, env, work: Path) -> dict:
    jacobi = CONFIGS[name][1]
    load_at_start = _load()
    model, loss, params, consts, train, config = setup(name, data_path, batch)
    pairs = train.pairs()
    check = check_same_loss(model, loss, params, consts, pairs, consts["rate"])
    bsz = min(batch, len(pairs))
    plain = PlainStep(params, consts, pairs, bsz, config.lr)
    # fit holds trajectories as rows, so that --consecutive can draw runs of them
    chunk = FitChunk(model, loss, train, consts["rate"], bsz, config.lr,
                     consecutive=config.consecutive if loss.reads_runs else 1)
    t0 = time.perf_counter()
    plain.run(2)  # compile and warm up
    plain_compile_s = time.perf_counter() - t0
    chunk.run(1)
    pilot = max(3, args.plain_steps // 10)
    plain_guess = plain.run(pilot) / pilot
    w, k = chunk.run(pilot)
    chunk_guess = w / k
    # The span: enough metriplex steps (as its own chunk runs them here) to fill --seconds.
    span = (args.span if args.span != "auto"
            else max(200, math.ceil(args.seconds / chunk_guess)))
    plain_steps = max(args.plain_steps, math.ceil(args.plain_seconds / plain_guess))
    chunk_steps = max(args.plain_steps, math.ceil(args.plain_seconds / chunk_guess))
    long_steps = args.short + span
    ours, ref, inproc, runs = [], [], [], []
    for r in range(args.repeats):
        out = work / f"{name}-{batch}-{r}"
        short = run_cli(cli_options(data_path, name, batch, args.short,
                                    out.with_name(out.name + "-short")), env)
        ta = plain.run(plain_steps)
        ca = chunk.run(chunk_steps)
        long = run_cli(cli_options(data_path, name, batch, long_steps,
                                   out.with_name(out.name + "-long")), env)
        tb = plain.run(plain_steps)
        cb = chunk.run(chunk_steps)
        ours.append((long["wall_s"] - short["wall_s"]) / span)
        ref.append((ta + tb) / (2 * plain_steps))
        inproc.append((ca[0] + cb[0]) / (ca[1] + cb[1]))
        runs.append({"short": short, "long": long, "plain_s": [ta, tb],
                     "chunk_s": [ca[0], cb[0]], "chunk_steps": ca[1],
                     "fit_per_step_s": (long["fit_s"] - short["fit_s"]) / span})
    ms = 1e3 * statistics.median(ours)
    plain_ms = 1e3 * statistics.median(ref)
    ratio = ms / plain_ms
    return dict(
        configuration=name, jacobi=jacobi, batch=batch, n=10, dtype="float32",
        metriplex_ms=ms, plain_ms=plain_ms, ratio=ratio, target=TARGET[jacobi],
        met=ratio <= TARGET[jacobi],
        metriplex_fit_ms=1e3 * statistics.median(r["fit_per_step_s"] for r in runs),
        inprocess_ms=1e3 * statistics.median(inproc),
        inprocess_ratio=statistics.median(inproc) / statistics.median(ref),
        short_run_wall_s=statistics.median(r["short"]["wall_s"] for r in runs),
        short_run_fit_s=statistics.median(r["short"]["fit_s"] for r in runs),
        plain_compile_s=plain_compile_s, loss_check=check, load_at_start=load_at_start,
        load_at_end=_load(), runs=runs, short=args.short, long=long_steps, span=span,
        plain_steps=plain_steps, repeats=args.repeats,
    )


def table(rows) -> str:
    lines = ["| configuration | batch | metriplex ms/step (wall) | plain JAX ms/step (wall) | "
             "ratio | target | met | load (1 min) |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(
            f"| {r['configuration']} | {r['batch']} | {r['metriplex_ms']:.1f} | "
            f"{r['plain_ms']:.1f} | {r['ratio']:.2f} | ≤ {r['target']:g} | "
            f"{'met' if r['met'] else 'not met'} | {r['load_at_start'][0]:.1f} |")
    return "\n".join(lines)


def breakdown(rows) -> str:
    lines = ["| configuration | batch | runs compared (steps) | short run: process s | "
             "of which fit s | outside fit s | fit-only ms/step | fit's chunk in-process "
             "ms/step | in-process ratio |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(
            f"| {r['configuration']} | {r['batch']} | {r['long']} vs {r['short']} | "
            f"{r['short_run_wall_s']:.1f} | "
            f"{r['short_run_fit_s']:.1f} | {r['short_run_wall_s'] - r['short_run_fit_s']:.1f} | "
            f"{r['metriplex_fit_ms']:.1f} | {r['inprocess_ms']:.1f} | "
            f"{r['inprocess_ratio']:.2f} |")
    return "\n".join(lines)


def main(args) -> int:
    work = _WORK
    env = {k: v for k, v in os.environ.items() if k not in CLEARED_ENV}
    env["PYTHONPATH"] = os.pathsep.join(
        [str(work / "code")] + ([env["PYTHONPATH"]] if env.get("PYTHONPATH") else []))
    command = " ".join(["benchmarks/plain_reference.py", *sys.argv[1:]])
    load_before = _load()
    machine = {"cpu": _cpu_name(), "cpu_count": os.cpu_count(),
               "platform": platform.platform(), "jax": jax.__version__,
               "optax": optax.__version__, "backend": jax.default_backend(),
               "xla_threads": "XLA default", "code": CODE,
               "date": time.strftime("%Y-%m-%d %H:%M:%S %Z")}
    print(f"# metriplex train vs a plain JAX step ({'quick' if args.quick else 'full'})")
    print(f"{machine['cpu']}, {machine['cpu_count']} CPUs; jax {machine['jax']} "
          f"({machine['backend']}), default XLA threading; code: {CODE}")
    print(f"load average before: {load_before}", flush=True)
    t_start = time.perf_counter()
    rows = []
    try:
        data_path = make_data(work, args.quick)
        for name in args.configs:
            for batch in args.batches:
                row = measure_row(name, batch, data_path, args, env, work)
                rows.append(row)
                print(f"  {name:<21} B={batch:<5} metriplex {row['metriplex_ms']:8.1f} ms  "
                      f"plain {row['plain_ms']:8.1f} ms  ratio {row['ratio']:.2f}  "
                      f"(fit-only {row['metriplex_fit_ms']:.1f} ms, in-process chunk "
                      f"{row['inprocess_ms']:.1f} ms; load "
                      f"{row['load_at_start'][0]:.1f})", flush=True)
    finally:
        if not args.keep:
            shutil.rmtree(work, ignore_errors=True)
    load_after = _load()
    print(f"\nload average after: {load_after}; CPUs: {os.cpu_count()}; "
          f"{time.perf_counter() - t_start:.0f} s in all\n")
    print(table(rows))
    print("\nWhere the wall time of a run goes (the short run; fit-only: the same difference "
          "taken on `train_seconds` of metrics.json, i.e. without start-up and the final "
          "evaluation):\n")
    print(breakdown(rows))
    if args.out:
        result = {"command": command, "machine": machine, "load_before": load_before,
                  "load_after": load_after, "seconds": time.perf_counter() - t_start,
                  "method": {"short": args.short, "span": args.span,
                             "seconds": args.seconds, "plain_steps": args.plain_steps,
                             "repeats": args.repeats},
                  "rows": rows}
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(json.dumps(result, indent=1, default=str) + "\n")
        print(f"\nwrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main(ARGS))
