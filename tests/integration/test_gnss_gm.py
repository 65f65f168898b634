"""The optional Gauss-Markov GNSS height error state (issue 13, item 2), ``ekf-rts``.

Drive: hill-drive, 300 s, GNSS height error = white 0.5 m + Gauss-Markov σ 3 m, τ 120 s (the
receiver reports σ_v = √(0.5² + 3²), as ``sensors.gnss`` does). Treated as white, 10 Hz of
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
from vnav_graph.sensors.model import GM_WHITE_MIN_FRACTION, GnssHeightGM, gnss_gm_split
from vnav_graph.simulation.scenario import load_scenario, simulate

GM_SD, GM_TAU = 3.0, 120.0
N_SEEDS = 6


def test_split_closed_form():
    gm = GnssHeightGM(3.0, 120.0)
    sd = np.array([np.hypot(0.5, 3.0), 3.0, 10.0, np.nan])
    out = gnss_gm_split(sd, gm)
    np.testing.assert_allclose(out[:3], [0.5, GM_WHITE_MIN_FRACTION * 3.0, np.sqrt(91.0)])
    assert np.isnan(out[3])
    np.testing.assert_array_equal(gnss_gm_split(sd[:3], None), sd[:3])


def test_config_rejects_bad_settings():
    with pytest.raises(ValueError, match="gnss_gm_sd_v"):
        EkfConfig(gnss_gm_sd_v=-1.0)
    with pytest.raises(ValueError, match="gnss_gm_sd_v"):
        EkfConfig(gnss_gm_sd_v=2.0, gnss_gm_tau_s=0.0)
    assert EkfConfig().gnss_gm is None


def test_error_dynamics_entry():
    ing = np.zeros(km.NING)
    ing[0:9] = np.eye(3).ravel()
    f = km.build_f(ing, np.inf, np.inf, np.inf, 120.0)
    assert f[km.IGH, km.IGH] == pytest.approx(-1.0 / 120.0)
    assert np.count_nonzero(f[km.IGH]) == 1 and np.count_nonzero(f[:, km.IGH]) == 1
    assert np.all(km.build_f(ing, np.inf, np.inf, np.inf, np.inf)[km.IGH] == 0.0)


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


def _alt_z(est, d):
    e = est.trajectory.alt - d.truth.at(est.trajectory.t).alt
    ea = np.interp(est.t_cov, est.trajectory.t, e)
    return e, ea / np.sqrt(est.cov[:, 2, 2])


def test_gm_state_makes_the_altitude_sigma_honest(runs):
    z_off = np.concatenate([_alt_z(off, d)[1] for d, off, _ in runs])
    z_gm = np.concatenate([_alt_z(gm, d)[1] for d, _, gm in runs])
    rms_off, rms_gm = np.sqrt(np.mean(z_off**2)), np.sqrt(np.mean(z_gm**2))
    # white-noise model: σ too small by an order of magnitude (measured rms z ≈ 15)
    assert rms_off > 4.0, rms_off
    # with the state: the error is its σ (measured 0.72 over 4 seeds); six 300 s runs hold
    # only ~15 independent GM samples (τ 120 s), hence the band
    assert 0.5 < rms_gm < 1.5, rms_gm
    e_off = np.sqrt(np.mean(np.concatenate([_alt_z(off, d)[0] for d, off, _ in runs]) ** 2))
    e_gm = np.sqrt(np.mean(np.concatenate([_alt_z(gm, d)[0] for d, _, gm in runs]) ** 2))
    assert e_gm < e_off, (e_gm, e_off)


def test_gm_state_reported_and_off_by_default(runs):
    d, off, gm = runs[0]
    assert "gnss_height_gm" not in off.info
    assert gm.info["gnss_height_gm"] == {"sd_m": GM_SD, "tau_s": GM_TAU}
