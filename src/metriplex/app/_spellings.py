"""What ``--energy``, ``--entropy``, ``--poisson`` and ``--friction`` may say, and the block
each spelling makes: one :class:`Spelling` per value, in one table per option.

The command line's help lists the tables' help texts, :func:`metriplex.app.config.validate`
accepts their keys and checks their arguments, and :func:`metriplex.app._build.build_model`
makes the blocks from them. Offering a new block on the command line is one line in a table
(with the function that makes it, if it needs more than its constructor).
"""

from __future__ import annotations

import dataclasses
from typing import Any, Callable, NamedTuple

import jax

from .._errors import MetriplexError
from ..io import read_matrix
from ..structure._registry import from_spec
from ..structure.confinement import Confinement
from ..structure.constant import ConstantFriction, ConstantPoisson
from ..structure.friction import (CholeskyFriction, ExchangeFriction, ProjectedCholeskyFriction,
                                  ZeroFriction)
from ..structure.lie_poisson import LiePoisson, ProjectedLiePoisson
from ..structure.local import Lattice, LocalFriction, LocalPotential
from ..structure.poisson import CanonicalPoisson, ZeroPoisson
from ..structure.potential import FeatureMap, MLPPotential, SumOf, ZeroPotential
from ..structure.scaling import Scaling


class Learn(NamedTuple):
    """What a learned block is made from: ``n`` variables, the network's ``net`` settings
    (width, depth, activation), the training states ``x``, the block's own scales
    (``output_scale`` of a potential, ``scaling`` of L or M), whether its degeneracy is
    ``exact``, the ``features`` it sees, a ``quadratic`` term, a ``confinement`` wall, a
    ``linear`` term (the energy's, for temperatures read from the data), its
    PRNG ``key``, the option's ``argument`` (the text after the colon, e.g. ``10`` of
    ``local:10``) and the ``entropy_variables`` of a given sum (a Lie–Poisson L is not linear
    in them)."""

    n: int
    net: dict[str, Any]
    x: Any
    key: jax.Array
    output_scale: float = 1.0
    scaling: Scaling | None = None
    exact: bool = False
    features: FeatureMap | None = None
    quadratic: bool = False
    confinement: Confinement | None = None
    linear: bool = False
    argument: str = ""
    entropy_variables: tuple[int, ...] = ()


@dataclasses.dataclass(frozen=True)
class Spelling:
    """One value of a structure option. ``help``: what ``--help`` lists. A block the user
    gives has ``given(argument, n)``, which checks the text after the colon against data with
    ``n`` variables and makes the block; a learned one has ``learned(Learn)`` and, where it
    fits only some data or takes an argument, ``check(argument, n)``."""

    help: str
    given: Callable[[str, int], Any] | None = None
    learned: Callable[[Learn], Any] | None = None
    check: Callable[[str, int], None] | None = None


def indices(text: str, n: int, option: str) -> tuple[int, ...]:
    """The comma-separated variable indices ``text`` of ``option``, each in ``[0, n)``."""
    try:
        idx = tuple(int(v) for v in text.split(",") if v.strip() != "")
    except ValueError:
        raise MetriplexError(
            f"{option} expects comma-separated integer indices (e.g. 8,9); got {text!r}."
        ) from None
    if not idx:
        raise MetriplexError(
            f"{option} names no variable; got {text!r}. Give at least one index, counted from "
            "0 after `trajectory` and `t` (e.g. 2)."
        )
    bad = [i for i in idx if not 0 <= i < n]
    if bad:
        raise MetriplexError(
            f"{option} indices must lie in [0, {n - 1}] for data with {n} variables; got "
            f"{list(idx)}. Count state columns from 0 (after `trajectory` and `t`)."
        )
    twice = sorted({i for i in idx if idx.count(i) > 1})
    if twice:
        raise MetriplexError(
            f"{option} indices must be distinct; got {list(idx)}, which repeats {twice}. "
            f"Name each variable once (e.g. {','.join(str(i) for i in dict.fromkeys(idx))})."
        )
    return idx


def _canonical(argument: str, n: int) -> CanonicalPoisson:
    try:
        K = int(argument)
    except ValueError:
        raise MetriplexError(
            f"--poisson canonical:K needs an integer K (the number of position/momentum "
            f"pairs); got 'canonical:{argument}'."
        ) from None
    if n < 2:
        raise MetriplexError(
            f"--poisson canonical:{K} needs at least one position and one momentum (n >= 2 "
            f"variables), but the data have n={n}. Use --poisson zero (no reversible part) "
            "or give data with more variables."
        )
    if K < 1:
        raise MetriplexError(
            f"--poisson canonical:K needs K >= 1 position/momentum pairs; got K={K}. Use "
            f"canonical:K with 1 <= K <= {n // 2} for these n={n} variables."
        )
    if 2 * K > n:
        raise MetriplexError(
            f"--poisson canonical:{K} needs 2K <= n (K positions then K momenta), but the data "
            f"have n={n} variables. Use canonical:K with 1 <= K <= {n // 2}."
        )
    return CanonicalPoisson(n, K)


def _three(argument: str, n: int) -> None:
    if n != 3:
        raise MetriplexError(f"--poisson casimir3 is for 3 state variables; the data have {n}.")


def _potential(b: Learn) -> MLPPotential:
    return MLPPotential(b.n, features=b.features, data=b.x, output_scale=b.output_scale,
                        quadratic=b.quadratic, confinement=b.confinement, linear=b.linear,
                        key=b.key, **b.net)


def _from_file(cls, path: str, key: str, n: int):
    """The constant block ``cls`` of the matrix ``key`` in the file ``path``; its refusal names
    the file."""
    matrix = read_matrix(path, key, n)
    try:
        return cls(matrix)
    except MetriplexError as e:
        option = "--poisson" if key == "L" else "--friction"
        raise MetriplexError(f"{option} file:{path}: {e}") from None


