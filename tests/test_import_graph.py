"""The module import graph: no circles, and the ground floor (io, plots, papers, reference, ...)
imports nothing above it. Read from the source with ``ast`` (imports inside functions count too)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PKG = Path(__file__).resolve().parents[1] / "deltajax"

#: modules that must not import any other deltajax module outside their own package
GROUND = ["io", "papers.py", "reference.py", "eigen3.py", "fields.py", "_precision.py", "schemas.py", "regular.py", "plots"]


def _module_file(parts: list[str]) -> Path | None:
    p = PKG.joinpath(*parts)
    if p.with_suffix(".py").is_file():
        return p.with_suffix(".py")
    if (p / "__init__.py").is_file():
        return p / "__init__.py"
    return None


def _imports(path: Path) -> set[Path]:
    """deltajax files imported by ``path`` (``from . import x`` counts as importing module ``x``)."""
    here = list(path.relative_to(PKG).parts[:-1])
    out: set[Path] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = here[:len(here) - node.level + 1]
            elif node.module and node.module.split(".")[0] == "deltajax":
                base = []
            else:
                continue
            mod = [m for m in (node.module or "").split(".") if m]
            if not node.level:
                mod = mod[1:]
            target = _module_file(base + mod)
            if target is not None and target.name != "__init__.py":
                out.add(target)
                continue
            for alias in node.names:  # ``from . import x`` / ``from .pkg import sub``
                sub = _module_file(base + mod + [alias.name])
                out.add(sub if sub is not None else target)
        elif isinstance(node, ast.Import):
            for alias in node.names:
                parts = alias.name.split(".")
                if parts[0] == "deltajax" and len(parts) > 1:
                    out.add(_module_file(parts[1:]))
    out.discard(None)
    out.discard(path)
    return out


@pytest.fixture(scope="module")
def graph() -> dict[Path, set[Path]]:
    return {p: _imports(p) for p in PKG.rglob("*.py")}


@pytest.mark.slow
def test_no_import_circles(graph):
    """No set of modules imports each other in a loop (package faces ``__init__.py`` only hand names on and are
    left out, as farm-studio does)."""
    g = {a: {b for b in bs if b.name != "__init__.py"} for a, bs in graph.items() if a.name != "__init__.py"}
    index, low, stack, on, cycles, n = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = n[0]
        n[0] += 1
        stack.append(v)
        on.add(v)
        for w in g.get(v, ()):
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
                cycles.append(sorted(str(c.relative_to(PKG)) for c in comp))

    for v in list(g):
        if v not in index:
            visit(v)
    assert cycles == []


@pytest.mark.parametrize("name", GROUND)
def test_ground_floor_imports_nothing_above(graph, name):
    root = PKG / name
    own = [root] if root.is_file() else list(root.rglob("*.py"))
    up = {str(t.relative_to(PKG)) for f in own for t in graph[f]
          if not (root.is_dir() and root in t.parents)}
    assert up == set(), f"{name} imports {sorted(up)}"
