"""Run every example's ``main()`` on a short duration (MPLBACKEND=Agg) and check its numbers.

Examples that need an estimator this build does not have yet skip with the reason.
"""

from __future__ import annotations

import importlib.util
import math
import sys
from pathlib import Path

import numpy as np
import pytest

from vnav_graph.estimators import base
from vnav_graph.evaluation.montecarlo import shorten_scenario
from vnav_graph.simulation import simulate

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


@pytest.fixture(autouse=True)
def _agg(monkeypatch):
    monkeypatch.setenv("MPLBACKEND", "Agg")


def load(name: str):
    spec = importlib.util.spec_from_file_location(name, EXAMPLES / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[name] = mod  # so that classes defined there pickle by reference
    spec.loader.exec_module(mod)
    missing = [n for n in getattr(mod, "REQUIRES", ()) if n not in base.available()]
    if missing:
        pytest.skip(f"{name} needs estimator(s) not in this build yet: {', '.join(missing)}")
    return mod


def test_every_example_is_tested():
    tested = {"ex_simulate_drive", "ex_calibrate_baro", "ex_custom_estimator",
              "ex_compare_ekf_graph", "ex_graph_real_log"}
    assert {p.stem for p in EXAMPLES.glob("ex_*.py")} == tested


def test_ex_simulate_drive():
    res = load("ex_simulate_drive").main(duration_s=60.0, seed=2)
    d = res.drive
    assert d.duration_s == pytest.approx(60.0, abs=1e-9)
    # the residual of the baro model is the white noise v: mean 0, sd = noise_sd (0.3 m);
    # 1500 samples → sd of the mean 0.008 m, of the sd 0.0055 m; bounds are 5σ
    sd = d.baro.spec.noise_sd
    n = res.baro_residual_m.size
    assert abs(np.mean(res.baro_residual_m)) < 5 * sd / math.sqrt(n)
    assert abs(np.std(res.baro_residual_m) - sd) < 5 * sd / math.sqrt(2 * n)


def test_ex_custom_estimator(monkeypatch):
    mod = load("ex_custom_estimator")
    monkeypatch.setattr(base, "_REGISTRY", dict(base._REGISTRY))  # undo register() afterwards
    doc = mod.main(duration_s=60.0, seeds=2, workers=1)
    rows = [r for r in doc["runs"] if r["estimator"] == "baro-only"]
    assert [r["seed"] for r in rows] == [0, 1] and all(r["status"] == "ok" for r in rows)
    for r in rows:  # the bench's number equals a direct evaluation of the closed form
        drive = simulate(shorten_scenario("hill-drive", 60.0), r["seed"])
        g, b, tr = drive.gnss, drive.baro, drive.truth
        first = g.t <= g.t[0] + 30.0
        bias = np.mean(np.interp(g.t[first], b.t, b.altitude) - g.lla[first, 2])
        err = b.altitude - bias - np.interp(b.t, tr.t, tr.alt)
        # float round-off only (same operations in a different order)
        assert r["alt_rmse_m"] == pytest.approx(np.sqrt(np.mean(err**2)), rel=1e-10)
        assert r["baro"]["bias_m"]["est"] == pytest.approx(bias, rel=1e-12)
    variant = [r for r in doc["runs"] if r["estimator"] == "loop3-tau60"]
    if variant:  # the registered variant gives exactly what the class gives when run directly
        from vnav_graph.estimators.vertical.loops import Loop3, Loop3Config
        from vnav_graph.evaluation.metrics import evaluate

        drive = simulate(shorten_scenario("hill-drive", 60.0), 0)
        direct = evaluate(Loop3(Loop3Config(tau=60.0)).run(drive), drive)
        assert variant[0]["alt_rmse_m"] == pytest.approx(direct["alt_rmse_m"], rel=1e-12)
        loop3 = [r for r in doc["runs"] if r["estimator"] == "loop3"]
        assert loop3[0]["alt_rmse_m"] != variant[0]["alt_rmse_m"]  # the time constant matters
    agg = doc["aggregate"]["hill-drive"]["baro-only"]
    assert agg["alt_rmse_m"]["mean"] == pytest.approx(np.mean([r["alt_rmse_m"] for r in rows]))


def test_ex_calibrate_baro():
    res = load("ex_calibrate_baro").main(duration_s=300.0, seed=1)
    cal, t = res["calibration"], res["truth"]
    assert t["scale"] == res["drive"].baro_truth.scale
    # OLS standard errors assume white residuals; the simulated bias b(t) is a Gauss-Markov
    # process (correlated), which makes the true error larger than the stated σ for the
    # scale and bias — allow 6σ there, 4σ for the latency (driven by white noise).
    assert abs(cal.latency_s - t["latency_s"]) < 4 * cal.latency_sd
    assert abs(cal.scale - t["scale"]) < 6 * cal.scale_sd
    assert abs(cal.bias_m - t["bias_m"]) < 6 * cal.bias_sd
    if res["vekf7"] is not None:
        v = res["vekf7"]["latency_s"]
        if v["est"] is not None and v["sd"] is not None:
            assert abs(v["est"] - v["truth"]) < 4 * v["sd"]  # 4σ: filter consistency


def test_ex_compare_ekf_graph():
    res = load("ex_compare_ekf_graph").main(duration_s=60.0, seed=0)
    s = res["summary"]["estimators"]
    assert all(m["status"] == "ok" for m in s.values()), {k: m["error"] for k, m in s.items()}
    for m in s.values():  # real-time factor = drive duration / runtime (closed form)
        assert m["realtime_factor"] == pytest.approx(60.0 / m["runtime_s"], rel=1e-6)
    if "ekf-rts" in s:
        assert res["gains"]["smoothing_m"] == s["ekf"]["alt_rmse_m"] - s["ekf-rts"]["alt_rmse_m"]
        assert res["gains"]["graph_m"] == (s["ekf-rts"]["alt_rmse_m"]
                                           - s["graph-batch"]["alt_rmse_m"])


def test_ex_graph_real_log():
    mod = load("ex_graph_real_log")
    log = mod.find_log()
    if log is None:
        pytest.skip("no Sensor Logger log in tests/data, $VNAV_DATA or ../shared/data")
    res = mod.main(duration_s=60.0, log=log)
    d = res["drive"]
    from vnav_graph.io import load_drive

    full = load_drive(log).duration_s  # the committed fixture may be shorter than 60 s
    assert d.duration_s == pytest.approx(min(60.0, full), abs=0.05)  # cut within 5 samples
    m = res["summary"]["estimators"]["graph-batch"]
    assert m["status"] == "ok", m["error"]
    # phone GNSS heights scatter by several metres; a working smoother stays within 3× the
    # stated GNSS vertical σ of the fixes on average
    sd_v = float(np.sqrt(np.mean(d.gnss.pos_sd[:, 2] ** 2)))
    assert res["alt_vs_gnss_rms_m"]["graph-batch"] < 3 * sd_v
