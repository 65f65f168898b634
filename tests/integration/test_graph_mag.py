"""graph-batch / graph-isam2 with the built-in magnetometer (``graph.model.builtin_sensors``)."""

from __future__ import annotations

import numpy as np
import pytest

from vnav_graph.estimators.ekf.filter import EKFRTS
from vnav_graph.estimators.graph import GraphBatch, GraphConfig, GraphISAM2
from vnav_graph.evaluation.metrics import errors_vs_truth
from vnav_graph.evaluation.montecarlo import shorten_scenario
from vnav_graph.simulation import simulate


@pytest.fixture(scope="module")
def drive():
    return simulate(shorten_scenario("hill-drive-mag", 300.0), 2)


def _yaw_rms_deg(est, drive, t_from: float = 30.0) -> float:
    """RMS of the package's own heading error (``evaluation.metrics``) after ``t_from``."""
    e = errors_vs_truth(est, drive)
    return float(np.sqrt(np.mean(e.heading[e.t > t_from] ** 2)))


def test_graph_batch_uses_the_magnetometer(drive) -> None:
    with_mag = GraphBatch().run(drive)
    without = GraphBatch(GraphConfig(use_mag=False)).run(drive)
    h = with_mag.info["extra_variables"]["h0"]
    truth = np.array(drive.meta["mag_truth"]["hard_iron_ut"])
    est, sd = np.array(h["est"]), np.array(h["sd"])
    assert np.all(np.abs(est - truth) <= 3 * sd), (est, sd, truth)
    assert np.all(sd[:2] < 0.5)  # horizontal hard iron observable through the turns
    assert with_mag.info["solver"] == "banded" and not with_mag.info["warnings"]
    assert "h0" not in without.info["extra_variables"]
    # measured (seed 2): smoothed yaw RMS after 30 s 0.201° → 0.140°
    assert _yaw_rms_deg(with_mag, drive) < 0.8 * _yaw_rms_deg(without, drive)
    # the same model as ekf-rts: both smoothers agree on the hard iron within their σ
    e = EKFRTS().run(drive).info["extra_variables"]["h0"]
    assert np.all(np.abs(np.array(e["est"][:2]) - est[:2]) <= 2 * sd[:2])


def test_graph_isam2_final_pass_has_the_magnetometer(drive) -> None:
    b = GraphBatch().run(drive).info["extra_variables"]["h0"]
    i = GraphISAM2().run(drive).info["extra_variables"]["h0"]
    np.testing.assert_allclose(i["est"], b["est"], atol=0.05)


def test_graph_isam2_heading_factors_through_its_window(drive) -> None:
    """The heading factors are linearised in Python and rebuilt by graph-isam2's book
    (``isam2.py_factors``); with a 120 s window most of them leave iSAM2 in its marginal.
    Its hard iron still equals graph-batch's, and the online one (after the last update,
    before the final rounds) is the final one within a tenth of its σ."""
    b = GraphBatch().run(drive).info["extra_variables"]["h0"]
    info = GraphISAM2(GraphConfig(isam2_window_s=120.0)).run(drive).info
    i, on = info["extra_variables"]["h0"], info["extra_variables_online"]["h0"]
    assert info["isam2_marginalised_keyframes"] > 100
    assert info["isam2_relinearized_custom"] > 0 and not info["warnings"]
    # measured (seed 2): within 0.021 µT of graph-batch's (σ 0.11–1.6 µT), online − final
    # ≤ 4e-4 µT; 3 080 heading-factor rebuilds, 180 keyframes marginalised
    np.testing.assert_allclose(i["est"], b["est"], atol=0.05)
    assert np.all(np.abs(np.array(on["est"]) - i["est"]) <= 0.1 * np.array(i["sd"]))


def test_an_unsteady_magnetometer_is_left_out_by_both_families() -> None:
    """A field whose strength swings (electrical interference of ±25 µT) is beyond the
    hard-iron model: ekf and graph-batch leave it out and say why."""
    from vnav_graph.estimators.ekf.filter import EKF
    from vnav_graph.types.streams import MagStream

    d = simulate(shorten_scenario("hill-drive-mag", 120.0), 1)
    m = d.mag
    swing = 25.0 * np.sin(2 * np.pi * m.t / 20.0)[:, None] * np.array([1.0, 0.0, 0.0])
    d = d.replace(mag=MagStream(m.t, m.field_b + swing, m.sd_ut))
    for est in (EKF().run(d), GraphBatch().run(d)):
        assert "magnetometer not used" in est.info["mag_note"]
        assert "h0" not in (est.info.get("extra_variables") or {})


