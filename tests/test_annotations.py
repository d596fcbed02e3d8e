"""Every public function and method of the package is fully annotated (#15).

The rule: every function or method in ``src/metriplex`` whose name does not start with ``_``
(private modules and methods of private classes included), plus ``__init__`` and
``__call__``, annotates each of its parameters (``*args`` and ``**kwargs`` too; not the
``self`` or ``cls`` of a method) and its return value. Other dunder methods, private names and
functions nested inside functions are exempt.

A static scan of the source (AST only: nothing is imported, so it costs no JAX start-up), which
names the file, line and function of every gap. Every module has
``from __future__ import annotations``, so annotations are never evaluated at run time.
"""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "src" / "metriplex"

#: Dunder methods that the rule covers; the others (``__repr__``, ``__add__``, ...) are exempt.
COVERED_DUNDERS = frozenset({"__init__", "__call__"})

_Function = (ast.FunctionDef, ast.AsyncFunctionDef)


def _is_public(name: str) -> bool:
    if name.startswith("__") and name.endswith("__"):
        return name in COVERED_DUNDERS
    return not name.startswith("_")


def _is_staticmethod(fn: ast.FunctionDef | ast.AsyncFunctionDef) -> bool:
    return any(isinstance(d, ast.Name) and d.id == "staticmethod" for d in fn.decorator_list)


def _missing(fn: ast.FunctionDef | ast.AsyncFunctionDef, in_class: bool) -> list[str]:
    """The parameters of ``fn`` without an annotation, in the signature's order (``*args``
    and ``**kwargs`` with their stars), and ``return`` if its return value has none."""
    args = fn.args
    positional = args.posonlyargs + args.args
    if in_class and not _is_staticmethod(fn) and positional \
            and positional[0].arg in ("self", "cls"):
        positional = positional[1:]
    params = [(a, a.arg) for a in positional]
    if args.vararg is not None:
        params.append((args.vararg, f"*{args.vararg.arg}"))
    params += [(a, a.arg) for a in args.kwonlyargs]
    if args.kwarg is not None:
        params.append((args.kwarg, f"**{args.kwarg.arg}"))
    gaps = [name for a, name in params if a.annotation is None]
    if fn.returns is None:
        gaps.append("return")
    return gaps


def _scan(tree: ast.AST) -> list[tuple[int, str, list[str]]]:
    """``(line, qualified name, gaps)`` of every public function or method of a module that
    lacks an annotation. Module-level functions (also those under ``if``/``try``) and methods
    of classes at any depth of class nesting are covered; bodies of functions are not."""
    found = []

    def visit(node: ast.AST, prefix: str, in_class: bool) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, _Function):
                if _is_public(child.name):
                    gaps = _missing(child, in_class)
                    if gaps:
                        found.append((child.lineno, prefix + child.name, gaps))
            elif isinstance(child, ast.ClassDef):
                visit(child, f"{prefix}{child.name}.", True)
            elif not isinstance(child, ast.Lambda):
                visit(child, prefix, in_class)

    visit(tree, "", False)
    return found


def unannotated(package: Path = PACKAGE) -> list[str]:
    """``file:line function (missing: ...)`` for every gap in the package at ``package``."""
    report = []
    for path in sorted(package.rglob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
        rel = path.relative_to(package.parent).as_posix()
        for line, name, gaps in _scan(tree):
            report.append(f"{rel}:{line} {name} (missing: {', '.join(gaps)})")
    return report


def _gaps_in(source: str) -> dict[str, list[str]]:
    return {name: gaps for _, name, gaps in _scan(ast.parse(source))}


def test_the_rule_on_examples():
    source = '''
def public(a, b: int, *args, c, **kw): ...
def done(a: int, *args: int, **kw: str) -> None: ...
def _private(a): ...
class _Hidden:
    def method(self, x): ...
    def __repr__(self): ...
    def __init__(self, x: int): ...
    def _helper(self, y): ...
class Shown:
    def __call__(self, x: int) -> int: ...
    @classmethod
    def make(cls, n: int) -> "Shown": ...
    @staticmethod
    def convert(value) -> int: ...
    @property
    def size(self): ...
    class Inner:
        def deep(self) -> None: ...
        def deeper(self, z: int): ...
if True:
    def conditional(q: int): ...
def outer() -> None:
    def nested(unannotated): ...
'''
    assert _gaps_in(source) == {
        "public": ["a", "*args", "c", "**kw", "return"],
        "_Hidden.method": ["x", "return"],
        "_Hidden.__init__": ["return"],
        "Shown.convert": ["value"],
        "Shown.size": ["return"],
        "Shown.Inner.deeper": ["return"],
        "conditional": ["return"],
    }


def test_the_scan_sees_the_package():
    files = sorted(PACKAGE.rglob("*.py"))
    assert len(files) > 50
    names = set()
    for path in files:
        tree = ast.parse(path.read_text(encoding="utf-8"), str(path))
        names |= {f"{path.stem}.{n.name}" for n in ast.walk(tree)
                  if isinstance(n, _Function) and _is_public(n.name)}
    assert {"train.fit", "_model.terms", "_train.make_chunk", "cli.main",
            "potential.__init__", "_layout.save_figure"} <= names
    assert len(names) > 300


def test_every_public_function_is_annotated():
    report = unannotated()
    assert not report, (
        f"{len(report)} public function(s) lack annotations (see tests/test_annotations.py for "
        "the rule; every parameter but self/cls, and the return value):\n" + "\n".join(report)
    )
