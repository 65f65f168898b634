"""The package's import graph, read from the code with ``ast``, has no cycle.

Every ``import`` and ``from ... import`` counts, at module level or inside a function;
relative imports are resolved against the importing module. ``from pkg import name`` is an
edge to ``pkg.name`` when that is a module of the package, else to ``pkg``. A package's
``__init__`` is the module ``pkg``; importing ``pkg.sub`` also runs ``pkg`` but that implicit
edge is not counted (a package re-exporting its submodules is not a cycle of the code).
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = "vnav_graph"
ROOT = Path(__file__).resolve().parents[2] / PACKAGE


def module_names(root: Path = ROOT) -> dict[str, Path]:
    """Dotted module name → file, for every ``.py`` file of the package."""
    out: dict[str, Path] = {}
    for p in root.rglob("*.py"):
        parts = list(p.relative_to(root.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = p
    return out


def imports_of(name: str, path: Path, modules: dict[str, Path]) -> set[str]:
    """The package modules ``name`` (at ``path``) imports, anywhere in its code."""
    is_pkg = path.name == "__init__.py"
    base = name.split(".") if is_pkg else name.split(".")[:-1]
    found: set[str] = set()

    def add(target: str) -> None:
        while target and target not in modules:  # pkg.mod.attr -> pkg.mod
            target = target.rpartition(".")[0]
        if target and target != name:
            found.add(target)

    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            for a in node.names:
                if a.name.split(".")[0] == PACKAGE:
                    add(a.name)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                anchor = base[: len(base) - (node.level - 1)]
                mod = ".".join(anchor + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            if mod.split(".")[0] != PACKAGE:
                continue
            for a in node.names:
                sub = f"{mod}.{a.name}"
                add(sub if sub in modules else mod)
    return found


def import_graph(root: Path = ROOT) -> dict[str, set[str]]:
    modules = module_names(root)
    return {n: imports_of(n, p, modules) for n, p in modules.items()}


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One cycle ``[a, b, ..., a]`` of the directed graph, or None (iterative DFS)."""
    state: dict[str, int] = {}  # 1 on the stack, 2 done
    for start in sorted(graph):
        if state.get(start):
            continue
        stack = [(start, iter(sorted(graph[start])))]
        path = [start]
        state[start] = 1
        while stack:
            node, it = stack[-1]
            nxt = next(it, None)
            if nxt is None:
                state[node] = 2
                stack.pop()
                path.pop()
            elif state.get(nxt) == 1:
                return path[path.index(nxt):] + [nxt]
            elif not state.get(nxt):
                state[nxt] = 1
                stack.append((nxt, iter(sorted(graph.get(nxt, ())))))
                path.append(nxt)
    return None


def test_finder_sees_cycles_and_resolves_relative_imports(tmp_path: Path) -> None:
    pkg = tmp_path / PACKAGE
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "sub" / "__init__.py").write_text("from .a import f\n")
    (pkg / "sub" / "a.py").write_text("def f():\n    from ..b import g\n    return g\n")
    (pkg / "b.py").write_text("from .sub import a\n")
    graph = import_graph(pkg)
    assert graph["vnav_graph.sub.a"] == {"vnav_graph.b"}
    assert graph["vnav_graph.b"] == {"vnav_graph.sub.a"}
    assert graph["vnav_graph.sub"] == {"vnav_graph.sub.a"}
    assert find_cycle(graph) == ["vnav_graph.b", "vnav_graph.sub.a", "vnav_graph.b"]
    (pkg / "sub" / "a.py").write_text("import math\n")
    assert find_cycle(import_graph(pkg)) is None


def test_package_has_no_import_cycle() -> None:
    graph = import_graph()
    assert len(graph) > 50 and f"{PACKAGE}.cli" in graph
    cycle = find_cycle(graph)
    if cycle is not None:
        pytest.fail("import cycle: " + " -> ".join(cycle))


def _importers_of(graph: dict[str, set[str]], users: str, used: tuple[str, ...]
                  ) -> dict[str, list[str]]:
    """Modules under ``users`` that import a module under one of the ``used`` prefixes."""
    def under(m: str, prefix: str) -> bool:
        return m == prefix or m.startswith(prefix + ".")

    return {n: sorted(m for m in deps if any(under(m, u) for u in used))
            for n, deps in graph.items() if under(n, users)
            and any(under(m, u) for m in deps for u in used)}


def test_evaluation_imports_no_runner_pipeline_or_cli() -> None:
    graph = import_graph()
    banned = (f"{PACKAGE}.cli", f"{PACKAGE}.run")
    assert all(b in graph for b in banned)  # the rule names modules that exist
    bad = _importers_of(graph, f"{PACKAGE}.evaluation", banned)
    assert not bad, f"evaluation imports upward: {bad}"


def test_graph_rooms_import_nothing_from_batch() -> None:
    """The model, the shared solver and the incremental front end stand without graph-batch:
    ``isam2/``, ``model/`` and ``solver/`` import nothing from ``batch/``."""
    graph = import_graph()
    g = f"{PACKAGE}.estimators.graph"
    assert f"{g}.batch.smoother" in graph and f"{g}.solver.outputs" in graph
    for room in ("isam2", "model", "solver"):
        bad = _importers_of(graph, f"{g}.{room}", (f"{g}.batch",))
        assert not bad, f"{room}/ imports batch/: {bad}"
