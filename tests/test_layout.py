"""The package's layout, read from the source: no import cycles, the stages in their packages.

The import graph is read with ``ast`` (no module is imported), counting every import wherever it
stands, inside a function or under ``TYPE_CHECKING`` too: a cycle hidden in a function is still a
cycle for a reader.
"""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent.parent / "verne_post"


def _modules() -> dict[str, tuple[Path, bool]]:
    """Dotted name -> (file, is a package's ``__init__``)."""
    modules = {}
    for path in PACKAGE.rglob("*.py"):
        parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
        init = path.name == "__init__.py"
        modules[".".join(parts[:-1] if init else parts)] = (path, init)
    return modules


def _imports(name: str, modules: dict[str, tuple[Path, bool]]) -> set[str]:
    """The package's modules that module ``name`` imports: ``from x import y`` counts as an import
    of module ``x.y`` where that is a module, else of ``x``."""
    path, init = modules[name]
    here = name.split(".") if init else name.split(".")[:-1]
    found = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom):
            base = ".".join([*here[:len(here) - node.level + 1], node.module or ""]).strip(".") if node.level \
                else node.module or ""
            targets = [f"{base}.{alias.name}" if f"{base}.{alias.name}" in modules else base for alias in node.names]
        elif isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        else:
            continue
        found.update(t for t in targets if t in modules and t != name)
    return found


def _graph() -> dict[str, set[str]]:
    modules = _modules()
    return {name: _imports(name, modules) for name in modules}


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for nxt in sorted(graph[node]):
            if nxt not in index:
                visit(nxt)
                low[node] = min(low[node], low[nxt])
            elif nxt in on_stack:
                low[node] = min(low[node], index[nxt])
        if low[node] == index[node]:
            component = []
            while True:
                top = stack.pop()
                on_stack.discard(top)
                component.append(top)
                if top == node:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return found


def test_the_reader_sees_imports() -> None:
    """The graph is not empty by mistake: known imports are found."""
    graph = _graph()
    assert "verne_post.machine" in graph["verne_post.pipeline"]
    assert "verne_post.kinematics.geometry" in graph["verne_post.kinematics.full"]
    assert "verne_post.checks.stage" in graph["verne_post.placement.search"]
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_no_import_cycles() -> None:
    assert _cycles(_graph()) == []


def test_the_kinematics_import_nothing_else_of_the_package() -> None:
    """Pure kinematics over a parameter record: the machine file uses them, not the reverse."""
    graph = _graph()
    for name, imported in graph.items():
        if name.startswith("verne_post.kinematics"):
            assert all(other.startswith("verne_post.kinematics") for other in imported), (name, imported)



def test_at_most_ten_modules_at_the_top() -> None:
    assert len(list(PACKAGE.glob("*.py"))) <= 10
