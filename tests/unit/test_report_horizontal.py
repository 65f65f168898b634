"""Horizontal and heading errors in the report: the series against closed forms (an estimate
3 m north of the truth with its yaw 2° off), and the horizontal, heading and map figures
written and embedded in report.html byte for byte."""

from __future__ import annotations

import base64
import re

import numpy as np
import pytest

from vnav_graph.evaluation.montecarlo import shorten_scenario
from vnav_graph.geo.earth import radii
from vnav_graph.geo.frames import quat_to_rph, rph_to_quat
from vnav_graph.report import write_report
from vnav_graph.report.errors import error_set
from vnav_graph.run.pipeline import RunResult, summarize
from vnav_graph.simulation import simulate
from vnav_graph.types import Estimate, Trajectory

NORTH_M, YAW_DEG, SD_H, SD_YAW_DEG = 3.0, 2.0, 1.0, 0.5
NEW = ("heading_error.png", "horizontal_error.png", "trajectory_map.png")


@pytest.fixture(scope="module")
def drive():
    return simulate(shorten_scenario("hill-drive", 60.0), 7)  # GNSS outage 30-45 s


def moved_truth(drive, name):
    """The truth NORTH_M north with yaw + YAW_DEG, σ_N = σ_E = SD_H, σ_yaw = SD_YAW_DEG."""
    tr = drive.truth
    t = tr.t[::20]
    lla = tr.lla[::20].copy()
    rn, _ = radii(lla[:, 0])
    lla[:, 0] += NORTH_M / (rn + lla[:, 2])
    rph = quat_to_rph(tr.q_nb[::20])
    rph[:, 2] += np.radians(YAW_DEG)
    cov = np.full((t.size, 18, 18), np.nan)
    cov[:, 0, 0] = cov[:, 1, 1] = SD_H**2
    cov[:, 2, 2] = 0.5**2
    cov[:, 8, 8] = np.radians(SD_YAW_DEG) ** 2
    return Estimate(name, Trajectory(t, lla, tr.vel_n[::20], rph_to_quat(rph)),
                    frozenset({"alt", "vel_d", "pos_h", "att", "cov"}), cov=cov, t_cov=t,
                    runtime_s=0.5)


def test_horizontal_and_heading_errors_closed_form(drive):
    results = [RunResult("ekf", moved_truth(drive, "ekf"), None, 0.5)]
    (s,) = error_set(drive, results).series
    # the tangent plane at the origin vs the meridian arc: well under a millimetre here
    np.testing.assert_allclose(s.horiz, NORTH_M, atol=2e-3)
    np.testing.assert_allclose(s.horiz_sd, np.hypot(SD_H, SD_H), rtol=1e-12)
    np.testing.assert_allclose(s.heading, YAW_DEG, atol=1e-6)
    np.testing.assert_allclose(s.heading_sd, SD_YAW_DEG, rtol=1e-9)
    summary = summarize(drive, results)
    m = summary["estimators"]["ekf"]
    assert m["horiz_rmse_m"] == pytest.approx(np.sqrt(np.mean(s.horiz**2)), abs=1e-3)
    assert m["heading_rmse_deg"] == pytest.approx(np.sqrt(np.mean(s.heading**2)), abs=1e-3)


def test_new_figures_written_and_embedded(drive, tmp_path):
    results = [RunResult(n, moved_truth(drive, n), None, 0.5) for n in ("ekf", "graph-batch")]
    summary = summarize(drive, results)
    write_report(tmp_path, summary, results, drive)
    pngs = sorted(p.name for p in (tmp_path / "plots").iterdir())
    assert set(NEW) <= set(pngs)
    page = (tmp_path / "report.html").read_text(encoding="utf-8")
    embedded = {base64.b64decode(b) for b in
                re.findall(r'src="data:image/png;base64,([A-Za-z0-9+/=]+)"', page)}
    for name in NEW:
        png = (tmp_path / "plots" / name).read_bytes()
        assert png in embedded, name
        width = int.from_bytes(png[16:20], "big")  # IHDR width
        assert width >= 1600, (name, width)
    assert "Horizontal position error" in page and "Heading (yaw) error" in page
    assert "Trajectory map" in page and "the truth inside the simulated GNSS outages" in page


def test_no_horizontal_figure_without_pos_h_is_said(drive, tmp_path):
    est = moved_truth(drive, "vkf4")
    est = est.replace(provides=frozenset({"alt", "vel_d", "cov"}))
    results = [RunResult("vkf4", est, None, 0.5)]
    write_report(tmp_path, summarize(drive, results), results, drive)
    pngs = {p.name for p in (tmp_path / "plots").iterdir()}
    assert "horizontal_error.png" not in pngs and "heading_error.png" not in pngs
    page = (tmp_path / "report.html").read_text(encoding="utf-8")
    assert "No horizontal-error plot: no estimator provides a horizontal position." in page
    assert "No heading-error plot" in page


def test_holdout_horizontal_sigma_closed_form(drive):
    """The holdout scores carry σ_h = sqrt(P_NN + P_EE + σ_GNSS,N² + σ_GNSS,E²) at the fixes,
    which the real-log horizontal figure draws (+3σ_h)."""
    from vnav_graph.evaluation.holdout import in_windows, score

    g = drive.gnss
    withheld = in_windows(g.t, [(10.0, 20.0)])
    s = score(moved_truth(drive, "ekf"), drive, withheld)
    inside = (g.t >= drive.truth.t[0]) & (g.t <= drive.truth.t[-1])
    want = np.sqrt(2 * SD_H**2 + g.pos_sd[inside, 0] ** 2 + g.pos_sd[inside, 1] ** 2)
    np.testing.assert_allclose(s.horiz_sd, want, rtol=1e-12)
    assert s.horiz_sd.shape == s.alt_err.shape
    no_h = moved_truth(drive, "vkf4").replace(provides=frozenset({"alt", "vel_d", "cov"}))
    assert score(no_h, drive, withheld).horiz_sd is None
