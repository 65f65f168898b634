"""benchmarks/real_logs_table.py's goals table counts solver warnings apart from the baro
calibration's prior-conflict notes (``estimators.checks.prior_conflict_notes``)."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

_B = Path(__file__).resolve().parents[2] / "benchmarks"
sys.path.insert(0, str(_B))
_spec = importlib.util.spec_from_file_location("real_logs_table", _B / "real_logs_table.py")
rlt = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(rlt)

NOTE = "baro latency -0.48 ± 0.05 s is 5.8 prior σ from its prior 0.10 ± 0.10 s"


def _block(warnings: list[str], notes: list[str]) -> dict:
    return {"status": "ok", "alt_rmse_m": 1.0, "horiz_rmse_m": 5.0, "warnings": warnings,
            "baro_prior_conflict": notes,
            "baro": {"scale": {"est": 0.01, "sd": 0.005}}}


def test_prior_conflicts_are_not_solver_warnings():
    doc = {"estimators": {"graph-batch": _block(["stopped at the cap", NOTE], [NOTE]),
                          "graph-isam2": _block([NOTE], [NOTE]),
                          "ekf-rts": _block([], [])},
           "reference_screening": {"withheld": 10, "excluded": 0}}
    rows = [r for r in rlt.render({"log": doc}).splitlines() if r.startswith("| log | 1.00")]
    assert len(rows) == 1
    cells = [c.strip() for c in rows[0].strip("|").split("|")]
    assert cells[3] == "1 (+2 prior conflict)"
