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


def _targets(node: ast.AST, here: tuple[str, ...]) -> list[tuple[str, ...]]:
    """Dotted paths (inside the package) that one import statement names, from a file in subpackage ``here``."""
    if isinstance(node, ast.ImportFrom):
        if node.level:
            base = here[: len(here) - (node.level - 1)] if node.level - 1 <= len(here) else ()
            head = base + tuple(node.module.split(".")) if node.module else base
            return [head] if node.module else [base + (a.name,) for a in node.names]
        if node.module and node.module.split(".")[0] == "stressbots":
            parts = tuple(node.module.split(".")[1:])
            return [parts] if parts else [(a.name,) for a in node.names]
    elif isinstance(node, ast.Import):
        return [tuple(a.name.split(".")[1:]) for a in node.names if a.name.split(".")[0] == "stressbots"]
    return []


def _type_checking_only(node: ast.AST) -> bool:
    """``if TYPE_CHECKING:`` (or ``typing.TYPE_CHECKING``): a block that never runs."""
    test = getattr(node, "test", None)
    return isinstance(node, ast.If) and (
        (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING")
        or (isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")
    )


def _runtime_nodes(tree: ast.AST):
    """Every node that can run: imports inside functions count, imports for the type checker only do not
    (they never execute, so they cannot make the import order fragile)."""
    stack = [tree]
    while stack:
        node = stack.pop()
        yield node
        if _type_checking_only(node):
            stack.extend(getattr(node, "orelse", []))
            continue
        stack.extend(ast.iter_child_nodes(node))


def import_graph(package: Path = PACKAGE, *, inside: str | None = None) -> dict[str, set[str]]:
    """Module -> package modules it imports anywhere in its source (top level or inside functions).

    By default the nodes are the package's top-level modules and its subpackages (``control``, ``sim``,
    ``lab``), each subpackage one node standing for all its files. With ``inside="sim"`` the nodes are that
    subpackage's own modules (``__init__`` included) and only imports among them count.
    """
    graph: dict[str, set[str]] = {}
    if inside is None:
        nodes = {p.stem for p in package.glob("*.py")} | {p.parent.name for p in package.glob("*/__init__.py")}
        files = [(p, ()) for p in package.glob("*.py")] + [(p, (p.parent.name,)) for p in package.glob("*/*.py")]
    else:
        nodes = {p.stem for p in (package / inside).glob("*.py")}
        files = [(p, (inside,)) for p in (package / inside).glob("*.py")]
    for path, here in files:
        me = (here[0] if here else path.stem) if inside is None else path.stem
        deps = graph.setdefault(me, set())
        for node in _runtime_nodes(ast.parse(path.read_text(encoding="utf-8"))):
            for target in _targets(node, here):
                if inside is None and target:
                    deps.add(target[0])
                elif inside is not None and len(target) > 1 and target[0] == inside:
                    deps.add(target[1])
        deps &= nodes
        deps.discard(me)
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
    # the import resolver: from a file in subpackage "sim", ".x" is sim.x and "..x" the top-level x
    typed = ast.parse("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from .cli import main\ndef f():\n    from .sim import x\n")
    assert sorted(str(n.module) for n in _runtime_nodes(typed) if isinstance(n, ast.ImportFrom)) == ["sim", "typing"]
    rel = ast.parse("from .bodies import a\nfrom ..kinematics import b\nfrom . import contact\n").body
    assert [_targets(n, ("sim",)) for n in rel] == [[("sim", "bodies")], [("kinematics",)], [("sim", "contact")]]


def test_no_import_cycles_among_the_package_modules():
    graph = import_graph()
    assert "cli" in graph and "pipeline" in graph and "control" in graph  # the graph is the package's
    assert "planning" in graph["control"]  # a subpackage's imports of top-level modules count
    assert cycles(graph) == []


def test_no_import_cycles_inside_the_subpackages():
    subpackages = sorted(p.parent.name for p in PACKAGE.glob("*/__init__.py"))
    assert {"control", "sim"} <= set(subpackages)
    for sub in subpackages:
        graph = import_graph(inside=sub)
        assert cycles(graph) == [], sub
    assert "bodies" in import_graph(inside="sim")["contact"]  # relative imports inside a subpackage count


def test_library_modules_do_not_import_the_cli_or_the_console():
    graph = import_graph()
    for module, deps in graph.items():
        if module not in ("cli", "__main__"):
            assert "cli" not in deps, module
        if module not in ("cli", "demo", "console", "__main__"):
            assert "console" not in deps, module
