"""Tests import no ``_private`` name of the package: a test that needs one is testing an
implementation detail, and the name cannot move without breaking it."""

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


def test_tests_import_no_private_names():
    assert not private_imports(TESTS), private_imports(TESTS)


def test_the_finder_sees_a_private_import(tmp_path):
    (tmp_path / "t.py").write_text("from vnav_graph.jit import _prune, KEEP_CACHES\n"
                                   "import vnav_graph.io.readers._common as c\n"
                                   "from vnav_graph import __version__\n")
    assert private_imports(tmp_path) == ["t.py:1: _prune", "t.py:2: vnav_graph.io.readers._common"]