def test_both_families_report_the_same_field_and_a_missing_date() -> None:
    """ekf and graph-batch report the same declination and field model, and both say when
    the drive has no date (the graph used to say nothing)."""
    from vnav_graph.estimators.ekf.filter import EKF
    from vnav_graph.sensors.magnetometer import DEFAULT_YEAR

    d = simulate(shorten_scenario("hill-drive-mag", 60.0), 1)
    meta = {k: v for k, v in d.meta.items() if k != "decimal_year"}
    for drive, dated in ((d, True), (d.replace(meta=meta), False)):
        infos = [EKF().run(drive).info, GraphBatch().run(drive).info]
        keys = ("mag_declination_deg", "mag_field_model", "mag_note")
        assert [{k: i.get(k) for k in keys} for i in infos].count(
            {k: infos[0].get(k) for k in keys}) == 2
        assert np.isfinite(infos[0]["mag_declination_deg"])
        assert ("mag_note" in infos[0]) is not dated
        if not dated:
            assert f"{DEFAULT_YEAR:.1f}" in infos[1]["mag_note"]


def test_a_compass_that_contradicts_the_heading_is_dropped_by_both_families(drive) -> None:
    """A compass turned 60° about the vertical (mounting error): no constant hard iron
    explains it while the car turns. With it the hard iron of both families comes out far
    outside its 3 µT prior (measured: graph-batch 13.5σ, ekf-rts 7.3σ); both drop it, say
    why, and return exactly their run without the magnetometer."""
    from vnav_graph.types.streams import MagStream

    a = np.radians(60.0)
    rot = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])
    m = drive.mag
    bad = drive.replace(mag=MagStream(m.t, m.field_b @ rot.T, m.sd_ut))
    for cls, config in ((GraphBatch, GraphConfig), (EKFRTS, None)):
        est = cls().run(bad)
        assert "contradicts the heading" in est.info["mag_note"]
        assert "h0" not in (est.info.get("extra_variables") or {})
        if config is None:
            from vnav_graph.estimators.ekf.filter import EkfConfig as config
        ref = cls(config(use_mag=False)).run(bad)
        np.testing.assert_array_equal(est.trajectory.alt, ref.trajectory.alt)
    # the consistent compass of the same drive is kept
    assert "mag_note" not in GraphBatch().run(drive).info


def test_graph_isam2_drops_a_contradicting_compass_too(drive) -> None:
    """graph-isam2 applies the same post-solve hard-iron check (``hard_iron_note``)."""
    from vnav_graph.types.streams import MagStream

    a = np.radians(60.0)
    rot = np.array([[np.cos(a), -np.sin(a), 0.0], [np.sin(a), np.cos(a), 0.0], [0.0, 0.0, 1.0]])
    m = drive.mag
    bad = drive.replace(mag=MagStream(m.t, m.field_b @ rot.T, m.sd_ut))
    est = GraphISAM2().run(bad)
    assert "contradicts the heading" in est.info["mag_note"]
    assert "h0" not in est.info["extra_variables"]


def test_extension_counts_reach_the_summary():
    """What each extension added (here the smoothers' own magnetometer: one heading factor
    per magnetometer interval and the hard-iron variable H(0)) is in ``info["extensions"]``
    and the summary block; null for an estimator without extensions."""
    from vnav_graph.run.pipeline import summarize
    from vnav_graph.run.runner import run_estimators
    from vnav_graph.simulation import simulate

    d = simulate("hill-drive-mag", 0, duration_s=60.0)
    s = summarize(d, run_estimators(d, ["graph-batch", "graph-isam2", "ekf"]))["estimators"]
    for name in ("graph-batch", "graph-isam2"):
        mag = s[name]["extensions"]["magnetometer"]
        assert mag["variables"] == 1 and 40 <= mag["factors"] <= 70  # measured 61 in 60 s
    assert s["ekf"]["extensions"] is None
