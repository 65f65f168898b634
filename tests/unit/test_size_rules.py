"""The house's size rules, read from the source: no module in ``vnav_graph/`` over 500 lines,
no plain function over 100 lines, no numba kernel (``@njit``) over 200 lines.

``PENDING`` names the places still over their limit; the test fails on any other one, so a
new long file or function is caught when it is written.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2] / "vnav_graph"
MAX_FILE, MAX_FUNCTION, MAX_KERNEL = 500, 100, 200
PENDING: set[str] = set()


def _jitted(node: ast.FunctionDef) -> bool:
    for d in node.decorator_list:
        f = d.func if isinstance(d, ast.Call) else d
        name = f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", "")
        if name in ("njit", "jit"):
            return True
    return False


def oversized() -> list[str]:
    out = []
    for path in sorted(ROOT.rglob("*.py")):
        rel = path.relative_to(ROOT).as_posix()
        text = path.read_text()
        n = text.count("\n")
        if n > MAX_FILE:
            out.append(f"{rel} ({n} lines)")
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                length = node.end_lineno - node.lineno + 1
                limit = MAX_KERNEL if _jitted(node) else MAX_FUNCTION
                if length > limit:
                    out.append(f"{rel}:{node.name} ({length} lines)")
    return out


def test_no_file_or_function_over_its_limit():
    new = [o for o in oversized() if o.split(" (")[0] not in PENDING]
    assert not new, "over the size rules: " + "; ".join(new)


def test_the_finder_sees_a_long_function(tmp_path):
    """121 plain lines are over the limit; a 151-line kernel is not."""
    (tmp_path / "m.py").write_text("def f():\n" + "    x = 1\n" * 120 + "\n@njit\ndef k():\n"
                                   + "    y = 2\n" * 150)
    globals()["ROOT"], old = tmp_path, ROOT
    try:
        assert oversized() == ["m.py:f (121 lines)"]
    finally:
        globals()["ROOT"] = old
