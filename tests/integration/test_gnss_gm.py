"""The optional Gauss-Markov GNSS height error state, ``ekf-rts`` and
``graph-batch`` (the same model: ``sensors.gnss_model.GnssGM``; the graph's G(k) chain).

Drive: hill-drive, 300 s, GNSS height error = white 0.5 m + Gauss-Markov σ 3 m, τ 120 s (the
receiver reports σ_v = √(0.5² + 3²), as ``simulation.gnss`` does). Treated as white, 10 Hz of
such heights are averaged as if independent: the filter's altitude σ is far too small. With the
state (σ and τ of the simulation: the test is of the model, not of prior tuning) the altitude
error is consistent with its σ.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from vnav_graph.estimators.ekf import model as km
from vnav_graph.estimators.ekf.filter import EKFRTS, EkfConfig
from vnav_graph.estimators.graph import GraphBatch, GraphConfig
from vnav_graph.sensors.gnss_model import GM_WHITE_MIN_FRACTION, GnssGM, white_rest
from vnav_graph.simulation.scenario import load_scenario, simulate

GM_SD, GM_TAU = 3.0, 120.0
N_SEEDS = 6


def test_split_closed_form():
    sd = np.array([np.hypot(0.5, 3.0), 3.0, 10.0, np.nan])
    out = white_rest(sd, 3.0)
    np.testing.assert_allclose(out[:3], [0.5, GM_WHITE_MIN_FRACTION * 3.0, np.sqrt(91.0)])
    assert np.isnan(out[3])
    # per axis: the height-only state splits the down column only, the 3-axis one all three
    pos_sd = np.tile([np.hypot(0.5, 2.0), np.hypot(0.5, 2.0), np.hypot(1.0, 3.0)], (2, 1))
    np.testing.assert_allclose(GnssGM(0.0, 3.0, 120.0).split(pos_sd)[:, 2], 1.0)
    np.testing.assert_array_equal(GnssGM(0.0, 3.0, 120.0).split(pos_sd)[:, :2], pos_sd[:, :2])
    np.testing.assert_allclose(GnssGM(2.0, 3.0, 120.0).split(pos_sd), [[0.5, 0.5, 1.0]] * 2)
    assert GnssGM(2.0, 3.0, 60.0).axes == (0, 1, 2) and GnssGM(2.0, 0.0, 60.0).axes == (0, 1)


def test_config_rejects_bad_settings():
    with pytest.raises(ValueError, match="gnss_gm_sd_v"):
        EkfConfig(gnss_gm_sd_v=-1.0)
    with pytest.raises(ValueError, match="gnss_gm_sd_v"):
        EkfConfig(gnss_gm_sd_v=2.0, gnss_gm_tau_s=0.0)
    assert EkfConfig().gnss_gm is None
    with pytest.raises(ValueError, match="GraphConfig.gnss_gm_sd_v"):
        GraphConfig(gnss_gm_sd_v=float("nan"))
    with pytest.raises(ValueError, match="GraphConfig.gnss_gm_sd_v"):
        GraphConfig(gnss_gm_sd_v=2.0, gnss_gm_tau_s=-1.0)
    with pytest.raises(ValueError, match="gnss_gm_sd_h"):
        EkfConfig(gnss_gm_sd_h=-2.0)
    assert GraphConfig().gnss_gm is None


def test_error_dynamics_entry():
    ing = np.zeros(km.NING)
    ing[0:9] = np.eye(3).ravel()
    f = km.build_f(ing, np.inf, np.inf, np.inf, 120.0)
    for i in range(km.IGE, km.IGE + 3):
        assert f[i, i] == pytest.approx(-1.0 / 120.0)
        assert np.count_nonzero(f[i]) == 1 and np.count_nonzero(f[:, i]) == 1
        assert np.all(km.build_f(ing, np.inf, np.inf, np.inf, np.inf)[i] == 0.0)


@pytest.fixture(scope="module")
def runs():
    cfg = load_scenario("hill-drive")
    cfg = replace(cfg, duration_s=300.0,
                  gnss=replace(cfg.gnss, gm_sd_v=GM_SD, gm_tau_s=GM_TAU, pos_sd_v=0.5))
    out = []
    for s in range(N_SEEDS):
        d = simulate(cfg, s)
        out.append((d, EKFRTS().run(d),
                    EKFRTS(EkfConfig(gnss_gm_sd_v=GM_SD, gnss_gm_tau_s=GM_TAU)).run(d)))
    return out


@pytest.fixture(scope="module")
def graph_runs(runs):
    gm = GraphConfig(gnss_gm_sd_v=GM_SD, gnss_gm_tau_s=GM_TAU)
    return [(d, GraphBatch().run(d), GraphBatch(gm).run(d)) for d, _, _ in runs]


def _alt_z(est, d):
    e = est.trajectory.alt - d.truth.at(est.trajectory.t).alt
    ea = np.interp(est.t_cov, est.trajectory.t, e)
    return e, ea / np.sqrt(est.cov[:, 2, 2])


@pytest.mark.parametrize("family", ["ekf-rts", "graph-batch"])
def test_gm_state_makes_the_altitude_sigma_honest(family, request):
    runs = request.getfixturevalue("runs" if family == "ekf-rts" else "graph_runs")
    z_off = np.concatenate([_alt_z(off, d)[1] for d, off, _ in runs])
    z_gm = np.concatenate([_alt_z(gm, d)[1] for d, _, gm in runs])
    rms_off, rms_gm = np.sqrt(np.mean(z_off**2)), np.sqrt(np.mean(z_gm**2))
    # white-noise model: σ too small by an order of magnitude (measured rms z ≈ 15)
    assert rms_off > 4.0, rms_off
    # with the state: the error is its σ (measured over these 6 seeds: ekf-rts 0.94,
    # graph-batch 0.82; without it 18.4 for both); six 300 s runs hold only ~15 independent
    # GM samples (τ 120 s), hence the band
    assert 0.5 < rms_gm < 1.5, rms_gm
    e_off = np.sqrt(np.mean(np.concatenate([_alt_z(off, d)[0] for d, off, _ in runs]) ** 2))
    e_gm = np.sqrt(np.mean(np.concatenate([_alt_z(gm, d)[0] for d, _, gm in runs]) ** 2))
    assert e_gm < e_off, (e_gm, e_off)


@pytest.mark.parametrize("family", ["ekf-rts", "graph-batch"])
def test_gm_state_reported_and_off_by_default(family, request):
    runs = request.getfixturevalue("runs" if family == "ekf-rts" else "graph_runs")
    d, off, gm = runs[0]
    assert "gnss_height_gm" not in off.info
    assert gm.info["gnss_height_gm"] == {"sd_m": GM_SD, "tau_s": GM_TAU}


def test_both_families_agree_within_their_sigma(runs, graph_runs):
    """Same model, same data: the two smoothers' mean altitude errors differ by far less than
    their σ (not equal: the EKF's prior correlates the first fix's height with g(0), the
    graph's accelerometer bias is a random walk, the EKF's a Gauss-Markov process)."""
    diff, sd = [], []
    for (d, _, ekf), (_, _, gb) in zip(runs, graph_runs, strict=True):
        diff.append(np.mean(_alt_z(gb, d)[0]) - np.mean(_alt_z(ekf, d)[0]))
        sd.append(np.sqrt(np.mean(gb.cov[:, 2, 2])))
    ratio = np.sqrt(np.mean(np.square(diff))) / np.mean(sd)
    # measured 0.50 (differences −0.77 … +1.48 m against σ 1.64 m); 12 seeds of the same drive
    # without the fixture's cut: ekf-rts / graph-batch rms z 0.79 / 0.77, RMSE 1.32 / 1.28 m
    assert ratio < 0.7, (diff, sd)


def test_graph_gm_general_path_equals_banded(runs):
    """The general sparse path (GTSAM elimination, G(k) pieces in the pair cover) solves the
    same system as the banded fast path with the G(k) columns in the keyframe block."""
    d = runs[0][0]
    cfg = GraphConfig(gnss_gm_sd_v=GM_SD, gnss_gm_tau_s=GM_TAU)
    a = GraphBatch(cfg).run(d)
    b = GraphBatch(replace(cfg, solver="general")).run(d)
    assert a.info["solver"] == "banded" and b.info["solver"] == "general"
    np.testing.assert_allclose(b.trajectory.alt, a.trajectory.alt, rtol=0, atol=1e-6)
    np.testing.assert_allclose(b.cov[:, 2, 2], a.cov[:, 2, 2], rtol=1e-6)
    assert b.baro.scale.est == pytest.approx(a.baro.scale.est, abs=1e-8)


def test_gm_link_is_the_exact_discrete_process():
    import gtsam
    from gtsam.symbol_shorthand import G

    from vnav_graph.estimators.graph.model.cpp_factors import gnss_gm_factor

    gm = GnssGM(0.0, 3.0, 120.0)
    f = gnss_gm_factor(4, 2.0, gm)
    vals = gtsam.Values()
    vals.insert(G(4), np.array([1.3]))
    vals.insert(G(5), np.array([-0.4]))
    phi = np.exp(-2.0 / 120.0)
    var_w = 9.0 * (1 - phi**2)
    assert f.error(vals) == pytest.approx(0.5 * (-0.4 - phi * 1.3) ** 2 / var_w, rel=1e-12)


def test_graph_isam2_carries_the_state_online_and_in_its_final_pass(runs, graph_runs):
    """graph-isam2: the online pass carries G(k) too (keyframe fixes then enter as rows of the
    interval they end), and the final pass solves graph-batch's problem."""
    from vnav_graph.estimators.ekf.filter import EKF
    from vnav_graph.estimators.graph import GraphISAM2

    gm = GraphConfig(gnss_gm_sd_v=GM_SD, gnss_gm_tau_s=GM_TAU)
    e_on, e_off, e_ekf = [], [], []
    for i, (d, _, _) in enumerate(runs):
        on, off = GraphISAM2(gm).run(d), GraphISAM2().run(d)
        ekf = EKF(EkfConfig(gnss_gm_sd_v=GM_SD, gnss_gm_tau_s=GM_TAU)).run(d).trajectory
        t = on.online.t[on.online.t > 5.0]
        for out, tr in ((e_on, on.online), (e_off, off.online), (e_ekf, ekf)):
            out.append(tr.at(t).alt - d.truth.at(t).alt)
        if i == 0:
            assert on.info["gnss_height_gm"] == {"sd_m": GM_SD, "tau_s": GM_TAU}
            assert "gnss_height_gm" not in off.info
            gb = graph_runs[0][2]
            # to solver tolerance: the two solves start apart (iSAM2's estimate, the batch's
            # initial values) and stop when a step would lower ½χ² by < 0.05; along the
            # weakly determined height offset (σ 1.64 m) that leaves centimetres
            sd = float(np.sqrt(np.mean(gb.cov[:, 2, 2])))
            np.testing.assert_allclose(on.trajectory.alt, gb.trajectory.alt, rtol=0,
                                       atol=0.05 * sd)
    rms = [float(np.sqrt(np.mean(np.concatenate(e) ** 2))) for e in (e_on, e_off, e_ekf)]
    # measured over the 6 drives: online with G(k) 2.48 m, without 2.21 m, forward ekf with
    # the state 1.91 m. The state does not make the *online* height better here (its gain is
    # in smoothing and in honest σ, above), and iSAM2's online pass trails the ekf by 30 %:
    # the bounds catch a broken online state (a wrong interval for the keyframe fixes gave
    # 38–64 m) without claiming more than was measured
    assert rms[0] < 1.25 * rms[1], rms
    assert rms[0] < 1.5 * rms[2], rms


