"""Every public function, class and method of metriplex has a docstring and annotations, and
every docstring of the package keeps the one house style (#15).

The style is the one most of the package already wrote, in the manner of Equinox and Diffrax:

- the first line, on the opening quotes, is the summary: what a function returns or a class is
  (a noun phrase: "The relative error of ..."), or an imperative for a function called for its
  effect ("Write data as ..."); never "Returns ..." or "This function ...";
- arguments are described in prose, each named in double backticks; no NumPy ("Parameters"
  underlined with dashes) or Google ("Args:") sections;
- mathematics in reST: the :math: role inline, the math directive displayed; a docstring with a
  backslash is a raw string, never one with escaped backslashes, and there is no dollar math;
- examples in Markdown fences opened with a language (python; text or bash for a layout or a
  command), never doctest prompts or reST literal blocks;
- triple double quotes.

The public API is what a user reaches without an underscore: every module of src/metriplex
whose dotted name has no part starting with one, and in it the names of its __all__ or, without
one, the functions and classes it defines (a package's __init__: every public function or class
it holds). A method is public when its name has no underscore, or is __call__; it may inherit
its docstring from the method it overrides (the abstract bases document the interface once).
The annotations of the same functions are checked here by introspection; the static scan of
every function of the package is tests/test_annotations.py. The style checks read every
docstring of the package, private ones included (AST only).
"""

from __future__ import annotations

import ast
import importlib
import inspect
import pkgutil
import re
from pathlib import Path

import metriplex

PACKAGE = Path(metriplex.__file__).resolve().parent

#: Gaps allowed for a while (none now); each entry must still be a gap, so the list only
#: shrinks.
KNOWN_GAPS: frozenset[str] = frozenset()


# -- the public API, by introspection ---------------------------------------------------------

def _public_modules() -> list:
    modules, seen = [], set()
    names = ["metriplex"] + [
        info.name for info in pkgutil.walk_packages(metriplex.__path__, "metriplex.")
        if not any(part.startswith("_") for part in info.name.split(".")[1:])
    ]
    for name in sorted(names):
        module = importlib.import_module(name)
        if id(module) not in seen:  # the alias modules (metriplex.cli, ...) are the app's own
            seen.add(id(module))
            modules.append(module)
    return modules


def _is_ours(obj: object) -> bool:
    return (inspect.isclass(obj) or inspect.isfunction(obj)) and \
        getattr(obj, "__module__", "").startswith("metriplex")


def _public_objects(module) -> dict[str, object]:
    """``qualified name -> object`` of the public functions and classes of ``module``."""
    if hasattr(module, "__all__"):
        names = [n for n in module.__all__ if not n.startswith("_")]
    else:
        is_package = Path(module.__file__).name == "__init__.py"
        names = [n for n, obj in vars(module).items() if not n.startswith("_") and _is_ours(obj)
                 and (is_package or obj.__module__ == module.__name__)]
    return {f"{module.__name__}.{n}": getattr(module, n) for n in names
            if _is_ours(getattr(module, n))}


def _own_doc(obj: object) -> str | None:
    doc = vars(obj).get("__doc__") if inspect.isclass(obj) else getattr(obj, "__doc__", None)
    # A dataclass or NamedTuple without a docstring gets its signature as one.
    if inspect.isclass(obj) and doc and doc.startswith(f"{obj.__name__}("):
        return None
    return doc if doc and doc.strip() else None


def _function_of(member: object) -> object | None:
    """The function behind a class attribute (method, property, static or class method)."""
    if isinstance(member, (staticmethod, classmethod)):
        return member.__func__
    if isinstance(member, property):
        return member.fget
    member = getattr(member, "method", member)  # Equinox wraps the methods of a Module
    return member if inspect.isfunction(member) else None


def _method_doc(cls: type, name: str) -> str | None:
    """The docstring of method ``name`` of ``cls``, or of the nearest one it overrides."""
    for base in cls.__mro__:
        fn = _function_of(vars(base).get(name))
        if fn is not None and fn.__doc__ and fn.__doc__.strip():
            return fn.__doc__
    return None


