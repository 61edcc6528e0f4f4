"""The package's layout (issue 23): no import cycles, imports one way between the rooms, no
internal import of an old module path, and the old paths still import with a warning.

The imports are read with ``ast`` from the source, every one of them: at a module's top and
inside functions (an import hidden in a function still ties the two modules together); only
those under ``if TYPE_CHECKING:`` are left out (they never run).
"""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

import pytest

import bounce_cli

PACKAGE = Path(bounce_cli.__file__).parent
ROOT = PACKAGE.parent

#: the rooms from the ground up (docs/design.md, "Rooms"): a module imports only modules of
#: its own room or of a room before it. The version, the lazy exports and the errors
#: (standard library only) come first, then the package's face (``bounce_cli/__init__.py``);
#: the paper's printed values sit low, so that anything above the analyses may compare with
#: them, while the claims and the gallery of ``bounce reproduce`` (``reproduction``) read the
#: experiments and sit above them; the Python API and the command line are the top.
ROOMS = (
    "bounce_cli.version",
    "bounce_cli.lazy",
    "bounce_cli.errors",
    "bounce_cli.memory",
    "bounce_cli",
    "bounce_cli.model",
    "bounce_cli.analysis",
    "bounce_cli.paper",
    "bounce_cli.runtime",
    "bounce_cli.data",
    "bounce_cli.virtual",
    "bounce_cli.experiments",
    "bounce_cli.reproduction",
    "bounce_cli.api",
    "bounce_cli.cli",
    "bounce_cli.__main__",
)

#: imports that still run against the order, each to be removed by the work named (then the
#: test fails until its line here goes too)
KNOWN_EXCEPTIONS: set[tuple[str, str]] = set()


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


MODULES = {module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}


def is_type_checking_block(node: ast.AST) -> bool:
    return isinstance(node, ast.If) and (
        (isinstance(node.test, ast.Name) and node.test.id == "TYPE_CHECKING")
        or (isinstance(node.test, ast.Attribute) and node.test.attr == "TYPE_CHECKING"))


def import_nodes(tree: ast.AST):
    """Every Import / ImportFrom of ``tree``, at any depth, outside TYPE_CHECKING blocks."""
    for node in ast.iter_child_nodes(tree):
        if is_type_checking_block(node):
            yield from (n for child in node.orelse for n in import_nodes_of(child))
            continue
        yield from import_nodes_of(node)


def import_nodes_of(node: ast.AST):
    if isinstance(node, (ast.Import, ast.ImportFrom)):
        yield node
    else:
        yield from import_nodes(node)


def imported_modules(module: str, path: Path) -> list[tuple[str, list[str], int]]:
    """(the module named, the names imported from it, line) of each import of bounce_cli's
    in ``path`` (relative imports resolved; a name that is a submodule gives the submodule)."""
    is_package = path.name == "__init__.py"
    found = []
    for node in import_nodes(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found += [(a.name, [], node.lineno) for a in node.names
                      if a.name.split(".")[0] == "bounce_cli"]
            continue
        if node.level:
            base = module.split(".") if is_package else module.split(".")[:-1]
            base = base[:len(base) - node.level + 1]
            target = ".".join(base + ([node.module] if node.module else []))
        else:
            target = node.module or ""
        if target.split(".")[0] != "bounce_cli":
            continue
        names = [a.name for a in node.names]
        submodules = [n for n in names if f"{target}.{n}" in MODULES]
        found += [(f"{target}.{n}", [], node.lineno) for n in submodules]
        if len(submodules) < len(names):
            found.append((target, [n for n in names if n not in submodules], node.lineno))
    return found


def import_graph() -> dict[str, set[str]]:
    """module -> the package's modules it imports."""
    graph = {}
    for module, path in MODULES.items():
        targets = set()
        for target, _, _ in imported_modules(module, path):
            while target not in MODULES and "." in target:  # a name inside a module
                target = target.rsplit(".", 1)[0]
            if target != module:
                targets.add(target)
        graph[module] = targets
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def room_of(module: str) -> int:
    """The index in :data:`ROOMS` of the room holding ``module`` (the longest match)."""
    best = max((r for r in ROOMS if module == r or module.startswith(r + ".")), key=len)
    return ROOMS.index(best)


@pytest.mark.slow
def test_the_graph_reads_imports_inside_functions_and_skips_type_checking(tmp_path):
    graph = import_graph()
    # a function-level import (cli.console imports the typer app inside main)
    assert "bounce_cli.cli.commands" in graph["bounce_cli.cli.console"]
    # bounce_cli's face names api only for type checkers
    assert "bounce_cli.api" not in graph["bounce_cli"]
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


@pytest.mark.slow
def test_no_import_cycles():
    assert cycles(import_graph()) == []


def test_imports_run_one_way_between_the_rooms():
    against = {(module, target) for module, targets in import_graph().items()
               for target in targets if room_of(target) > room_of(module)}
    assert against - KNOWN_EXCEPTIONS == set(), "imports from a room to a later one"
    assert KNOWN_EXCEPTIONS - against == set(), "an exception no longer needed: remove it"


def test_every_module_is_in_a_room():
    top_level = {m for m in MODULES
                 if m.count(".") == 1 and not (PACKAGE / m.split(".")[1]).is_dir()}
    assert top_level == {"bounce_cli.api", "bounce_cli.errors", "bounce_cli.memory",
                         "bounce_cli.lazy", "bounce_cli.version", "bounce_cli.__main__"}


#: module paths retired in 0.2.0 (CHANGELOG.md), a sample of each kind: a flat module, an
#: ``engine`` module, the ``engine`` package, the forwarding table itself
RETIRED_PATHS = ("bounce_cli.engine", "bounce_cli.engine.params", "bounce_cli.engine.control",
                 "bounce_cli.config", "bounce_cli.recordings", "bounce_cli.claims",
                 "bounce_cli.old_paths", "bounce_cli.paper.claims",
                 "bounce_cli.paper.reproduce")


@pytest.mark.parametrize("old", RETIRED_PATHS)
def test_a_retired_module_path_imports_no_more(old):
    """One import path per public name: the forwarders of the old paths are gone."""
    with pytest.raises(ModuleNotFoundError):
        importlib.import_module(old)


@pytest.mark.parametrize("package, old_name", [("bounce_cli.paper", "FIG3_MODEL"),
                                               ("bounce_cli.cli", "app")])
def test_a_package_serves_no_names_of_the_module_it_replaced(package, old_name):
    with pytest.raises(AttributeError):
        getattr(importlib.import_module(package), old_name)


def test_the_top_level_exports_still_work():
    for name in bounce_cli.__all__:
        assert getattr(bounce_cli, name) is not None