def test_three_axis_state_in_every_graph_path():
    """G(k) with north, east and down (``gnss_gm_sd_h`` > 0): the general sparse path solves
    the banded path's system, graph-isam2's final pass graph-batch's problem, and both report
    the model (urban 150 s, the scenario's own σ and τ)."""
    from vnav_graph.estimators.graph import GraphISAM2

    d = simulate("urban", 1, duration_s=150.0)
    cfg = GraphConfig(gnss_gm_sd_h=2.5, gnss_gm_sd_v=4.0, gnss_gm_tau_s=30.0)
    a = GraphBatch(cfg).run(d)
    b = GraphBatch(replace(cfg, solver="general")).run(d)
    assert a.info["solver"] == "banded" and b.info["solver"] == "general"
    # measured 3e-9 m: two factorisations of one system, stopped by the same rule
    np.testing.assert_allclose(b.trajectory.pos_n(d.origin_lla), a.trajectory.pos_n(d.origin_lla),
                               rtol=0, atol=1e-6)
    np.testing.assert_allclose(b.cov[:, 0, 0], a.cov[:, 0, 0], rtol=1e-6)
    i = GraphISAM2(cfg).run(d)
    # measured 4.6 mm (the two solves start apart and stop at a ½χ² step of 0.05)
    np.testing.assert_allclose(i.trajectory.alt, a.trajectory.alt, rtol=0, atol=0.05)
    want = {"sd_h_m": 2.5, "sd_v_m": 4.0, "tau_s": 30.0}
    assert a.info["gnss_gm"] == want and i.info["gnss_gm"] == want
    ekf = EKFRTS(EkfConfig(gnss_gm_sd_h=2.5, gnss_gm_sd_v=4.0, gnss_gm_tau_s=30.0)).run(d)
    assert ekf.info["gnss_gm"] == want and ekf.info["gnss_height_gm"] == {"sd_m": 4.0,
                                                                          "tau_s": 30.0}


