"""The package's structure: no import cycles among its modules, imports inside functions included.

The intended flow is cli -> demo -> pipeline -> library, with console presentation (:mod:`console`)
beside them and never imported by the library. A cycle makes the import order fragile and hides
layering mistakes (a library module printing through the CLI), so none is allowed.
"""

from __future__ import annotations

import ast
from pathlib import Path

import stressbots

PACKAGE = Path(stressbots.__file__).parent


def import_graph(package: Path = PACKAGE) -> dict[str, set[str]]:
    """Module -> package modules it imports anywhere in its source (top level or inside functions)."""
    modules = {p.stem for p in package.glob("*.py")}
    graph: dict[str, set[str]] = {}
    for path in package.glob("*.py"):
        deps: set[str] = set()
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom):
                if node.level == 1 and node.module:
                    deps.add(node.module.split(".")[0])
                elif node.level == 1:
                    deps.update(a.name for a in node.names)
                elif node.level == 0 and node.module and node.module.split(".")[0] == "stressbots":
                    parts = node.module.split(".")
                    deps.update([parts[1]] if len(parts) > 1 else [a.name for a in node.names])
            elif isinstance(node, ast.Import):
                for a in node.names:
                    parts = a.name.split(".")
                    if parts[0] == "stressbots" and len(parts) > 1:
                        deps.add(parts[1])
        graph[path.stem] = {d for d in deps if d in modules and d != path.stem}
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                found.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_the_cycle_finder_finds_cycles():
    """The checker itself: a planted cycle (including one through a function-level import) is found."""
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []
    src = "def f():\n    from .cli import main\n"
    tree = ast.parse(src)
    assert any(isinstance(n, ast.ImportFrom) and n.module == "cli" for n in ast.walk(tree))


def test_no_import_cycles_among_the_package_modules():
    graph = import_graph()
    assert "cli" in graph and "pipeline" in graph  # the graph is the package's
    assert cycles(graph) == []


def test_library_modules_do_not_import_the_cli_or_the_console():
    graph = import_graph()
    for module, deps in graph.items():
        if module not in ("cli", "__main__"):
            assert "cli" not in deps, module
        if module not in ("cli", "demo", "console", "__main__"):
            assert "console" not in deps, module
