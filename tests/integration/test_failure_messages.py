"""Every ``error`` in ``summary.json`` names what failed and why: never empty, never a bare
exception type ending in ": " (GTSAM's C++ exceptions reach Python with a message that starts
with a newline, or none)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from vnav_graph.cli import main
from vnav_graph.estimators.base import create

GTSAM_LIKE = ("\nIndeterminate linear system detected while working near variable\n"
              "7061644215716937825 (Symbol: b97).\n")


def _errors(out: Path) -> dict[str, str]:
    s = json.loads((out / "summary.json").read_text())
    return {n: m["error"] for n, m in s["estimators"].items() if m["status"] != "ok"}


def _named(err: str) -> bool:
    return bool(err and err.strip()) and not err.rstrip(" ").endswith(":")


@pytest.mark.parametrize(("message", "expect"), [
    ("", "RuntimeError (no message; raised at test_failure_messages.py"),
    ("   \n  ", "RuntimeError (no message; raised at test_failure_messages.py"),
    (GTSAM_LIKE, "RuntimeError: Indeterminate linear system detected while working near "
                 "variable"),
])
def test_an_empty_or_newline_first_message_is_never_reported_bare(tmp_path, monkeypatch,
                                                                  message, expect):
    def boom(self, drive):
        raise RuntimeError(message)
    monkeypatch.setattr(type(create("vkf4")), "run", boom)
    out = tmp_path / "out"
    assert main(["run", "--scenario", "hill-drive", "--duration", "30", "--estimators",
                 "loop3,vkf4", "--out", str(out), "--no-progress"]) == 3
    err = _errors(out)
    assert set(err) == {"vkf4"} and err["vkf4"].startswith(expect)
    assert all(_named(e) for e in err.values())


@pytest.mark.slow
def test_phone_folder_with_a_held_10_km_gnss_jump_runs_graph_isam2(tmp_path):
    """The corpus's 10 km / 5 s jump in a Sensor Logger folder (unhandled, graph-isam2 meets an
    indefinite information block, whose GTSAM message starts with a newline): the fixes are
    dropped with an input warning and both graphs run."""
    from tests.fuzz.corpus import SEMANTIC, sim_raw, write_sl_folder

    raw, _ = sim_raw()
    jumped = SEMANTIC["gnss-jump-10km-5s"][0](raw, None)
    path = write_sl_folder(jumped, tmp_path / "jump")
    out = tmp_path / "out"
    assert main(["run", str(path), "--estimators", "graph-isam2,graph-batch", "--out",
                 str(out), "--no-progress"]) == 0
    s = json.loads((out / "summary.json").read_text())
    assert any("50 fix(es) in 1 glitch" in w for w in s["drive"]["warnings"])
    assert all(m["status"] == "ok" for m in s["estimators"].values())
    assert all(_named(m["error"]) for m in s["estimators"].values() if m["error"] is not None)