def _network_poisson(kind: str, exact_kind: str) -> Callable[[Learn], Any]:
    def make(b: Learn) -> Any:
        chosen = exact_kind if b.exact else kind
        if chosen == "neural" and b.n == 2:
            # a(x) J of one sign: E, always learned on the command line, takes the sign.
            chosen = "planar"
        spec = {"kind": chosen, **b.net, "scaling": b.scaling.to_json()}
        return from_spec("poisson", spec, b.n, key=b.key)

    return make


def lattice(argument: str, n: int, option: str) -> Lattice:
    """The :class:`~metriplex.structure.Lattice` of ``option``'s
    ``local:CELLS[,periodic][,shared]``."""
    cells, *words = [w.strip() for w in argument.split(",")]
    bad = [w for w in words if w not in ("periodic", "shared")]
    if bad or len(set(words)) != len(words):
        raise MetriplexError(
            f"{option} local:CELLS takes the number of cells, then ',periodic' for a ring and "
            f"',shared' for cells that are alike (one network for every bond); got "
            f"'local:{argument}'. Example: local:10 or local:8,periodic,shared.")
    try:
        count = int(cells)
    except ValueError:
        raise MetriplexError(
            f"{option} local:CELLS needs an integer number of cells (the state holds the same "
            f"fields in every cell, stored field by field); got 'local:{argument}'. Example: "
            "local:10.") from None
    return Lattice(count, n, periodic="periodic" in words, shared="shared" in words)


def _lattice_check(option: str) -> Callable[[str, int], None]:
    def check(argument: str, n: int) -> None:
        lattice(argument, n, option)

    return check


def _local_energy(b: Learn) -> LocalPotential:
    # (--features for a local block is refused with the other options, by validate.)
    if b.quadratic:
        raise MetriplexError(
            "--energy local reads each bond's own variables: it takes no --quadratic. Leave "
            "it out, or use --energy neural.")
    return LocalPotential(lattice(b.argument, b.n, "--energy"), data=b.x,
                          output_scale=b.output_scale, confinement=b.confinement, key=b.key,
                          **b.net)


def _local_friction(b: Learn) -> LocalFriction:
    return LocalFriction(lattice(b.argument, b.n, "--friction"), scaling=b.scaling, key=b.key,
                         **b.net)


def _friction(b: Learn) -> CholeskyFriction | ProjectedCholeskyFriction:
    cls = ProjectedCholeskyFriction if b.exact else CholeskyFriction
    return cls(b.n, **b.net, scaling=b.scaling, features=b.features, data=b.x, key=b.key)


def _lie_poisson(b: Learn) -> LiePoisson | ProjectedLiePoisson:
    """``lie-poisson``: linear in every variable but the given entropy ones, whose zero is
    arbitrary (:class:`~metriplex.structure.lie_poisson.LiePoisson`)."""
    rest = tuple(k for k in range(b.n) if k not in b.entropy_variables)
    return (ProjectedLiePoisson if b.exact else LiePoisson)(
        b.n, scaling=b.scaling, key=b.key,
        linear_in=rest if b.entropy_variables and rest else None)


LOCAL_HELP = ("local:CELLS[,periodic][,shared] (a sum of terms over neighbouring cells, "
              "one network per bond or, shared, one for all; the state holds the same fields "
              "in every cell, stored field by field)")
ENERGY = {
    "neural": Spelling("neural (default)", learned=_potential),
    "local": Spelling(LOCAL_HELP, learned=_local_energy,
                      check=_lattice_check("--energy")),
}
ENTROPY = {
    "neural": Spelling("neural (default)", learned=_potential),
    "sum": Spelling("sum:I,J,... (S = sum of those components, counted from 0)",
                    given=lambda a, n: SumOf(indices(a, n, "--entropy sum:I,J,..."))),
    "zero": Spelling("zero", given=lambda a, n: ZeroPotential()),
}
POISSON = {
    "neural": Spelling("neural (default; of one sign, a(x) J, for two variables)",
                       learned=_network_poisson("neural", "projected-neural")),
    "canonical": Spelling("canonical:K (first K positions, next K momenta)", given=_canonical),
    "zero": Spelling("zero", given=lambda a, n: ZeroPoisson(n)),
    "casimir3": Spelling("casimir3 (n = 3, Jacobi exact)",
                         learned=_network_poisson("casimir3", "casimir3-entropy"), check=_three),
    "lie-poisson": Spelling("lie-poisson (learned, linear in the state)",
                            learned=_lie_poisson),
    "file": Spelling("file:PATH (a constant L from .npy, .npz or .mat)",
                     given=lambda a, n: _from_file(ConstantPoisson, a, "L", n)),
}
FRICTION = {
    "neural": Spelling("neural (default)", learned=_friction),
    "exchange": Spelling("exchange (pairwise exchange between variables; M grad E = 0 exactly)",
                         learned=lambda b: ExchangeFriction(b.n, **b.net, scaling=b.scaling,
                                                            key=b.key)),
    "local": Spelling(LOCAL_HELP.replace("a sum", "M grad E = 0 exactly; a sum"),
                      learned=_local_friction,
                      check=_lattice_check("--friction")),
    "zero": Spelling("zero", given=lambda a, n: ZeroFriction(n)),
    "file": Spelling("file:PATH (a constant M from .npy, .npz or .mat)",
                     given=lambda a, n: _from_file(ConstantFriction, a, "M", n)),
}
#: The tables by option.
SPELLINGS = {"--energy": ENERGY, "--entropy": ENTROPY, "--poisson": POISSON,
             "--friction": FRICTION}
