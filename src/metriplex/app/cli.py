"""The ``metriplex`` command line: a thin front that parses options and calls the library.

Bad input ends with one clear message on stderr and exit status 2, never a traceback.
Here: the parser (every option and its help) and ``main``; what each command does is in
:mod:`metriplex.app._commands`.
"""

from __future__ import annotations

import argparse
import difflib
import re
import sys
from typing import Any, NoReturn

from ._train_options import add_training_options, scheme_help
from ._commands import (cmd_evaluate, cmd_generate, cmd_reproduce, cmd_rollout, cmd_simulate,
                        cmd_train)
from .._errors import MetriplexError
from .._precision import full_precision
from ..integrate import ROOT_FINDERS
from ..io._registry import layouts_text, suffixes_text
from ._presets import EXPERIMENTS, PRESETS
from ._allocator import return_large_blocks

__all__ = ["DATA_FORMAT", "EXIT_BAD_INPUT", "EXIT_FAILED", "build_parser", "cmd_evaluate",
           "cmd_generate", "cmd_reproduce", "cmd_rollout", "cmd_simulate", "cmd_train", "main"]



def _solver_help() -> str:
    """``--solver``'s help, from the registry of root finders: every name and summary."""
    return "implicit steps: " + " | ".join(f"{k} ({v})" for k, (_, v) in ROOT_FINDERS.items())

EXIT_BAD_INPUT = 2
EXIT_FAILED = 3

#: A value that starts with a minus sign and a digit is a number, never an option: argparse
#: alone reads "--lr -1e-3" as "--lr" without a value (it knows only -1 and -.5 as numbers).
_NEGATIVE_NUMBER = re.compile(r"^-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$|^-(inf|infinity|nan)$",
                              re.IGNORECASE)


