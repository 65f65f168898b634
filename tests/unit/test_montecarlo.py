"""Monte Carlo bench: CI closed form, aggregation, failure recording, Dask == local pool.

Two tiny estimators defined here keep the test independent of the real ones:
``gnss-fix`` returns the GNSS fixes themselves with their stated covariance, so its NEES over
position and velocity is χ²(6) per epoch (mean 6) and its altitude RMSE is ≈ σ_GNSS,v = 2 m
(hill-drive) — closed forms to check the whole simulate → estimate → evaluate → aggregate path
against; ``always-fails`` raises.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from vnav_graph.evaluation.montecarlo import (
    aggregate,
    format_bench_md,
    mean_ci95,
    shorten_scenario,
)
from vnav_graph.run.bench import BenchTask, bench, run_task, run_tasks
from vnav_graph.types import Estimate, Trajectory


class GnssFix:
    """The GNSS fixes as the estimate, covariance = the fixes' stated variances."""

    name = "gnss-fix"

    def run(self, drive):
        g = drive.gnss
        cov = np.full((len(g), 18, 18), np.nan)
        cov[:, :6, :6] = 0.0
        for i in range(3):
            cov[:, i, i] = g.pos_sd[:, i] ** 2
            cov[:, 3 + i, 3 + i] = g.vel_sd[:, i] ** 2
        return Estimate(self.name, Trajectory(g.t, g.lla, g.vel_n),
                        frozenset({"alt", "vel_d", "pos_h", "vel_h", "cov"}), cov=cov,
                        t_cov=g.t, runtime_s=1e-3)


class AlwaysFails:
    name = "always-fails"

    def run(self, drive):
        raise RuntimeError("deliberate failure")


@pytest.fixture
def test_estimators(monkeypatch, registry):
    """Register the two test estimators for this test only (the registry is restored)."""
    registry("gnss-fix", GnssFix)
    registry("always-fails", AlwaysFails)


def test_mean_ci95_closed_form():
    ci = mean_ci95([1.0, 2.0, 3.0, 4.0, 5.0, None, float("nan")])  # None/NaN are not data
    # x̄ = 3, s = sqrt(2.5), t_{0.975,4} = 2.776445 (Student t table): half = t·s/√5
    half = 2.776445105 * math.sqrt(2.5) / math.sqrt(5.0)
    assert ci["n"] == 5 and ci["mean"] == pytest.approx(3.0, abs=1e-15)
    assert ci["sd"] == pytest.approx(math.sqrt(2.5), rel=1e-14)
    # 1e-9: the table value of t is given to 10 significant digits
    assert ci["ci95"] == pytest.approx([3.0 - half, 3.0 + half], rel=1e-9)
    assert mean_ci95([7.0]) == {"mean": 7.0, "ci95": None, "sd": None, "n": 1}
    assert mean_ci95([]) == {"mean": None, "ci95": None, "sd": None, "n": 0}


def _row(sc, seed, est, status="ok", rmse=None, scale=None):
    return {"scenario": sc, "seed": seed, "estimator": est, "status": status,
            "alt_rmse_m": rmse, "nees_mean": 12.0 if rmse else None, "nees_dof": 6,
            "runtime_s": 1.0, "baro": {"scale": {"est": scale, "sd": None, "truth": 0.01},
                                       "latency_s": {"est": None, "sd": None, "truth": 0.1},
                                       "bias_m": {"est": None, "sd": None, "truth": None}}}


def test_aggregate_counts_failures_and_derives_errors():
    runs = [_row("a", 0, "x", rmse=1.0, scale=0.012), _row("a", 1, "x", rmse=3.0, scale=0.007),
            _row("a", 2, "x", status="failed"), _row("b", 0, "x", rmse=2.0)]
    agg = aggregate(runs)
    c = agg["a"]["x"]
    assert (c["n_runs"], c["n_ok"], c["n_failed"]) == (3, 2, 1)
    # mean of {1, 3} = 2, s = √2, t_{0.975,1} = 12.706205 → half = 12.706205·√2/√2
    assert c["alt_rmse_m"]["mean"] == 2.0
    assert c["alt_rmse_m"]["ci95"] == pytest.approx([2 - 12.706205, 2 + 12.706205], rel=1e-7)
    assert c["nees_per_dof"]["mean"] == 2.0  # 12 / 6
    # |0.012 − 0.01| and |0.007 − 0.01| → mean 0.0025 (float round-off only)
    assert c["baro_scale_abs_err"]["mean"] == pytest.approx(0.0025, abs=1e-15)
    assert c["baro_latency_abs_err_s"] == {"mean": None, "ci95": None, "sd": None, "n": 0}
    assert agg["b"]["x"]["alt_rmse_m"]["ci95"] is None  # one seed: no interval


