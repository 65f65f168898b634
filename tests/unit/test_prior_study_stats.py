"""The z statistics and the real-log disguise of benchmarks/prior_study.py."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from vnav_graph.config import REAL_LOG_BARO
from vnav_graph.sensors.model import baro_prior, sensor_model
from vnav_graph.simulation import simulate

_P = Path(__file__).resolve().parents[2] / "benchmarks" / "prior_study.py"
_spec = importlib.util.spec_from_file_location("prior_study", _P)
ps = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(ps)


def _p(est, sd, truth):
    return {"est": est, "sd": sd, "truth": truth}


def test_z_scores_hand_made_block():
    z = ps.z_scores({"scale": _p(0.012, 0.004, 0.004),       # (0.012 − 0.004) / 0.004
                     "latency_s": _p(0.05, 0.1, 0.2),          # (0.05 − 0.2) / 0.1
                     "bias_m": _p(-1.0, 0.5, 2.0)})            # (−1 − 2) / 0.5
    assert z["scale"] == pytest.approx(2.0)
    assert z["latency_s"] == pytest.approx(-1.5)
    assert z["bias_m"] == pytest.approx(-6.0)
    # no sd, a zero sd, no truth (a real log), no estimate: no z
    z = ps.z_scores({"scale": _p(0.01, None, 0.0), "latency_s": _p(0.1, 0.0, 0.1),
                     "bias_m": _p(1.0, 1.0, None)})
    assert z == {"scale": None, "latency_s": None, "bias_m": None}
    assert ps.z_scores({"scale": None})["scale"] is None


def test_rms_stats_and_summary():
    s = ps.rms_stats([3.0, -4.0, None])
    assert s["n"] == 2
    assert s["rms_z"] == pytest.approx(np.sqrt(12.5))
    assert s["mean_z"] == pytest.approx(-0.5)
    lo, hi = s["rms_z_ci95"]
    assert lo < s["rms_z"] < hi
    assert ps.rms_stats([])["rms_z"] is None

    def row(seed, err, sd):
        b = {p: _p(err, sd, 0.0) for p in ps.PARAMS}
        return {"scenario": "default", "seed": seed, "estimator": "ekf-rts", "status": "ok",
                "baro": b, "z": ps.z_scores(b)}

    rows = [row(0, 1.0, 0.5), row(1, -3.0, 1.0),
            {"scenario": "default", "seed": 2, "estimator": "ekf-rts", "status": "failed"}]
    got = ps.summarize(rows)["default"]["ekf-rts"]
    assert got["failed"] == 1
    assert got["bias_m"]["n"] == 2
    assert got["bias_m"]["rms_z"] == pytest.approx(np.sqrt((2.0**2 + 3.0**2) / 2))
    assert got["bias_m"]["mean_z"] == pytest.approx(-0.5)
    assert got["bias_m"]["rms_err"] == pytest.approx(np.sqrt(5.0))
    assert got["bias_m"]["median_sd"] == pytest.approx(0.75)
    assert "✗" in ps.markdown(ps.summarize(rows))  # 2.55 is outside 0.8–1.25


def test_as_real_log_gets_the_real_log_prior():
    d = simulate("default", 0, duration_s=30.0)
    # a simulated drive states its own baro spec, whose prior differs from the real-log one
    assert sensor_model(d).baro != baro_prior(REAL_LOG_BARO)
    r = ps.as_real_log(d)
    assert r.imu.spec is None and r.baro.spec is None
    assert r.truth is d.truth and r.baro_truth == d.baro_truth
    m = sensor_model(r)
    assert m.baro == baro_prior(REAL_LOG_BARO)
    assert m.imu_inferred