class _Parser(argparse.ArgumentParser):
    """argparse, with negative numbers in any notation as values, and usage errors as one line
    (the rule and the value, and where to look) instead of the whole usage text."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = _NEGATIVE_NUMBER
        #: each command's parser, by name (set by build_parser on the top-level parser)
        self.commands: dict[str, argparse.ArgumentParser] = {}

    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: error: {message}. See `{self.prog} --help`.\n")

    def unrecognised(self, command: str, extra: list[str]) -> NoReturn:
        """The error for options that ``command`` does not have, from that command's parser
        (so it points to the command's help), with the closest option it has for each."""
        sub = self.commands.get(command, self)
        # argparse lists a parser's options only in this attribute (stable since Python 2.7)
        known = sorted(s for s in sub._option_string_actions if s.startswith("--"))
        hints = [f"{a} is not an option; did you mean {close[0]}?" for a in extra
                 if a.startswith("--") and (close := difflib.get_close_matches(
                     a.split("=")[0], known, n=1, cutoff=0.7))]
        sub.error(f"unrecognized arguments: {' '.join(extra)}"
                  + ("" if not hints else " (" + "; ".join(hints) + ")"))


def build_parser() -> argparse.ArgumentParser:
    """The ``metriplex`` command line: one subcommand per ``cmd_*`` function, every option with its
    help."""
    parser = _Parser(
        prog="metriplex",
        description="Learn thermodynamically consistent (GENERIC) dynamics "
        "dx/dt = L(x) grad E(x) + M(x) grad S(x) from trajectories.",
    )
    parser.add_argument("--version", action="version", version=_version())
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    parser.commands = sub.choices  # each command's parser, by name (for its usage errors)

    p = sub.add_parser("generate", aliases=["simulate"],
                       help="generate trajectories of a built-in system",
                       description=_systems_help(), formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("system", metavar="SYSTEM", help="a built-in system (listed above)")
    p.add_argument("--trajectories", type=int, required=True,
                   help="number of trajectories, each from its own random initial state")
    p.add_argument("--steps", type=int, required=True,
                   help="steps per trajectory (each trajectory has STEPS + 1 samples)")
    p.add_argument("--dt", type=float, required=True,
                   help="time between samples, in the system's time unit")
    p.add_argument("--seed", type=int, default=0,
                   help="seed of the initial states (default 0)")
    p.add_argument("--param", action="append", metavar="NAME=VALUE",
                   help="system parameter, e.g. --param parameter_set=spnn or --param inertia=10,20,40")
    p.add_argument("--float64", action="store_true", help="integrate in float64")
    p.add_argument("--out", required=True, help=f"data file to write: {suffixes_text()}")
    p.add_argument("--overwrite", action="store_true", help=_OVERWRITE)
    p.set_defaults(func=cmd_generate)

    p = sub.add_parser("train", help="learn a GENERIC model from trajectory data",
                       epilog=DATA_FORMAT, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("data", metavar="DATA", help="trajectory data (format below)")
    p.add_argument("--out", required=True, metavar="RUN_DIR",
                   help="run folder: model.mpx, config.json, history.json, metrics.json, "
                   "checkpoint.ckpt, figures/")
    p.add_argument("--preset", help=" | ".join(PRESETS) + " (a reference experiment's "
                   "settings)")
    p.add_argument("--resume", action="store_true", help="continue an interrupted run in --out "
                   "(with the same DATA, --dt, trajectories and options; others are refused)")
    p.add_argument("--overwrite", action="store_true", help=_OVERWRITE)
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    s = p.add_argument_group("which trajectories train and validate (the ids used are "
                             "recorded in RUN_DIR/config.json)")
    s.add_argument("--trajectories", metavar="IDS", help="use only these trajectory ids of "
                   f"DATA, {_IDS} (default: all)")
    s.add_argument("--validation-ids", metavar="IDS", help="these of the selected trajectories "
                   "validate, the rest train (instead of the random --validation fraction)")
    s.add_argument("--split", metavar="FILE", help="the split to use: a JSON file "
                   '{"train": [ids], "validation": [ids]} (optionally "test": [ids], which '
                   "must not overlap them), or a run folder (or its config.json) whose split "
                   "is reused exactly")
    p.add_argument("--dt", type=float, metavar="STEP", help=_DT)
    add_training_options(p)
    p.set_defaults(func=cmd_train)

    p = sub.add_parser("rollout", help="predict every trajectory of DATA from its first state",
                       epilog=DATA_FORMAT, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("run", metavar="RUN_DIR", help="run folder written by `metriplex train`")
    p.add_argument("data", metavar="DATA", help="trajectories to predict (format below)")
    p.add_argument("--out", required=True,
                   help=f"predictions, in the data format: {suffixes_text()}")
    p.add_argument("--scheme", help=scheme_help("", "default: the scheme the run was trained "
                                                 "with"))
    p.add_argument("--solver", choices=tuple(ROOT_FINDERS), help=_solver_help())
    p.add_argument("--trajectories", metavar="IDS",
                   help=f"predict only these trajectory ids of DATA, {_IDS} (default: all)")
    p.add_argument("--dt", type=float, metavar="STEP", help=_DT)
    p.add_argument("--overwrite", action="store_true", help=_OVERWRITE)
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_rollout)

    p = sub.add_parser("evaluate", help="metrics (and figures) of a trained model on DATA",
                       epilog=DATA_FORMAT, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("run", metavar="RUN_DIR", help="run folder written by `metriplex train`")
    p.add_argument("data", metavar="DATA", help="test trajectories (format below)")
    p.add_argument("--out", metavar="METRICS.json",
                   help="write every metric as strict JSON here; the scalar ones are printed "
                   "to stdout as JSON either way")
    p.add_argument("--figures", metavar="DIR", help="also write the report figures here")
    p.add_argument("--scheme", help=scheme_help("", "default: the scheme the run was trained "
                                                 "with"))
    p.add_argument("--solver", choices=tuple(ROOT_FINDERS), help=_solver_help())
    p.add_argument("--horizon", type=float, help="also report the error up to t0 + HORIZON")
    p.add_argument("--trajectories", metavar="IDS",
                   help=f"evaluate only these trajectory ids of DATA, {_IDS} (default: all; "
                   "the ids evaluated are `trajectory_ids` in the JSON)")
    p.add_argument("--dt", type=float, metavar="STEP", help=_DT)
    p.add_argument("--every", type=int, default=1, metavar="K",
                   help="evaluate on every K-th sample of each trajectory, from its first "
                   "(default 1: all); with noise on the states, steps K samples long rise "
                   "above it (the verdict says when: README, Noisy data)")
    p.add_argument("--no-verdict", action="store_true",
                   help="skip the 'is it GENERIC?' verdict (consistent | not consistent | "
                   "cannot tell, each reason with its figure, under `verdict` in the JSON; it "
                   "trains a black-box reference)")
    p.add_argument("--verdict-steps", type=int, default=3000,
                   help="training steps of the black-box reference (default 3000)")
    p.add_argument("--strict", action="store_true",
                   help="exit with the verdict's outcome, for scripts: 0 consistent, 1 not "
                   "consistent, 3 cannot tell (2 stays bad input); the outcome is also "
                   "`verdict.outcome` in the --out JSON")
    p.add_argument("--overwrite", action="store_true", help=_OVERWRITE)
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=cmd_evaluate)

    p = sub.add_parser("reproduce", help="run a reference experiment end to end, with figures")
    p.add_argument("experiment", metavar="EXPERIMENT",
                   help=" | ".join(EXPERIMENTS))
    p.add_argument("--quick", action="store_true", help="reduced size (about two minutes)")
    p.add_argument("--out", default=None, help="output folder (default runs/EXPERIMENT)")
    p.add_argument("--degeneracy", default=None,
                   help="soft | exact (default: soft, the presets'; with --defaults, auto as "
                   "in train)")
    p.add_argument("--defaults", action="store_true",
                   help="train with the experiment's structure only (what is learned, what is "
                   "given) and default settings, as without a preset")
    p.add_argument("--no-verdict", action="store_true",
                   help="skip the verdict on the test data (is it GENERIC?), which trains a "
                   "black-box reference as evaluate does (a --quick run has none)")
    p.add_argument("--overwrite", action="store_true", help=_OVERWRITE)
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.set_defaults(func=cmd_reproduce)
    return parser


_OVERWRITE = "replace existing outputs (without it, existing files are never touched)"
_IDS = "a comma list with ranges such as 0,3,5-9 (negative ids with =: --trajectories=-3,-1)"
_DT = ("give every trajectory the uniform time grid t = k*STEP (k = 0, 1, ...), for a file "
       "without times or a .mat time vector that does not fit the snapshots (a file whose own "
       "times have another step is refused)")

DATA_FORMAT = f"""\
data format: the observed states, in the layout of their file's suffix
{layouts_text()}
Trajectories may be ragged and unevenly sampled; samples within a trajectory are in time order.
With --dt STEP each trajectory gets t = 0, STEP, 2*STEP, ... (a file whose own times have
another step is refused).
"""


def _version() -> str:
    from .. import __version__

    return f"metriplex {__version__}"


def _systems_help() -> str:
    try:
        from .. import systems

        return "Built-in systems:\n\n" + "\n\n".join(
            s.help_text() for s in systems.SYSTEMS.values()
        )
    except Exception:  # the listing must never break --help
        return "Generate trajectories of a built-in ground-truth system."


def main(argv: list[str] | None = None) -> int:
    """Run the ``metriplex`` command with ``argv`` (default: ``sys.argv[1:]``); the exit status: 0
    on success, 2 on bad input (one message on stderr), 130 when interrupted, or the command's own.
    """
    parser = build_parser()
    args, extra = parser.parse_known_args(argv)
    if extra:
        parser.unrecognised(args.command, extra)
    return_large_blocks()
    try:
        with full_precision():  # float32 products in float32 on GPUs too (metriplex._precision)
            code = args.func(args)
    except MetriplexError as e:
        print(f"metriplex {args.command}: error: {e}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print(f"metriplex {args.command}: interrupted{_what_is_kept(args)}", file=sys.stderr)
        return 130
    except OSError as e:
        where = f" {str(e.filename)!r}" if e.filename else ""
        print(f"metriplex {args.command}: error: cannot access{where}: {e.strerror or e}. Check "
              "the path and its permissions.", file=sys.stderr)
        return EXIT_BAD_INPUT
    return code or 0


def _what_is_kept(args: argparse.Namespace) -> str:
    """What an interrupted ``train`` leaves: a checkpoint to resume from, or nothing (before
    the first checkpoint of its first stage)."""
    if args.command != "train" or not getattr(args, "out", None):
        return ""
    from pathlib import Path

    from ._resume import left_checkpoint

    if left_checkpoint(Path(args.out), 0):
        return f"; continue with the same command and --resume ({args.out} holds a checkpoint)"
    return (f" before its first checkpoint, so there is nothing to resume: run the same command "
            f"again with --overwrite to start over in {args.out}")


if __name__ == "__main__":
    sys.exit(main())
