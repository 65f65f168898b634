"""A real log's row takes the holdout run's self-check: a holdout answer more than 1 km from
the withheld fixes marks the estimator "diverged" (kept, with its errors, not ranked), and
the holdout run's flags join the row's warnings (``pipeline.apply_holdout``); the corpus
oracle ``tests.fuzz.oracle.wrong_but_ok`` sees an "ok" row over 1 km."""

from __future__ import annotations

from tests.fuzz.oracle import wrong_but_ok
from vnav_graph.evaluation.metrics import METRIC_KEYS
from vnav_graph.run.pipeline import apply_holdout


def _row(**kw):
    return {"status": "ok", "error": None, "warnings": [], **dict.fromkeys(METRIC_KEYS),
            "runtime_s": 1.0, **kw}


def _holdout(**kw):
    h = {"status": "ok", "error": None, "alt_rmse_m": 3.0, "alt_max_abs_m": 9.0,
         "horiz_rmse_m": 4.0, "vel_down_rmse_mps": None,
         "per_window": [{"t0": 0.0, "t1": 60.0, "n": 5, "alt_rmse_m": 3.0,
                         "horiz_rmse_m": 4.0, "vel_down_rmse_mps": None}],
         "self_check": {"flags": []}}
    h.update(kw)
    return h


def _apply(h_a, h_b):
    summary = {"estimators": {"a": _row(), "b": _row()}, "comparison": None, "rankings": None}
    doc = {"estimators": {"a": h_a, "b": h_b}, "windows": [{"t0": 0.0, "t1": 60.0}],
           "outage_s": 60.0, "scoring": "withheld fixes"}
    return apply_holdout(summary, doc)


def test_a_diverged_holdout_run_marks_the_row_and_keeps_its_errors():
    far = "height error up to 1126 m against the withheld GNSS fixes (limit 1000 m)"
    out = _apply(_holdout(self_check={"flags": ["height jump of 206 m to the first fix"]}),
                 _holdout(status="diverged", error=far, alt_max_abs_m=1126.0))
    a, b = out["estimators"]["a"], out["estimators"]["b"]
    assert a["status"] == "ok" and a["warnings"] == ["holdout run: height jump of 206 m to "
                                                     "the first fix"]
    assert b["status"] == "diverged" and b["error"] == f"holdout run: {far}"
    assert b["alt_max_abs_m"] == 1126.0 and b["holdout_error"] == far
    ranked = [r["name"] for r in out["rankings"]["offline"]["alt_rmse_m"]]
    assert ranked == ["a"]  # the diverged row is not ranked
    assert not wrong_but_ok(out)


def test_the_oracle_sees_an_ok_row_over_a_kilometre():
    """What the summary said before a holdout answer over 1 km was marked: "ok"."""
    out = _apply(_holdout(), _holdout(alt_max_abs_m=1126.0,
                                      self_check={"flags": [], "error_max_m": {
                                          "online_horizontal": 1500.0, "basis": "x"}}))
    assert out["estimators"]["b"]["status"] == "ok"
    assert wrong_but_ok(out) == ["b: alt_max_abs_m = 1126 m, status ok",
                                 "b: holdout_self_check.online_horizontal = 1500 m, status ok"]
