"""The on-chip front end's modules import one another one way: no import cycle among ``hdl/frontend``
(``lanes/``, ``layouts``, ``reference``, ``wordpipe``, ``words``, ``passes``, ``pipeline``, ``stereo``, ...),
counting every import at any depth: function-level ones and those under ``TYPE_CHECKING`` too (a cycle
hidden in a function is still a cycle)."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]
PACKAGE = ("bayesmachine", "hdl", "frontend")


def module_graph(folder: Path, package: tuple[str, ...]) -> dict[str, set[str]]:
    """module -> the modules of the same package tree it imports (dotted names; a package is its
    ``__init__``), from every ``import`` and ``from ... import`` at any depth of each file."""
    names = {}
    for path in folder.rglob("*.py"):
        parts = path.relative_to(folder).with_suffix("").parts
        inner = parts[:-1] if parts[-1] == "__init__" else parts
        names[".".join(package + inner)] = (path, package + (parts[:-1]))
    graph: dict[str, set[str]] = {name: set() for name in names}
    for name, (path, pkg) in names.items():
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            targets: list[str] = []
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = ".".join(pkg[: len(pkg) - node.level + 1]) if node.level else ""
                head = ".".join(p for p in (base, node.module or "") if p)
                targets = [head] + [f"{head}.{alias.name}" for alias in node.names]
            for target in targets:
                while target and target not in names:  # a name imported from a module: the module
                    target = target.rpartition(".")[0]
                if target and target != name:
                    graph[name].add(target)
    return graph


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import cycle of ``graph`` (its modules in order, the first repeated at the end), or None."""
    state: dict[str, int] = {}  # 1: on the current path, 2: done
    path: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        path.append(node)
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                return path[path.index(nxt):] + [nxt]
            if nxt not in state and (found := visit(nxt)) is not None:
                return found
        path.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state and (found := visit(node)) is not None:
            return found
    return None


def test_the_cycle_finder_sees_a_cycle_through_a_function_level_import(tmp_path: Path) -> None:
    pkg = tmp_path / "front"
    (pkg / "lanes").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "lanes" / "__init__.py").write_text("from . import kind\n")
    (pkg / "lanes" / "kind.py").write_text("def f():\n    from ..words import g\n")
    (pkg / "words.py").write_text("from .lanes import kind\n")
    graph = module_graph(pkg, ("x", "front"))
    assert graph["x.front.words"] == {"x.front.lanes", "x.front.lanes.kind"}
    assert find_cycle(graph) is not None
    (pkg / "lanes" / "kind.py").write_text("import os\n")
    assert find_cycle(module_graph(pkg, ("x", "front"))) is None


def test_no_import_cycle_in_the_front_end() -> None:
    graph = module_graph(ROOT / "hdl" / "frontend", PACKAGE)
    assert {"bayesmachine.hdl.frontend.words", "bayesmachine.hdl.frontend.lanes.consistency"} <= set(graph)
    cycle = find_cycle(graph)
    assert cycle is None, "an import cycle in hdl/frontend: " + " -> ".join(cycle or [])
