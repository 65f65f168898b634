"""Seed-004 4-state baro-inertial Kalman filter (vnav_graph.estimators.vertical.vkf4)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy.stats import chi2

from vnav_graph.config import IMU_PRESETS
from vnav_graph.estimators.vertical.vkf4 import VKF4, VKF4Config
from vnav_graph.evaluation.metrics import errors_vs_truth, nees
from vnav_graph.simulation import load_scenario, simulate

OUTAGE = (250.0, 370.0)  # a 120 s GNSS outage containing a level change of the sortie


@pytest.fixture(scope="module")
def outage_runs():
    cfg = load_scenario("sortie")
    c = replace(cfg, duration_s=500.0, gnss=replace(cfg.gnss, outages=(OUTAGE,)))
    runs = []
    for seed in range(3):
        d = simulate(c, seed)
        runs.append((d, VKF4().run(d)))
    return runs


def test_altitude_bounded_in_120s_outage(outage_runs) -> None:
    # With baro only, the corrected INS follows the baro minus its last error estimate, so the
    # altitude error can only grow by how much the true baro error changes during the outage:
    # the scale error times the altitude change, |s|·max|h − h(t_out)|, plus the latency error
    # τ·|v_up|. 3 m covers the filter's error at the outage start (σ ≈ 1 m, 3σ) plus noise.
    # A free-inertial channel with this IMU would drift by tens of metres in 120 s.
    for d, est in outage_runs:
        err = errors_vs_truth(est, d)
        m = (err.t >= OUTAGE[0]) & (err.t < OUTAGE[1])
        tr = d.truth
        mt = (tr.t >= OUTAGE[0]) & (tr.t < OUTAGE[1])
        dh = np.max(np.abs(tr.alt[mt] - tr.alt[mt][0]))
        bt = d.baro_truth
        bound = 3.0 + abs(bt.scale) * dh + abs(bt.latency_s) * np.max(np.abs(tr.vel_n[mt, 2]))
        assert np.max(np.abs(err.alt[m])) < bound
        # and no drift: the second half of the outage is not worse than the bound either
        late = m & (err.t > 0.5 * (OUTAGE[0] + OUTAGE[1]))
        assert np.max(np.abs(err.alt[late])) < bound


def test_nees_consistent(outage_runs) -> None:
    # 2-dof NEES (height, down velocity) averaged over 3 seeds: inside the two-sided 99 %
    # χ² band chi2(0.005/0.995, 3·2)/3 on ≥ 90 % of the 1 Hz epochs.
    vals = [nees(est, d) for d, est in outage_runs]
    dof = vals[0][1]
    assert dof == 2
    k = min(v[0].size for v in vals)
    avg = np.mean([v[0][:k] for v in vals], axis=0)
    lo, hi = chi2.ppf([0.005, 0.995], 3 * dof) / 3
    assert np.mean((avg > lo) & (avg < hi)) >= 0.9


def test_innovations_white_unit(outage_runs) -> None:
    # normalised innovation RMS ≈ 1 for a consistent filter; 0.8..1.25 allows the deliberate
    # conservatism of the lumped process noise A (bias absorbed as white noise).
    for _, est in outage_runs:
        for key in ("baro", "gnss_alt"):
            rms = float(np.sqrt(np.mean(est.innovations[key] ** 2)))
            assert 0.8 < rms < 1.25, key


def test_covariance_layout(outage_runs) -> None:
    d, est = outage_runs[0]
    assert est.cov is not None and est.cov.shape[1:] == (18, 18)
    finite = np.isfinite(np.diagonal(est.cov[-1]))
    assert np.flatnonzero(finite).tolist() == [2, 5, 17]  # pos_n down, vel_n down, baro_bias
    blk = est.cov[:, [2, 5, 17]][:, :, [2, 5, 17]]
    np.testing.assert_allclose(blk, np.swapaxes(blk, 1, 2), atol=1e-12)
    assert np.all(np.linalg.eigvalsh(blk) > 0)
    assert np.all(np.isnan(est.trajectory.lla[:, :2]))
    assert est.provides == frozenset({"alt", "vel_d", "baro", "cov"})


def test_noiseless_sensors_track_truth() -> None:
    # Noiseless IMU, baro with no scale/latency/noise and a constant bias, no GNSS noise
    # effect beyond 0.01 m: the filter must follow truth to the AHRS-induced error only
    # (attitude from a GNSS-aided reference: mm/s² of f_D error; measured 0.017 m RMS). The
    # 0.1 m bound leaves room for other seeds; the baro error states must take up the
    # 4 m offset (time average incl. the first seconds of convergence: 0.2 m).
    cfg = load_scenario("sortie")
    c = replace(
        cfg, duration_s=300.0, imu=IMU_PRESETS["industrial"].noiseless(),
        gnss=replace(cfg.gnss, pos_sd_v=0.01, pos_sd_h=0.01, vel_sd=0.001, outages=()),
        baro=replace(cfg.baro, scale=0.0, latency_s=0.0, latency_range_s=None, bias_init=4.0,
                     bias_tau=float("inf"), noise_sd=0.0),
    )
    d = simulate(c, 7)
    est = VKF4(VKF4Config(baro_noise_sd=0.05)).run(d)
    err = errors_vs_truth(est, d)
    assert np.sqrt(np.mean(err.alt[err.t > 60.0] ** 2)) < 0.1
    assert est.baro is not None and est.baro.bias_m is not None
    assert est.baro.bias_m.est == pytest.approx(4.0, abs=0.2)
