"""Tests use no ``_private`` name of the package, imported or read as a module attribute
(``jit._prune``): a test that needs one is testing an implementation detail, and the name
cannot move without breaking it."""

from __future__ import annotations

import ast
from pathlib import Path

TESTS = Path(__file__).resolve().parents[1]


def private_imports(root: Path) -> list[str]:
    out = []
    for path in sorted(root.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("vnav_graph"):
                out += [f"{path.relative_to(root).as_posix()}:{node.lineno}: {a.name}"
                        for a in node.names if a.name.startswith("_")
                        and not a.name.startswith("__")]
            elif isinstance(node, ast.Import):
                out += [f"{path.relative_to(root).as_posix()}:{node.lineno}: {a.name}"
                        for a in node.names if a.name.startswith("vnav_graph")
                        and any(p.startswith("_") and not p.startswith("__")
                                for p in a.name.split("."))]
    return out


def _package_modules(tree: ast.AST) -> set[str]:
    """Local names bound to a vnav_graph module or object by this file's imports."""
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("vnav_graph"):
            names |= {a.asname or a.name for a in node.names}
        elif isinstance(node, ast.Import):
            names |= {a.asname or a.name.split(".")[0] for a in node.names
                      if a.name.startswith("vnav_graph")}
    return names


def private_attributes(root: Path) -> list[str]:
    """``name._private`` reads, and ``monkeypatch.setattr(name, "_private", …)``, where
    ``name`` is bound by an import from vnav_graph."""
    out = []
    for path in sorted(root.rglob("*.py")):
        tree = ast.parse(path.read_text())
        mods = _package_modules(tree)
        where = path.relative_to(root).as_posix()
        for node in ast.walk(tree):
            if (isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name)
                    and node.value.id in mods and node.attr.startswith("_")
                    and not node.attr.startswith("__")):
                out.append(f"{where}:{node.lineno}: {node.value.id}.{node.attr}")
            elif (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                  and node.func.attr == "setattr" and len(node.args) >= 2
                  and isinstance(node.args[0], ast.Name) and node.args[0].id in mods
                  and isinstance(node.args[1], ast.Constant)
                  and str(node.args[1].value).startswith("_")
                  and not str(node.args[1].value).startswith("__")):
                out.append(f"{where}:{node.lineno}: {node.args[0].id}.{node.args[1].value}")
    return out


def test_tests_import_no_private_names():
    assert not private_imports(TESTS), private_imports(TESTS)


def test_tests_read_no_private_attributes():
    assert not private_attributes(TESTS), private_attributes(TESTS)


def test_the_finder_sees_a_private_attribute(tmp_path):
    (tmp_path / "t.py").write_text("from vnav_graph import jit\n"
                                   "import numpy as np\n"
                                   "jit._prune(1, 2)\n"
                                   "np._core\n"
                                   "def f(monkeypatch):\n"
                                   "    monkeypatch.setattr(jit, '_x', 1)\n")
    assert private_attributes(tmp_path) == ["t.py:3: jit._prune", "t.py:6: jit._x"]


def test_the_finder_sees_a_private_import(tmp_path):
    (tmp_path / "t.py").write_text("from vnav_graph.util.jit import _prune, KEEP_CACHES\n"
                                   "import vnav_graph.io.readers._common as c\n"
                                   "from vnav_graph import __version__\n")
    assert private_imports(tmp_path) == ["t.py:1: _prune", "t.py:2: vnav_graph.io.readers._common"]
