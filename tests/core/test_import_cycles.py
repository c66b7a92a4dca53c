"""core/ has no import cycle: not at run time, and not through type-only imports either.

A cycle hidden behind `if TYPE_CHECKING:` still means two modules that can only be read
together; the layers (commands, events and errors at the bottom, the run's domain, the
offline lab above it) keep each module's imports pointing one way.
"""

from __future__ import annotations

import ast
from pathlib import Path

CORE = Path(__file__).resolve().parents[2] / "core"


def _module(path: Path) -> str:
    parts = path.relative_to(CORE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports(tree: ast.Module, known: set[str]) -> set[str]:
    """The core modules a module imports at its top or under `if TYPE_CHECKING:`."""
    found: set[str] = set()
    body: list[ast.stmt] = list(tree.body)
    for node in tree.body:
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            body.extend(node.body)
    for node in body:
        names: list[str] = []
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
        found |= {n for n in names if n in known}
    return found


def graph() -> dict[str, set[str]]:
    """Each core module's imports of other core modules.

    Not of its own packages: `from core.sim.types import X` in `core.sim.world` runs
    `core/sim/__init__.py` first, which Python allows for (a package is set up before its
    modules) whatever that imports.
    """
    paths = {_module(p): p for p in CORE.rglob("*.py")}
    known = set(paths)
    edges = {}
    for m, p in paths.items():
        ancestors = {".".join(m.split(".")[:k]) for k in range(1, m.count(".") + 1)}
        edges[m] = _imports(ast.parse(p.read_text()), known) - {m} - ancestors
    return edges


def cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan's)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(edges.get(v, ())):
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

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return found


def test_cycles_finds_a_cycle_and_only_one() -> None:
    edges = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert cycles(edges) == [["a", "b", "c"]]
    tree = ast.parse("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    import core.x\n")
    assert _imports(tree, {"core.x"}) == {"core.x"}  # a type-only import counts


def test_core_has_no_import_cycle() -> None:
    assert cycles(graph()) == []
