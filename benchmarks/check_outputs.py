"""CI gate: the benchmark/job outputs exist and carry the docs/design.md keys; no estimator failed.

Usage: python benchmarks/check_outputs.py DIR
Expects DIR/run/summary.json, DIR/bench/bench.json, DIR/reproductions.json and
DIR/graph_perf.json. Exits 1 with one line per problem.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

GRAPH_PERF_KEYS = {"drive_duration_s", "keyframes", "batch_s", "builtin_floor_s",
                   "batch_over_floor", "isam2_s", "isam2_realtime_factor",
                   "isam2_update_p99_ms", "ekf_s", "ekf_realtime_factor", "peak_rss_mb",
                   "general_over_floor", "isam2_lag_s", "isam2_peak_rss_mb", "isam2_final",
                   "isam2_online_s", "isam2_marginals_s"}
# newer bench_graph.py
GRAPH_PERF_ADDITIVE = {"peak_rss_mb_by_stage", "isam2_relinearized", "isam2_stage_growth_mb"}
REPRO_KEYS = {"seed003_steady_sd_m", "seed003_gps_only_sd_m", "seed003_settling_s",
              "seed001_rmse_m", "seed001_calibration", "seed004_outage_alt_rmse_m"}
METRIC_KEYS = {"status", "error", "alt_rmse_m", "alt_max_abs_m", "vel_down_rmse_mps",
               "nees_mean", "runtime_s", "realtime_factor", "baro", "online", "lag"}
# the online block of every estimator with a causal estimate (null for the pure smoothers),
# and graph-isam2's fixed-lag block (the same keys and lag_s)
ONLINE_KEYS = {"alt_rmse_m", "horiz_rmse_m", "heading_rmse_deg", "heading_known_rmse_deg",
               "heading_known_after_s", "vel_down_rmse_mps", "nees_mean", "nees_dof"}
CAUSAL = {"observer1d", "loop2", "loop3", "loop3-adaptive", "vkf4", "vekf7", "ekf",
          "graph-isam2"}
PURE_SMOOTHERS = {"ekf-rts", "graph-batch"}


def causal_problems(where: str, name: str, m: dict) -> list[str]:
    """The online / lag blocks of one ok estimator block (summary, bench row)."""
    out = []
    on, lag = m.get("online"), m.get("lag")
    if name in CAUSAL and (not isinstance(on, dict) or not ONLINE_KEYS <= set(on)):
        out.append(f"{where}: {name} has no online block with {sorted(ONLINE_KEYS)}")
    if name in PURE_SMOOTHERS and on is not None:
        out.append(f"{where}: {name} is a pure smoother but has an online block")
    if lag is not None and not (ONLINE_KEYS | {"lag_s"}) <= set(lag):
        out.append(f"{where}: {name}'s lag block lacks {sorted(ONLINE_KEYS | {'lag_s'})}")
    return out


def check(root: Path) -> list[str]:
    problems: list[str] = []

    def load(rel: str) -> dict | None:
        p = root / rel
        if not p.exists():
            problems.append(f"missing {rel}")
            return None
        return json.loads(p.read_text())

    s = load("run/summary.json")
    if s is not None:
        if s.get("schema") != "vnav_graph.summary/1":
            problems.append("summary.json: wrong schema")
        for name, m in s.get("estimators", {}).items():
            if not METRIC_KEYS <= set(m):
                problems.append(f"summary.json: {name} lacks {sorted(METRIC_KEYS - set(m))}")
            if m.get("status") != "ok":
                problems.append(f"summary.json: {name} failed: {m.get('error')}")
            else:
                problems += causal_problems("summary.json", name, m)
        if not s.get("estimators"):
            problems.append("summary.json: no estimator ran")
    b = load("bench/bench.json")
    if b is not None:
        if b.get("schema") != "vnav_graph.run.bench/1" or not b.get("runs"):
            problems.append("bench.json: wrong schema or no runs")
        for r in b.get("runs", []):
            where = f"bench.json: {r.get('scenario')}/{r.get('seed')}"
            if r.get("status") != "ok":
                problems.append(f"{where}/{r.get('estimator')} failed: {r.get('error')}")
            else:
                problems += causal_problems(where, str(r.get("estimator")), r)
        names = {r.get("estimator") for r in b.get("runs", [])}
        if {"ekf-rts", "graph-batch"} <= names and not (root / "bench" / "forest.png").is_file():
            problems.append("bench: forest.png (the paired gains of the graph) missing")
    r = load("reproductions.json")
    if r is not None and not REPRO_KEYS <= set(r):
        problems.append(f"reproductions.json lacks {sorted(REPRO_KEYS - set(r))}")
    g = load("graph_perf.json")
    if g is not None and set(g) - GRAPH_PERF_ADDITIVE != GRAPH_PERF_KEYS:
        problems.append("graph_perf.json keys differ: "
                        f"{sorted((set(g) - GRAPH_PERF_ADDITIVE) ^ GRAPH_PERF_KEYS)}")
    return problems


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit("usage: check_outputs.py DIR")
    found = check(Path(sys.argv[1]))
    for p in found:
        print(f"check_outputs: {p}", file=sys.stderr)
    if found:
        sys.exit(1)
    print("check_outputs: all outputs present, no estimator failed")
