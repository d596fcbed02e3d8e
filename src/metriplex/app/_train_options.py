"""The options of ``metriplex train`` that choose what is learned and how
(:func:`add_training_options`), with their help; :mod:`metriplex.app.cli` adds them to train's
parser."""

from __future__ import annotations

import argparse

from ..integrate import SCHEMES
from ..structure import ACTIVATIONS
from ._repeats import GOOD_SCORE, NOISE_FLOOR, REPEATS
from ._stages import START_STEPS, STARTS
from .config import FEATURES


def scheme_help(prefix: str, default: str) -> str:
    """``--scheme``'s help, from the registry: every scheme's name and summary."""
    names = " | ".join(f"{name} ({cls.summary})" for name, cls in SCHEMES.items())
    return f"{prefix}{names} ({default})"


def add_training_options(p: argparse.ArgumentParser) -> None:
    """``metriplex train``'s options on what is learned and how: structure, loss, network,
    optimiser and run (the data and split options are in
    :func:`metriplex.app.cli.build_parser`)."""
    from .config import (ENERGY_CHOICES, ENTROPY_CHOICES, FRICTION_CHOICES, JACOBI_CHOICES,
                         POISSON_CHOICES, SCHEDULES, RunConfig, choices_help)

    d = RunConfig()
    g = p.add_argument_group("structure (what is learned, what is given)")
    g.add_argument("--energy", help=choices_help(ENERGY_CHOICES))
    g.add_argument("--entropy", help=choices_help(ENTROPY_CHOICES))
    g.add_argument("--poisson", help=choices_help(POISSON_CHOICES))
    g.add_argument("--friction", help=choices_help(FRICTION_CHOICES))
    g.add_argument("--constant", metavar="auto|none|I,J,...", help="variables that the learned "
                   "L and M hold constant (zero rows and columns; E and S may still depend on "
                   "them): auto (default) those constant along every training trajectory, such "
                   "as a parameter recorded with the data | none | their indices")
    g.add_argument("--degeneracy", help="auto (default: L grad S = 0 exact for --poisson neural "
                   "when S is given, M grad E = 0 exact when training starts with L grad E alone, "
                   "penalties otherwise) | soft (penalties only) | exact (L and M by "
                   "construction; casimir3 takes S as its Casimir; lie-poisson only beside "
                   "--entropy sum:...)")
    g.add_argument("--degeneracy-at", help="where soft degeneracy penalties are evaluated: states "
                   "(both states of each pair, default) | midpoints (one per pair; with "
                   "--scheme discrete-gradient about halves the step's cost)")
    g.add_argument("--residual-metric", help="how the pair residual is measured: auto (default: "
                   "correlated where M is not zero) | correlated (extra weight on combinations "
                   "of variables that the data keep nearly still, such as the sum of entropies "
                   "of cells that exchange heat) | diagonal (each variable in its own units)")
    g.add_argument("--jacobi", help="Jacobi-identity penalty: " + choices_help(JACOBI_CHOICES))
    g.add_argument("--jacobi-probes", type=int, help=f"probes per sample (default {d.jacobi_probes})")
    g.add_argument("--jacobi-samples", type=int, help="pairs of each batch that the Jacobi penalty "
                   "is evaluated on (default: all; fewer is cheaper, still unbiased)")
    g.add_argument("--quadratic", action="store_true", default=None, help="add a learned "
                   "quadratic form to the learned E and S networks (a second-order Taylor term "
                   "that extrapolates the forces linearly; off by default)")
    g.add_argument("--features", help=" | ".join(("none", *FEATURES))
                   + " (invariant features of the state; default none)")
    g.add_argument("--features-for", help="networks that see the features: a comma list of "
                   f"energy, entropy, friction (default {d.features_for})")
    g.add_argument("--scheme", help=scheme_help(
        "training residual scheme: ", "default: cn, or hermite where the training pairs' steps "
        "are coarse for the motion they record"))
    w = p.add_argument_group("loss weights and optimisation")
    w.add_argument("--w-traj", type=float, help=f"residual weight (default {d.w_traj})")
    w.add_argument("--w-degeneracy-L", dest="w_degeneracy_L", type=float,
                   help=f"|L grad S|^2 weight (default {d.w_degeneracy_L})")
    w.add_argument("--w-degeneracy-M", dest="w_degeneracy_M", type=float,
                   help=f"|M grad E|^2 weight (default {d.w_degeneracy_M})")
    w.add_argument("--w-jacobi", type=float, help=f"Jacobi weight (default {d.w_jacobi})")
    w.add_argument("--w-temperature", type=float, help="weight of a hinge on negative learned "
                   "temperatures dE/ds_i, needs --entropy sum:... (default: 1 where training "
                   "starts with L grad E alone, else 0)")
    w.add_argument("--reversible-first", action=argparse.BooleanOptionalAction, default=None,
                   help="first train L grad E alone (no friction), then add the learned "
                   "friction, so that friction does not carry the motion (see the README; "
                   "default: on when M is learned and neither L nor S is zero)")
    w.add_argument("--temperature-init", action=argparse.BooleanOptionalAction, default=None,
                   help="after the first stage, start from the temperatures dE/ds_i of the "
                   "data's energy balance where they exceed 100 in the networks' units "
                   "(default: on beside a given L, --entropy sum:... and the default energy "
                   "network without features)")
    w.add_argument("--hold-energy", action=argparse.BooleanOptionalAction, default=None,
                   help="after the first stage, train the friction to its energy held, then "
                   "everything: needs --reversible-first (off by default; see the README)")
    w.add_argument("--starts", type=int, metavar="K", help="try K initialisations for "
                   f"{START_STEPS} steps each (at most a tenth of --steps), then train the one of "
                   "lowest validation loss from its start (in the first stage where there is "
                   "one): a learned L and E can start into a poor minimum (default: "
                   f"{STARTS} where L is learned, else 1)")
    w.add_argument("--repeats", type=int, metavar="K", help="train again from another "
                   "initialisation while the held-out rollouts of the best model so far err by "
                   f"more than {GOOD_SCORE} of the data's spread (on noisy held-out states, "
                   f"{NOISE_FLOOR}x their noise if more) or fail, up to K trainings in "
                   f"all; the best is kept; the last of three where L = 0 learns --friction "
                   f"exchange, the last of four --quadratic (default: {REPEATS}, and a fourth "
                   "with --quadratic where E is the default network and the third does not "
                   "learn the exchange; 1 without held-out trajectories)")
    w.add_argument("--confine", action=argparse.BooleanOptionalAction, default=None,
                   help="add a wall to the learned E, zero on the training data's box widened "
                   "by one standard deviation (three where S is learned) and quartic outside "
                   "it, so that its level sets are bounded: with M grad E = 0 no rollout can "
                   "run away (default: on where a learned M has M grad E = 0 exact beside an "
                   "S that is not zero)")
    w.add_argument("--width", type=int, help=f"network width (default {d.width})")
    w.add_argument("--depth", type=int, help=f"hidden layers (default {d.depth})")
    w.add_argument("--activation", choices=sorted(ACTIVATIONS),
                   help=f"hidden-layer activation of every learned network, all smooth as the "
                   f"gradients of E and S need (default {d.activation})")
    w.add_argument("--lr", type=float, help=f"peak learning rate (default {d.lr})")
    w.add_argument("--weight-decay", type=float, help=f"AdamW weight decay (default {d.weight_decay})")
    w.add_argument("--steps", type=int, help=f"the most optimiser steps of each training stage "
                   f"(default {d.steps}); training usually stops earlier, when the held-out "
                   "rollouts stop improving")
    w.add_argument("--max-minutes", type=float, help="stop training after this many minutes, "
                   "the starts and stages together (default: no time limit)")
    w.add_argument("--batch-size", type=int, help=f"pairs per step (default {d.batch_size})")
    w.add_argument("--validation", type=float,
                   help="fraction of the selected trajectories held out for validation, drawn "
                   f"at random with --seed (default {d.validation}; 0 for none); to choose "
                   "them, see --validation-ids and --split")
    w.add_argument("--eval-every", type=int, help=f"steps between validations (default {d.eval_every})")
    w.add_argument("--patience", type=int, help="validations without improvement before the "
                   "learning rate is cut (x0.3, from the best model; after --lr-cuts cuts "
                   "training stops; default 20)")
    w.add_argument("--lr-cuts", type=int, help="learning-rate cuts before training stops "
                   f"(default {d.lr_cuts})")
    w.add_argument("--schedule", choices=sorted(SCHEDULES), help="learning-rate schedule: "
                   + "; ".join(f"{k}: {v}" for k, v in SCHEDULES.items()).replace("%", "%%"))
    w.add_argument("--lbfgs-steps", type=int, help="iterations of an L-BFGS finish on a fixed "
                   "batch of up to 8192 training pairs after the Adam stage, kept only where "
                   f"the held-out rollouts improve (default {d.lbfgs_steps}; 0 for none)")
    w.add_argument("--input-noise", type=float, metavar="FRACTION", help="Gaussian noise on "
                   "both states of every training pair, as a fraction of each variable's "
                   f"standard deviation (default {d.input_noise}; 0 for none)")
    w.add_argument("--jitter-constants", action=argparse.BooleanOptionalAction, default=None,
                   help="noise on each variable held constant that takes several values across "
                   "the trajectories (a recorded parameter), of the median gap between them, "
                   "so the model varies smoothly between those values (default "
                   f"{'on' if d.jitter_constants else 'off'})")
    w.add_argument("--consecutive", type=int, metavar="K", help="draw each training batch "
                   "as runs of K consecutive pairs, so each state is evaluated once, not twice; "
                   "not with --input-noise, --data-parallel, --window-steps or "
                   "--degeneracy-at midpoints, which keep independent pairs "
                   f"(default {d.consecutive}; 1 for independent pairs)")
    w.add_argument("--every", type=int, metavar="K", help="train on pairs K samples apart, "
                   "each training trajectory as K interleaved ones (every sample still used; "
                   "validation unchanged); default: the K of 1, 2, 3, 4, 6, 8, 12, 16 at which "
                   "the training data's rates are least rough, 1 for smooth motion, larger with "
                   "noise on the states (README, Noisy data)")
    w.add_argument("--window-steps", type=int, metavar="K", help="also train on rollouts "
                   "of K steps from the first states of 32 training pairs per batch, against "
                   "the data that follow them: errors that compound over a rollout are "
                   f"trained away (default {d.window_steps}; 0 for none)")
    w.add_argument("--average-steps", type=int, metavar="K", help="judge every validation by "
                   "a running average of the parameters over about K optimiser steps, and keep "
                   f"that average as the model (default {d.average_steps}; 0 for none)")
    w.add_argument("--checkpoint-every", type=int,
                   help=f"validations between checkpoints (default {d.checkpoint_every})")
    w.add_argument("--seed", type=int, help=f"PRNG seed (default {d.seed})")
    w.add_argument("--float64", action=argparse.BooleanOptionalAction, default=None,
                   help="train in float64 (default: where rounding the states to float32 "
                   "would change a typical rate over one step by over 2%%, as for a value "
                   "near 1e4 that moves little; --no-float64: float32 always, whose steps "
                   "cost about half as much on a CPU)")
    w.add_argument("--data-parallel", action="store_true", default=None,
                   help="split each batch over all local devices (GPUs, or CPU devices with "
                   "XLA_FLAGS=--xla_force_host_platform_device_count=N)")