def _unannotated(fn: object) -> list[str]:
    try:
        signature = inspect.signature(fn)
    except (TypeError, ValueError):
        return []
    params = list(signature.parameters.values())
    if params and params[0].name in ("self", "cls"):
        params = params[1:]
    gaps = [p.name for p in params if p.annotation is inspect.Parameter.empty]
    if signature.return_annotation is inspect.Signature.empty:
        gaps.append("return")
    return gaps


def api_gaps() -> list[str]:
    """``name: what is missing`` for every public function, class or method that lacks a
    docstring or an annotation."""
    gaps, done = [], set()
    for module in _public_modules():
        if not (module.__doc__ or "").strip():
            gaps.append(f"{module.__name__}: no module docstring")
        for obj in _public_objects(module).values():
            if id(obj) in done:
                continue
            done.add(id(obj))
            name = f"{obj.__module__}.{obj.__qualname__}"
            if _own_doc(obj) is None:
                gaps.append(f"{name}: no docstring")
            if inspect.isfunction(obj):
                missing = _unannotated(obj)
                if missing:
                    gaps.append(f"{name}: no annotation for {', '.join(missing)}")
                continue
            for attr, member in vars(obj).items():
                if attr.startswith("_") and attr != "__call__":
                    continue
                fn = _function_of(member)
                if fn is None:
                    continue
                if _method_doc(obj, attr) is None:
                    gaps.append(f"{name}.{attr}: no docstring")
                missing = _unannotated(fn)
                if missing:
                    gaps.append(f"{name}.{attr}: no annotation for {', '.join(missing)}")
    return gaps


# -- the style, by AST ------------------------------------------------------------------------

_SECTION = re.compile(
    r"^\s*(Parameters|Returns?|Raises|Args|Arguments|Attributes|Examples?|Notes|Yields|"
    r"See Also|References)\s*:?\s*\n\s*(-{3,}|\S)|^\s*(Args|Arguments|Returns|Raises|Yields|"
    r"Examples?|Attributes):\s*$|^\s*-{3,}\s*$",
    re.MULTILINE,
)
_FENCE = re.compile(r"^\s*```(.*)$", re.MULTILINE)
_FENCE_LANGUAGES = ("python", "text", "bash")
_RETIRED_OPENINGS = re.compile(
    r"^(Returns?|Computes|Calculates|Gets|Creates|Builds|Solves|Evaluates|This (function|method"
    r"|class)|Function|Method|Class|Helper)\b"
)


def style_problems(source: str, where: str = "<string>") -> list[str]:
    """``where name: problem (line N)`` for every docstring of ``source`` that leaves the style."""
    problems = []
    tree = ast.parse(source)
    for node in ast.walk(tree):
        if not isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef,
                                 ast.AsyncFunctionDef)):
            continue
        body = node.body
        if not (body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant)
                and isinstance(body[0].value.value, str)):
            continue
        literal = body[0].value
        text = literal.value
        raw = ast.get_source_segment(source, literal) or ""
        name = getattr(node, "name", "<module>")

        def problem(what: str) -> None:
            problems.append(f"{where} {name}: {what} (line {getattr(node, 'lineno', 1)})")

        prefix = re.match(r"^[rRuU]*", raw).group(0)
        if not raw[len(prefix):].startswith('"""'):
            problem("not in triple double quotes")
        elif raw[len(prefix) + 3:len(prefix) + 4] in ("\n", ""):
            problem("summary not on the opening line")
        if "r" not in prefix.lower() and "\\\\" in raw:
            problem("escaped backslash (write a raw docstring, r\"\"\")")
        if _SECTION.search(text):
            problem("NumPy/Google section header")
        if ">>>" in text:
            problem("doctest example (use a ```python fence)")
        if re.search(r"::\s*$", text, re.MULTILINE) and not all(
                m.group(0).lstrip().startswith(".. math::")
                for m in re.finditer(r"^.*::\s*$", text, re.MULTILINE)):
            problem("reST literal block '::' (use a ``` fence)")
        if re.search(r"(?<![\\`])\$[^$\n`]+\$", text):
            problem("$...$ math (use :math:`...`)")
        fences = _FENCE.findall(text)
        for opening in fences[::2]:
            if opening.strip() not in _FENCE_LANGUAGES:
                problem(f"fence ```{opening.strip()} (open with ```python, ```text or ```bash)")
        if len(fences) % 2:
            problem("unclosed ``` fence")
        if _RETIRED_OPENINGS.match(text.strip()):
            problem(f"summary opens with {text.split()[0]!r} (say what it is or returns)")
    return problems


