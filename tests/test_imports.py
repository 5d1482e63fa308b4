"""The package's import graph: no module imports another that imports it back, however far
round (lazy and type-checking imports count too), and no private name crosses a module."""

from __future__ import annotations

import ast
from pathlib import Path

import networkx as nx

PACKAGE = Path(__file__).resolve().parent.parent / "hapticop"


def _modules() -> dict[str, Path]:
    found = {}
    for path in PACKAGE.rglob("*.py"):
        parts = list(path.relative_to(PACKAGE.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts.pop()
        found[".".join(parts)] = path
    return found


def _imports(modules: dict[str, Path]):
    """(importer, imported module, name) for every import of a package module."""
    for module, path in modules.items():
        package = module.split(".") if path.name == "__init__.py" else module.split(".")[:-1]
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                for alias in node.names:
                    if alias.name in modules:
                        yield module, alias.name, ""
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    base = ".".join(package[: len(package) - node.level + 1] + ([node.module] if node.module else []))
                for alias in node.names:
                    if f"{base}.{alias.name}" in modules:
                        yield module, f"{base}.{alias.name}", ""
                    elif base in modules:
                        yield module, base, alias.name


def test_no_import_circle():
    modules = _modules()
    graph = nx.DiGraph((a, b) for a, b, _ in _imports(modules) if a != b)
    assert list(nx.simple_cycles(graph)) == []


def test_no_private_name_crosses_a_module():
    private = [(a, b, name) for a, b, name in _imports(_modules())
               if name.startswith("_") and not name.startswith("__")]
    assert private == []


def test_the_walk_sees_imports():
    """The checks above would pass on nothing: make sure they read the real graph."""
    edges = {(a, b) for a, b, _ in _imports(_modules())}
    assert ("hapticop.runtime.system", "hapticop.runtime.scheduler") in edges
    assert ("hapticop.composition.layers", "hapticop.composition.documents") in edges