@pytest.mark.parametrize("dt_over_tau", [0.01, 1.0, 5.0])
def test_gm_rows_of_phi_are_exact_and_keep_the_steady_state(dt_over_tau):
    """Φ's Gauss-Markov rows (GNSS error, baro bias, IMU biases) are e^{−Δt/τ} alone, so a
    stationary σ² stays σ² over any interval, an IMU gap of several τ included."""
    from vnav_graph.sensors.noise import gm_process_var

    tau = 30.0
    dt = dt_over_tau * tau
    for gap in (0.0, 1.0):
        ing = np.zeros(km.NING)
        ing[0:9] = np.eye(3).ravel()
        ing[21], ing[22] = dt, gap
        phi = km.step_phi(ing, 2 * tau, 3 * tau, 4 * tau, tau)
        for rows, t in ((range(km.IGE, km.IGE + 3), tau), ((km.IBB,), 4 * tau),
                        (range(km.IBG, km.IBG + 3), 2 * tau), (range(km.IBA, km.IBA + 3), 3 * tau)):
            for i in rows:
                expect = np.zeros(km.NX)
                expect[i] = np.exp(-dt / t)
                np.testing.assert_allclose(phi[i], expect, rtol=1e-15, atol=0)
        i = km.IGE
        sd = 2.5
        assert phi[i, i] ** 2 * sd**2 + gm_process_var(dt, tau, sd) == pytest.approx(sd**2,
                                                                                     rel=1e-14)