def test_shorten_scenario_keeps_outages_inside():
    hd = shorten_scenario("hill-drive", 150.0)  # outage (300, 360) of 600 s
    assert hd.duration_s == 150.0
    assert hd.gnss.outages == ((75.0, 112.5),)  # start 300/4, length min(60, 0.25·150)
    so = shorten_scenario("sortie", 150.0)  # (400, 460), (800, 860) of 1200 s
    assert so.gnss.outages == ((50.0, 87.5), (100.0, 137.5))
    assert shorten_scenario("hill-drive", None).gnss.outages == ((300.0, 360.0),)


def test_gnss_fix_nees_and_failures_recorded(test_estimators):
    doc = bench(["hill-drive"], ["gnss-fix", "always-fails"], [0, 1], duration_s=60.0,
                workers=2)
    assert doc["schema"] == "vnav_graph.run.bench/1"
    assert [(r["seed"], r["estimator"]) for r in doc["runs"]] == [
        (0, "gnss-fix"), (0, "always-fails"), (1, "gnss-fix"), (1, "always-fails")]
    for r in doc["runs"]:
        if r["estimator"] == "gnss-fix":
            assert r["status"] == "ok" and r["nees_dof"] == 6
            n = 600 - 150  # 10 Hz fixes over 60 s minus those in the 15 s outage
            # NEES ~ χ²(6) per epoch: mean 6, sd of the mean sqrt(12/n) ≈ 0.16; 5σ bound
            assert abs(r["nees_mean"] - 6.0) < 5 * math.sqrt(12.0 / n)
            # RMSE of N(0, 2²) over n fixes: sd ≈ 2/sqrt(2n) ≈ 0.067; 5σ bound
            assert abs(r["alt_rmse_m"] - 2.0) < 5 * 2.0 / math.sqrt(2 * n)
            assert r["gnss_outages"] == [[30.0, 45.0]]  # 300·60/600, length min(60, 0.25·60)
        else:
            assert r["status"] == "failed"
            assert r["error"] == "estimate: RuntimeError: deliberate failure"
            assert r["alt_rmse_m"] is None and r["nees_mean"] is None
    agg = doc["aggregate"]["hill-drive"]
    assert agg["always-fails"]["n_failed"] == 2 and agg["gnss-fix"]["n_ok"] == 2
    assert agg["always-fails"]["alt_rmse_m"]["mean"] is None
    md = format_bench_md(doc)
    assert "## Failed runs" in md and "deliberate failure" in md
    json.dumps(doc, allow_nan=False)  # strict JSON (no NaN) or this raises


def test_unknown_scenario_is_a_failed_row_not_a_crash():
    r = run_task(BenchTask("no-such-scenario", 0, "loop3"))
    assert r["status"] == "failed" and r["error"].startswith("simulate: ValueError")


def test_dask_local_cluster_equals_local_pool(test_estimators):
    distributed = pytest.importorskip("distributed")
    tasks = [BenchTask("hill-drive", s, "gnss-fix", 40.0) for s in (3, 4)]
    tasks.append(BenchTask("sortie", 5, "always-fails", 40.0))
    local = run_tasks(tasks, workers=2)
    with distributed.LocalCluster(n_workers=1, processes=False, threads_per_worker=1,
                                  dashboard_address=None) as cluster:
        dask_rows = run_tasks(tasks, dask=cluster.scheduler_address)

    def strip(r):  # wall-clock fields legitimately differ between executors
        return {k: v for k, v in r.items() if k not in ("runtime_s", "realtime_factor")}

    assert [strip(r) for r in dask_rows] == [strip(r) for r in local]  # exactly equal
    assert local[0]["alt_rmse_m"] != local[1]["alt_rmse_m"]  # different seeds, different data