def package_style_problems() -> list[str]:
    problems = []
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE).as_posix()
        problems += style_problems(path.read_text(encoding="utf-8"), rel)
    return problems


def _new(report: list[str]) -> list[str]:
    """The entries of ``report`` that are not known gaps (a style entry ends with its line)."""
    return [r for r in report if not any(r.startswith(k) for k in KNOWN_GAPS)]


# -- tests ------------------------------------------------------------------------------------

def test_the_style_rules_on_examples():
    source = '''
def numpy(a):
    """The thing.

    Parameters
    ----------
    a:
        A number.
    """
def google(a):
    """The thing.

    Args:
        a: a number.
    """
def doctest():
    """The thing.

    >>> doctest()
    """
def literal():
    """The thing::

        thing()
    """
def dollars():
    """The field $L\\\\nabla E$."""
def tagless():
    """The thing.

    ```
    thing()
    ```
    """
def returns():
    """Returns the thing."""
def late():
    """
    The thing.
    """
def single():
    \'\'\'The thing.\'\'\'
def good(a):
    r"""The thing :math:`L\\nabla E` of ``a`` (a number).

    .. math:: \\dot x = L\\nabla E

    ```python
    good(1)
    ```
    """
'''
    found = {line.split()[1].rstrip(":") for line in style_problems(source)}
    assert found == {"numpy", "google", "doctest", "literal", "dollars", "tagless",
                          "returns", "late", "single"}
    assert "escaped backslash" in " ".join(p for p in style_problems(source) if "dollars" in p)


def test_every_docstring_keeps_the_style():
    new = _new(package_style_problems())
    assert not new, (
        "these docstrings leave the house style (see this test's module docstring):\n"
        + "\n".join(new)
    )


def test_the_scan_sees_the_public_api():
    modules = {m.__name__ for m in _public_modules()}
    assert {"metriplex", "metriplex.structure.potential", "metriplex.systems.zoo.rlc_circuit",
            "metriplex.app.plots", "metriplex.integrate", "metriplex.io"} <= modules
    assert not any("._" in name for name in modules)
    names = {}
    for module in _public_modules():
        names.update(_public_objects(module))
    assert {"metriplex.fit", "metriplex.GenericModel", "metriplex.integrate.solve",
            "metriplex.structure.potential.MLPPotential", "metriplex.io.read"} <= set(names)
    assert len(names) > 150


def test_the_scan_finds_a_gap(monkeypatch):
    from metriplex.structure import potential

    monkeypatch.setattr(potential.SumOf, "__doc__", None)
    monkeypatch.setattr(potential.SumOf.spec, "__doc__", None)
    gaps = api_gaps()
    assert "metriplex.structure.potential.SumOf: no docstring" in gaps
    # spec inherits the abstract base's docstring: no gap while the base documents it.
    assert "metriplex.structure.potential.SumOf.spec: no docstring" not in gaps


def test_every_public_function_class_and_method_has_a_docstring_and_annotations():
    new = _new(api_gaps())
    assert not new, (
        f"{len(new)} public name(s) lack a docstring or an annotation:\n" + "\n".join(new)
    )


def test_the_known_gaps_are_still_gaps():
    report = api_gaps() + package_style_problems()
    stale = sorted(k for k in KNOWN_GAPS if not any(r.startswith(k) for r in report))
    assert not stale, "these known gaps are fixed; remove them from KNOWN_GAPS:\n" + "\n".join(
        stale)
