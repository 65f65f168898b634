"""graph-isam2 on real logs that used to make iSAM2 fail: the Erle crash log with a 24 s IMU
logging gap (gap detection, gap factors) and the 60 s GNSS holdout windows (robust retry),
compared with graph-batch on the same withheld fixes; the error message of a failed update."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from vnav_graph.estimators.graph.isam2 import setup as gi
from vnav_graph.estimators.graph.model import problem as gp
from vnav_graph.run.runner import run_holdout

LOITER = "erle_pxf_loiter_rtl/Loiter_RTL.bin"


def _load(data_dir: Path, rel: str):  # noqa: ANN202
    from vnav_graph.io import load_drive

    p = data_dir / rel
    if not p.exists():
        pytest.skip(f"{rel} not present (real logs are not shipped with the repository)")
    return load_drive(p)


def test_loiter_gap_detected(data_dir: Path) -> None:
    d = _load(data_dir, LOITER)
    P = gp.setup(d, gp.GraphConfig())
    gap = gp.imu_gaps(d.imu.t, P.kf_idx)
    # the log has exactly one IMU logging gap (after the crash), 24.09 s long
    k = np.flatnonzero(gap)
    assert k.size == 1
    j0, j1 = P.kf_idx[k[0]], P.kf_idx[k[0] + 1]
    assert np.max(np.diff(d.imu.t[j0:j1 + 1])) == pytest.approx(24.094, abs=1e-3)
    msg = str(gi.update_error(P, int(k[0]), RuntimeError(""), True))
    # the message names keyframe, time and cause instead of GTSAM's empty text
    assert f"keyframe {k[0] + 1}" in msg
    assert f"t = {P.t_kf[k[0] + 1]:.2f} s" in msg
    assert "IMU logging gap of 24.1 s" in msg
    assert "RuntimeError (no message" in msg


@pytest.mark.slow
def test_loiter_holdout_isam2_matches_batch(data_dir: Path) -> None:
    d = _load(data_dir, LOITER)
    r = run_holdout(d, ["graph-isam2", "graph-batch"])
    e = r.doc["estimators"]
    # graph-isam2's online (real-time) answer dead-reckons more than 1 km from the fixes in
    # a 60 s window of this hovering quad, which marks the run "diverged"
    # (selfcheck.LOST_M); the final answers are what is compared here
    assert e["graph-isam2"]["status"] == "ok" or e["graph-isam2"]["error"].startswith(
        ("online answer:", "online_")), e["graph-isam2"]["error"]
    assert e["graph-batch"]["status"] == "ok"
    # the final smoothing pass of graph-isam2 is graph-batch's solver started elsewhere; on
    # this log both reach ~1.2–1.4 m withheld-fix height RMSE — 0.5 m allows for the
    # different starting point (iteration cap 12) but not for a diverged front end (km)
    assert abs(e["graph-isam2"]["alt_rmse_m"] - e["graph-batch"]["alt_rmse_m"]) < 0.5
    # (runtime is measured by benchmarks/bench_real_logs.py, not asserted here)


CAR = "car_phone_1hz_2025-07-18/2025-07-18_23-13-43.csv"


@pytest.mark.slow
def test_car_1hz_holdout_isam2(data_dir: Path) -> None:
    d = _load(data_dir, CAR)
    r = run_holdout(d, ["graph-isam2"])
    e = r.doc["estimators"]["graph-isam2"]
    assert e["status"] == "ok", e["error"]
    # 93-min log, 1 Hz averaged IMU: low-rate settings (5 s keyframes) → ~1100 updates,
    # measured 7.4 s, 213 s with the high-rate settings (runtime: benchmarks/bench_real_logs.py)
    # withheld-fix height RMSE measured 1.35 m (graph-batch 1.5 m); a diverged online pass
    # that the final batch pass could not repair ends metres above it
    assert e["alt_rmse_m"] < 3.0


@pytest.mark.slow
def test_ski_holdout_isam2_matches_batch(data_dir: Path) -> None:
    d = _load(data_dir, "ski_iphone_100hz")
    r = run_holdout(d, ["graph-isam2", "graph-batch"])
    e = r.doc["estimators"]
    # its online answer dead-reckons more than 1 km from the fixes in a 60 s window (phone
    # IMU): "diverged" by selfcheck.LOST_M; the final answer is what is compared here
    assert e["graph-isam2"]["status"] == "ok" or e["graph-isam2"]["error"].startswith(
        ("online answer:", "online_")), e["graph-isam2"]["error"]
    # phone IMU, GNSS without velocity: until the online pass relinearised its custom terms
    # (graph.relin) it diverged when GNSS returned after a 60 s window and needed the dogleg
    # retry; now it does not, and its final pass (graph-batch's solver started from the
    # iSAM2 estimate) ends 0.4 % from graph-batch's own solution (1.977 vs 1.969 m)
    assert not [w for w in e["graph-isam2"]["warnings"] if "dogleg" in w]
    assert e["graph-isam2"]["alt_rmse_m"] == pytest.approx(e["graph-batch"]["alt_rmse_m"],
                                                          rel=0.02)


@pytest.mark.slow
def test_218_holdout_isam2_keeps_its_own_estimate(data_dir: Path) -> None:
    """218.BIN with the 60 s holdout windows: after the touchdown τd is weakly determined
    and h(t_s − τd) strongly curved; rebuilding the baro terms at every new estimate of
    (s, τd) made τd alternate between −0.24 and +0.37 s at every update (with the
    accelerometer scale factors), the final rounds never settled and graph-isam2 fell back
    to its batch pass. With the reversed steps halved (``relin.TermBook``) its own smoothed
    estimate is the optimum again, and its latency is the batch's (0.01 ± 0.05 s)."""
    from vnav_graph.estimators.graph import GraphBatch, GraphISAM2
    from vnav_graph.evaluation.holdout import choose_windows, withhold

    d = _load(data_dir, "erle_pxf_218/218.BIN")
    held = withhold(d, choose_windows(d.gnss.t))  # the drive run_holdout gives them
    e = GraphISAM2().run(held)
    b = GraphBatch().run(held)
    assert e.info["trajectory_source"] == "isam2", e.info["warnings"]
    assert e.info["accel_scale_estimated"]
    assert len(e.info["isam2_final_rounds"]) < 8
    # iSAM2 rebuilds its baro terms only when τd moves by more than lin_points.CALIB_THRESHOLD
    # (0.05 s, ≈ 1σ here), so its settled τd may differ from the batch's by a fraction of
    # that: measured 0.005 s (0.09σ) with the biases as random walks, 0.012 s (0.23σ) with
    # their Gauss-Markov step; the cycling this test guards against was ±0.3 s
    from vnav_graph.estimators.graph.isam2.lin_points import CALIB_THRESHOLD

    assert abs(e.baro.latency_s.est - b.baro.latency_s.est) < 0.5 * CALIB_THRESHOLD[1]
    assert abs(e.baro.latency_s.est - b.baro.latency_s.est) < 0.5 * b.baro.latency_s.sd
