"""ekf-rts's post-smoothing GNSS gate (``ekf.regate``): the whitened residual χ² of a fix
against the smoothed trajectory in closed form, the graph's threshold rule, and the re-run
with the misfits removed (counted in ``info`` and warned about)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from vnav_graph.estimators.ekf import regate
from vnav_graph.estimators.ekf.filter import EKFRTS, EkfConfig
from vnav_graph.geo.earth import radii
from vnav_graph.geo.frames import quat_to_mat
from vnav_graph.sensors.model import sensor_model
from vnav_graph.simulation.scenario import simulate
from vnav_graph.types.streams import GnssStream

CFG = EkfConfig(fb_separation=False, carry_heading_back=False)


@pytest.fixture(scope="module")
def smoothed():
    d = simulate("hill-drive", 2, duration_s=60.0)
    return d, EKFRTS(CFG).run(d)


def _fixes_on(d, est, offset_n):
    """GNSS fixes placed exactly on the smoothed antenna track, moved north by offset_n (G,)."""
    g, tr = d.gnss, est.trajectory
    j = np.clip(np.searchsorted(tr.t, g.t), 0, tr.t.size - 1)
    lla = np.column_stack([np.interp(g.t, tr.t, tr.lla[:, a]) for a in range(3)])
    d_n = np.einsum("kij,j->ki", quat_to_mat(tr.q_nb[j]), np.asarray(g.lever_arm_b, float))
    rn, re = radii(lla[:, 0])
    lla[:, 0] += (d_n[:, 0] + offset_n) / (rn + lla[:, 2])
    lla[:, 1] += d_n[:, 1] / ((re + lla[:, 2]) * np.cos(lla[:, 0]))
    lla[:, 2] -= d_n[:, 2]
    vel = np.column_stack([np.interp(g.t, tr.t, tr.vel_n[:, a]) for a in range(3)])
    return d.replace(gnss=GnssStream(g.t, lla, g.pos_sd, vel, g.vel_sd, g.lever_arm_b, g.spec))


def test_fix_chi2_closed_form(smoothed):
    d, est = smoothed
    offset = np.zeros(d.gnss.t.size)
    offset[[100, 300]] = [4.0, -12.0]  # metres north
    d2 = _fixes_on(d, est, offset)
    model = sensor_model(d2)
    c2, dof = regate.fix_chi2(d2, est, model, 0.0)
    assert dof == 6
    expect = (offset / model.gnss_pos_sd[:, 0]) ** 2
    # the output trajectory is interpolated at 50 Hz: residuals of a fix on it are round-off
    np.testing.assert_allclose(c2, expect, atol=1e-6)
    thr = regate.post_gate_threshold(0.9995, 6)
    assert thr == pytest.approx(chi2.ppf(1 - 0.0005**2, 6))
    used = np.ones(c2.size, dtype=bool)
    bad = regate.misfits(d2, est, model, 0.0, used, 0.9995)
    assert np.flatnonzero(bad).tolist() == [i for i in (100, 300) if expect[i] > thr]


def test_regated_removes_counts_and_warns(smoothed):
    d, est = smoothed
    offset = np.zeros(d.gnss.t.size)
    offset[[150, 450]] = 30.0
    d2 = _fixes_on(d, est, offset)
    model = sensor_model(d2)
    calls = []

    def again(sub):
        calls.append(sub.gnss.t.size)
        return sensor_model(sub), est  # the same trajectory: nothing else misfits

    out = regate.regated(d2, est, model, 0.0, CFG, "ekf-rts", again, 0.0)
    assert calls == [d2.gnss.t.size - 2]
    assert out.info["gnss_rejected_postsmooth"] == 2
    assert out.info["post_gate_rounds"] == 1
    assert out.info["gnss_rejected"] == est.info["gnss_rejected"] + 2
    assert set(d2.gnss.t[[150, 450]]) <= set(out.info["gnss_rejected_t"])
    assert any("did not fit the smoothed trajectory" in w for w in out.info["warnings"])


def test_fix_chi2_subtracts_the_gnss_error_state(smoothed):
    """With the Gauss-Markov GNSS error state the residual is z − (r + C l + ê), whitened by
    the white rest of the fix's σ (``GnssGM.split``): fixes placed on the antenna track plus
    ê have χ² 0, and an offset on top of ê counts in white σ."""
    d, est = smoothed
    g = d.gnss.t.size
    rng = np.random.default_rng(3)
    ge = np.column_stack([rng.normal(0, 2.5, g), np.zeros(g), np.zeros(g)])  # north only
    offset = ge[:, 0].copy()
    offset[200] += 3.0
    d2 = _fixes_on(d, est, offset)
    cfg = EkfConfig(gnss_gm_sd_h=2.0, gnss_gm_sd_v=0.0, gnss_gm_tau_s=30.0)
    model = sensor_model(d2, cfg.gnss_gm)
    est_gm = est.replace(info={**est.info, "gnss_gm_at_fixes": ge})
    c2, _ = regate.fix_chi2(d2, est_gm, model, 0.0)
    expect = np.zeros(g)
    expect[200] = (3.0 / model.gnss_pos_sd[200, 0]) ** 2
    np.testing.assert_allclose(c2, expect, atol=1e-6)
    # without ê the same fixes carry the whole error state, in units of the white σ
    c2_no, _ = regate.fix_chi2(d2, est, model, 0.0)
    np.testing.assert_allclose(c2_no, (offset / model.gnss_pos_sd[:, 0]) ** 2, atol=1e-6)


def test_ekf_rts_reports_the_smoothed_error_state_at_the_fixes(smoothed):
    d, _ = smoothed
    est = EKFRTS(EkfConfig(fb_separation=False, gnss_gm_sd_v=2.0, gnss_gm_tau_s=60.0)).run(d)
    ge = est.info["gnss_gm_at_fixes"]
    assert ge.shape == (d.gnss.t.size, 3)
    assert np.all(ge[:, :2] == 0.0)  # height-only state: north and east not carried
    assert np.all(np.isfinite(ge[:, 2])) and np.any(ge[:, 2] != 0.0)
    assert "gnss_gm_at_fixes" not in EKFRTS(CFG).run(d).info


@pytest.mark.parametrize("velocity_used", [True, False])
def test_a_fix_that_gave_only_its_velocity_is_tested(smoothed, velocity_used):
    """A fix whose position the filter refused but whose velocity it used is tested (and
    removed when it misfits); one of which nothing was used is not."""
    d, est = smoothed
    offset = np.zeros(d.gnss.t.size)
    offset[150] = 30.0
    d2 = _fixes_on(d, est, offset)
    t150 = d2.gnss.t[[150]]
    info = {**est.info, "gnss_rejected_t": t150,
            "gnss_unused_t": np.zeros(0) if velocity_used else t150}
    out = regate.regated(d2, est.replace(info=info), sensor_model(d2), 0.0, CFG, "ekf-rts",
                         lambda sub: (sensor_model(sub), est.replace(info=info)), 0.0)
    assert out.info["gnss_rejected_postsmooth"] == (1 if velocity_used else 0)


def test_unused_fixes_are_the_refused_positions_without_a_used_velocity(smoothed):
    _, est = smoothed
    unused = set(est.info["gnss_unused_t"])
    assert unused <= set(est.info["gnss_rejected_t"])


def test_huber_weights_are_the_forward_filters():
    """One threshold rule for the forward filter and the smoothed-residual weights: min(1, k/e)
    of the Mahalanobis norm e = √χ², the vectorised shared loss (``estimators.robust``, the
    graphs' IRLS weight) against the forward filter's scalar kernel (``ekf.model``)."""
    from vnav_graph.estimators.ekf.model import huber_weight

    e = np.array([0.0, 0.5, 1.99, 2.0, 2.01, 7.0, 1e4])
    for k in (2.0, 0.0):
        np.testing.assert_allclose(regate.huber_weights(e**2, k),
                                   [huber_weight(x, k) for x in e], rtol=1e-15)
    np.testing.assert_array_equal(regate.huber_weights(e**2, 0.0), np.ones(e.size))


def test_huber_sd_divides_the_white_part_only():
    """σ' of a fix of weight w keeps the Gauss-Markov part: split(σ') = split(σ)/√w, also
    where the white rest is at its 10 % floor (σ below σ_gm)."""
    from vnav_graph.sensors.gnss_model import GnssGM

    gm = GnssGM(2.5, 4.0, 30.0)
    sd = np.array([[2.55, 2.55, 4.12], [3.54, 3.54, 5.10], [1.0, 1.0, 2.0]])
    w = np.array([1.0, 0.25, 0.04])
    np.testing.assert_allclose(gm.split(regate.huber_sd(sd, w, gm)),
                               gm.split(sd) / np.sqrt(w)[:, None], rtol=1e-12)
    np.testing.assert_allclose(regate.huber_sd(sd, w, None), sd / np.sqrt(w)[:, None])


def test_huber_rounds_weigh_each_fix_by_its_smoothed_residual(smoothed):
    """Fixes k_p·σ·(1.5, 4) north of the smoothed track get position weights 1/1.5 and 1/4
    (the others, on it, 1); the pass runs on σ/√w (velocity on the track: σ kept) and
    ``info["post_huber"]`` counts the two."""
    d, est = smoothed
    cfg = EkfConfig(fb_separation=False, carry_heading_back=False, post_gate=True,
                    loss_gnss_pos="huber", loss_gnss_vel="huber", post_huber_rounds=2)
    sd_n = sensor_model(d).gnss_pos_sd[:, 0]
    offset = np.zeros(d.gnss.t.size)
    offset[[120, 400]] = 2.0 * np.array([1.5, 4.0]) * sd_n[[120, 400]]
    d2 = _fixes_on(d, est, offset)
    model = sensor_model(d2)
    seen = []

    def weighted(sub):
        seen.append(sensor_model(sub))
        return est  # the same trajectory: the weights do not change between rounds

    out = regate.huber_rounds(d2, est, model, 0.0, cfg, weighted)
    assert len(seen) == 2
    w = np.ones(d2.gnss.t.size)
    w[[120, 400]] = [1 / 1.5, 1 / 4.0]
    np.testing.assert_allclose(seen[-1].gnss_pos_sd, model.gnss_pos_sd / np.sqrt(w)[:, None],
                               rtol=1e-6)
    np.testing.assert_allclose(seen[-1].gnss_vel_sd, model.gnss_vel_sd)
    assert out.info["post_huber"] == {"rounds": 2, "downweighted": 2,
                                      "weight_min": pytest.approx(0.25, rel=1e-6)}


def test_huber_rounds_keep_the_sigma_of_a_refused_position(smoothed):
    """A fix whose position the forward gate refused keeps its σ whatever its residual (a
    weight would widen that gate for it)."""
    d, est = smoothed
    cfg = EkfConfig(fb_separation=False, carry_heading_back=False, post_gate=True,
                    loss_gnss_pos="huber", post_huber_rounds=1)
    sd_n = sensor_model(d).gnss_pos_sd[:, 0]
    offset = np.zeros(d.gnss.t.size)
    offset[[120, 400]] = 8.0 * sd_n[[120, 400]]
    d2 = _fixes_on(d, est, offset)
    model = sensor_model(d2)
    refused = est.replace(info={**est.info, "gnss_rejected_t": d2.gnss.t[[400]]})
    seen = []
    regate.huber_rounds(d2, refused, model, 0.0, cfg,
                        lambda sub: seen.append(sensor_model(sub)) or est)
    w = np.ones(d2.gnss.t.size)
    w[120] = 2.0 / 8.0
    np.testing.assert_allclose(seen[0].gnss_pos_sd, model.gnss_pos_sd / np.sqrt(w)[:, None],
                               rtol=1e-6)
