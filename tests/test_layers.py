"""The core never imports the application layer (docs/design.md, 'Layers and data flow').

The application layer is ``metriplex/app/``; its modules' old paths (``metriplex.config``,
``metriplex.cli``, ...) are alias modules of it. A static scan of every import statement in
``src/metriplex`` (top level and inside functions, absolute and relative) checks that no module
outside ``metriplex/app`` imports ``metriplex.app`` or one of the aliases, and that the alias
modules are used by nobody inside the package (they exist for outside code only). The module
graph has no cycle, and no module is longer than :data:`MAX_LINES` (#15).
"""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "src" / "metriplex"

#: The public modules that moved to metriplex/app/ and whose old paths are aliases of them (the
#: private ones, ``_build``, ``_selection``, ``_lock`` and ``_commands``, have no old path).
ALIASES = ("config", "runs", "plots", "cli", "experiments")

#: The most lines a module under src/ may have (#15): a longer one is split by what its parts
#: do, into private modules that the public one re-exports.
MAX_LINES = 400

#: Core modules allowed to import the application layer, and why.
ALLOWED = {
    # ``python -m metriplex`` runs metriplex/__main__.py, which must stay at the top of the
    # package; it is the command line's entry point, part of the application in all but place.
    "metriplex.__main__": "metriplex.app.cli",
}


def _module_name(path: Path) -> tuple[str, str]:
    """``(module, package)`` of a file under src/: the names relative imports resolve against."""
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    if parts[-1] == "__init__":
        name = ".".join(parts[:-1])
        return name, name
    name = ".".join(parts)
    return name, name.rsplit(".", 1)[0]


def _imports(path: Path) -> list[tuple[int, str]]:
    """Every module an import statement of the file names, absolute, with its line: for
    ``from X import a`` both ``X`` and ``X.a`` (``a`` may be a submodule)."""
    _, package = _module_name(path)
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module or ""
            found.append((node.lineno, module))
            found += [(node.lineno, f"{module}.{alias.name}") for alias in node.names]
    return found


def _is_app(module: str) -> bool:
    parts = module.split(".")
    return len(parts) > 1 and parts[0] == "metriplex" and (parts[1] == "app" or parts[1] in ALIASES)


def _sources() -> list[Path]:
    return sorted(PACKAGE.rglob("*.py"))


def test_the_scan_sees_the_package():
    names = {_module_name(p)[0] for p in _sources()}
    assert {"metriplex.app.cli", "metriplex.diagnostics", "metriplex.verdict"} <= names
    # the scanner resolves relative imports: runs imports plots as ``from . import plots``
    runs = PACKAGE / "app" / "runs.py"
    assert "metriplex.app.plots" in {m for _, m in _imports(runs)}


def test_the_core_never_imports_the_application_layer():
    bad = []
    for path in _sources():
        name, _ = _module_name(path)
        if name == "metriplex.app" or name.startswith("metriplex.app."):
            continue
        if name.split(".")[-1] in ALIASES and name.count(".") == 1:
            continue  # the alias modules themselves
        for line, module in _imports(path):
            if _is_app(module) and ALLOWED.get(name) != module.rsplit(".", 1)[0] \
                    and ALLOWED.get(name) != module:
                bad.append(f"{name} ({path.relative_to(PACKAGE.parent)}:{line}) imports {module}")
    assert not bad, ("the core imports the application layer (metriplex/app), which only the "
                     "application may do:\n" + "\n".join(bad))


def test_the_application_layer_uses_its_own_paths_not_the_aliases():
    bad = []
    for path in _sources():
        name, _ = _module_name(path)
        for line, module in _imports(path):
            parts = module.split(".")
            if len(parts) > 1 and parts[0] == "metriplex" and parts[1] in ALIASES:
                bad.append(f"{name} ({path.relative_to(PACKAGE.parent)}:{line}) imports "
                           f"{module}; import metriplex.app.{'.'.join(parts[1:])}")
    assert not bad, "inside the package, import the application layer from metriplex.app:\n" + \
        "\n".join(bad)


def test_the_old_paths_are_the_same_modules():
    import importlib

    for alias in ALIASES:
        old = importlib.import_module(f"metriplex.{alias}")
        new = importlib.import_module(f"metriplex.app.{alias}")
        assert old is new, alias


def test_only_public_modules_keep_an_old_path():
    # A private module's old path is no promise to anyone: the core holds no alias of one.
    for private in ("_build", "_selection", "_lock", "_commands"):
        assert not (PACKAGE / f"{private}.py").exists(), private


def test_no_import_cycle_among_the_modules():
    """The module graph of the package (top-level imports and those inside functions alike)
    has no cycle, packages aside (a package's ``__init__`` importing its own modules, which
    import from the package, is how packages re-export)."""
    names = {_module_name(p)[0]: p for p in _sources()}
    graph: dict[str, set[str]] = {}
    for name, path in names.items():
        by_line: dict[int, list[str]] = {}
        for line, module in _imports(path):
            by_line.setdefault(line, []).append(module)
        edges = set()
        for modules in by_line.values():
            # ``from P import m``: the edge goes to the module P.m where there is one, else to P
            base, rest = modules[0], modules[1:]
            if rest and all(m.startswith(base + ".") for m in rest):
                exact = [m for m in rest if m in names]
                modules = exact or [base]
            for module in modules:
                while module and module not in names:
                    module = module.rpartition(".")[0]
                if module and module != name:
                    edges.add(module)
        graph[name] = edges
    aliases = {f"metriplex.{a}" for a in ALIASES}
    cycles = []
    state: dict[str, int] = {}

    def visit(node: str, stack: list[str]) -> None:
        state[node] = 1
        for nxt in sorted(graph[node]):
            if nxt in aliases:
                continue
            if state.get(nxt) == 1:
                cycles.append(" -> ".join(stack[stack.index(nxt):] + [nxt]))
            elif nxt not in state:
                visit(nxt, stack + [nxt])
        state[node] = 2

    for node in sorted(graph):
        if node not in state:
            visit(node, [node])
    assert not cycles, "import cycles:\n" + "\n".join(cycles)


def test_no_module_is_longer_than_the_limit():
    """Every module under src/ (the package and anything beside it) has at most
    :data:`MAX_LINES` lines."""
    sources = sorted(PACKAGE.parent.rglob("*.py"))
    assert PACKAGE / "diagnostics.py" in sources
    long = []
    for path in sources:
        lines = len(path.read_text(encoding="utf-8").splitlines())
        if lines > MAX_LINES:
            long.append(f"{path.relative_to(PACKAGE.parent.parent)}: {lines} lines")
    assert not long, (f"modules longer than {MAX_LINES} lines; split each by what its parts do "
                      "(a private module, re-exported):\n" + "\n".join(long))
