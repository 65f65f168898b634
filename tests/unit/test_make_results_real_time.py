"""The results page's real-time comparison: both estimators over their common span (from the
later first epoch, ``online_common``), and the win rule's heading on heading_known where the
rows carry no common-epoch heading."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

from vnav_graph.evaluation.montecarlo import aggregate

REPO = Path(__file__).resolve().parents[2]


def make_results():
    spec = importlib.util.spec_from_file_location(
        "make_results", REPO / "benchmarks" / "make_results.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def online(from_s, heading, known, alt=1.0):
    return {"alt_rmse_m": alt, "horiz_rmse_m": 1.0, "heading_rmse_deg": heading,
            "heading_known_rmse_deg": known, "heading_known_after_s": from_s + 4.0,
            "vel_down_rmse_mps": 0.1, "nees_mean": 6.0, "nees_dof": 6, "from_s": from_s}


def row(est, seed, on, common=None):
    return {"scenario": "s", "seed": seed, "estimator": est, "status": "ok",
            "alt_rmse_m": 1.0, "runtime_s": 1.0, "nees_mean": None, "nees_dof": None,
            "baro": {}, "online": on, "online_common": common}


def test_real_time_pair_scored_over_the_common_span_with_the_heading_known_rule(tmp_path):
    mr = make_results()
    runs = []
    for i in range(4):
        # the ekf is online from 20 s; graph-isam2 from 0 s, 16° off over its own span (the
        # standstill where it does not know its heading), 0.5° worse than the ekf from 20 s
        # on, and not resolved where both report σ_yaw ≤ 5° (±0.1° alternating)
        runs.append(row("ekf", i, online(20.0, 2.0 + 0.01 * i, 1.0), {}))
        common = online(20.0, 2.5 + 0.01 * i, 1.0 + (0.1 if i % 2 else -0.1))
        runs.append(row("graph-isam2", i, online(0.0, 16.0, 1.0), {"ekf": common}))
    doc = {"schema": "vnav_graph.run.bench/1", "runs": runs, "aggregate": aggregate(runs),
           "config": {"scenarios": ["s"], "seeds": [0, 1, 2, 3], "duration_s": None,
                      "executor": "local", "wall_s": 1.0}}
    (tmp_path / "bench.json").write_text(json.dumps(doc))
    page = mr.render(tmp_path)
    assert "### Real time: forward ekf vs online graph-isam2" in page
    assert "ekf from 20.0 s, graph-isam2 from 0.0 s; both scored from 20.0 s" in page
    assert "Heading known (its own σ_yaw ≤ 5° from then on" in page
    assert "ekf 24.0 s, graph-isam2 4.0 s" in page  # each one's own online block
    # the common span: 0.5°, not the 14° of the standstill; not resolved on heading_known
    # (these rows carry no common-epoch heading: said so), the span's whole score beside it
    assert ("- heading RMSE: d = 0.00 [-0.18, 0.18] deg, gain 0 [-18, 18] %, n = 4: not "
            "resolved (the 95 % CI of the difference contains 0); heading each where its own "
            "σ_yaw ≤ 5° (the runs carry no common-epoch heading); whole drive d = -0.50 "
            "[-0.50, -0.50] deg") in page
    assert "d = -14" not in page
    # the rows: graph-isam2 takes its common-span block, the ekf (the later start) its own
    rt = mr.real_time_rows(runs, "ekf", "graph-isam2")
    g = [r for r in rt if r["estimator"] == "graph-isam2"]
    assert all(r["online"]["from_s"] == 20.0 for r in g)
    assert [r["heading_known_rmse_deg"] for r in g] == [0.9, 1.1, 0.9, 1.1]


def test_rows_without_online_common_are_said_to_be_scored_over_their_own_epochs(tmp_path):
    mr = make_results()
    runs = []
    for i in range(3):
        for est, start in (("ekf", 20.0), ("graph-isam2", 0.0)):
            r = row(est, i, online(start, 2.0 + i, 1.0))
            del r["online_common"]  # rows without the key
            runs.append(r)
    text = mr.real_time_span(runs, "s", "ekf", "graph-isam2")
    assert text.startswith("each over its own epochs (mean first epoch: ekf from 20.0 s, "
                           "graph-isam2 from 0.0 s; these bench rows have no `online_common`)")
    assert "both scored from" not in text
