"""Integration tests of ``ekf`` / ``ekf-rts`` on simulated drives (fixed small seeds).

Monte Carlo: 20 hill-drive seeds of 300 s (consumer IMU, 10 Hz GNSS with velocity, 25 Hz
baro). 300 s rather than 120 s because the averaged NEES is strongly correlated in time
(navigation errors decorrelate over ~10 s), so a 120 s run holds only about a dozen
independent samples and its in-band fraction scatters between 0.87 and 0.96 from one seed set
to the next even for a consistent filter; 300 s makes the fraction a stable statistic.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from vnav_graph.config import BaroSpec, GnssSpec, ImuSpec
from vnav_graph.estimators.ekf.filter import EKF, EKFRTS, EkfConfig
from vnav_graph.evaluation.metrics import nees
from vnav_graph.geo.frames import lla_to_ned
from vnav_graph.sensors.noise import gm_process_var
from vnav_graph.simulation.scenario import load_scenario, simulate

N_SEEDS = 20
DUR = 300.0


@pytest.fixture(scope="module")
def monte_carlo():
    runs = []
    for s in range(N_SEEDS):
        d = simulate("hill-drive", s, duration_s=DUR)
        runs.append((d, EKF().run(d), EKFRTS().run(d)))
    return runs


def _horiz_alt_err(traj, drive):
    tr = drive.truth.at(traj.t)
    e = traj.pos_n(drive.origin_lla) - tr.pos_n(drive.origin_lla)
    return np.hypot(e[:, 0], e[:, 1]), traj.alt - tr.alt


@pytest.mark.slow
def test_nees_inside_chi2_band(monte_carlo):
    vals, dof = [], None
    for d, est, _ in monte_carlo:
        v, dof = nees(est, d)
        vals.append(v)
    avg = np.mean(vals, axis=0)
    lo, hi = chi2.ppf([0.025, 0.975], N_SEEDS * dof) / N_SEEDS
    frac = np.mean((avg >= lo) & (avg <= hi))
    # the 20-seed average NEES lies in the two-sided 95 % band on >= 90 % of epochs
    assert frac >= 0.90, (frac, avg.mean())
    # and the grand mean is the number of degrees of freedom within 10 % (no systematic
    # optimism or pessimism hidden inside the band)
    assert abs(avg.mean() / dof - 1.0) < 0.10


def test_normalised_innovations_standard_normal(monte_carlo):
    for key in ("gnss_pos", "gnss_vel", "baro"):
        z = np.concatenate([est.innovations[key].ravel() for _, est, _ in monte_carlo])
        # N(0,1): with > 1e5 samples the sample mean and rms of a true N(0,1) are within
        # 0.01; 0.05 / 0.07 leave room for the small linearisation effects during manoeuvres
        assert abs(z.mean()) < 0.05, key
        assert abs(np.sqrt(np.mean(z**2)) - 1.0) < 0.07, key
        # tails: fraction beyond 3 sigma of N(0,1) is 0.27 %; allow 2x
        assert np.mean(np.abs(z) > 3.0) < 0.0054, key


@pytest.mark.slow
def test_rts_not_worse_than_filter_on_every_seed(monte_carlo):
    alt_f, alt_s = [], []
    for d, est, sm in monte_carlo:
        hf, af = _horiz_alt_err(sm.online, d)
        hs, as_ = _horiz_alt_err(sm.trajectory, d)
        # the smoother uses all data: its RMS error may not exceed the filter's (the online
        # trajectory of the same run), on every seed, horizontally; vertically by at most 2 %
        # on a seed (the smoother is better in expectation, not on every realisation: with the
        # zero-velocity updates seed 13's filter reaches 0.141 m, its smoother 0.143 m) and
        # by far on average (20 seeds: 0.152 m filter, 0.100 m smoother)
        alt_f.append(np.sqrt(np.mean(af**2)))
        alt_s.append(np.sqrt(np.mean(as_**2)))
        assert alt_s[-1] <= 1.02 * alt_f[-1], d.name
        assert np.sqrt(np.mean(hs**2)) <= np.sqrt(np.mean(hf**2)), d.name
        # the forward pass of ekf-rts is the ekf itself
        np.testing.assert_allclose(sm.online.lla, est.trajectory.lla, rtol=0, atol=1e-9)
    assert np.mean(alt_s) <= 0.8 * np.mean(alt_f)


def test_rts_covariance_not_larger_than_filter(monte_carlo):
    for d, est, sm in monte_carlo:
        cb = sm.info.get("heading_carried_back")
        if cb is not None:  # ekf-rts smoothed a second pass from t0 with the heading given
            est = EKF(EkfConfig(initial_heading=np.radians(cb["yaw0_deg"]),
                                initial_heading_sd=np.radians(cb["sd_deg"]))).run(d)
        pf = np.diagonal(est.cov, axis1=1, axis2=2)[:, :15]
        ps = np.diagonal(sm.cov, axis1=1, axis2=2)[:, :15]
        # P^s = P+ + G (P^s - P-) G^T <= P+ (equality at the last epoch); 1e-9 relative slack
        # for round-off
        assert np.all(ps <= pf * (1 + 1e-9) + 1e-15)


def test_baro_parameters_within_sigma(monte_carlo):
    z = {"scale": [], "latency_s": [], "bias_m": []}
    for d, _, sm in monte_carlo:
        truth = {"scale": d.baro_truth.scale, "latency_s": d.baro_truth.latency_s,
                 "bias_m": float(np.mean(d.truth.bias_baro))}
        for k in z:
            p = getattr(sm.baro, k)
            z[k].append((p.est - truth[k]) / p.sd)
            assert p.sd < p.prior_sd  # every parameter is informed by 300 s of data
    for k, v in z.items():
        v = np.asarray(v)
        # normalised errors of a consistent estimator are ~N(0,1) (bias_m: σ of the time
        # average from the smoothed cross-covariances, ``ekf.rts``); rms within 0.6-1.5 over
        # the seeds (too wide a σ fails too: the average of the pointwise σ's is
        # an upper bound) and no seed beyond 3.5 sigma. Measured: scale 1.18, latency
        # 0.82, bias 1.23
        assert 0.6 < np.sqrt(np.mean(v**2)) < 1.5, (k, v)
        assert np.max(np.abs(v)) < 3.5, (k, v)


def test_noiseless_drive_converges_to_truth():
    # ideal IMU (ImuSpec.noiseless keeps the bias random walk and the scale error)
    imu = ImuSpec(name="ideal", gyro_noise_density=0.0, gyro_bias_sd=0.0, gyro_bias_rw=0.0,
                  accel_noise_density=0.0, accel_bias_sd=0.0, accel_bias_rw=0.0,
                  accel_scale_sd=0.0)
    gnss = GnssSpec(pos_sd_h=0.01, pos_sd_v=0.01, vel_sd=0.001)
    baro = BaroSpec(scale=0.01, scale_sd=0.0, latency_s=0.1, bias_sd=0.0, noise_sd=0.0)
    cfg = load_scenario("hill-drive", duration_s=120.0, imu=imu, gnss=gnss, baro=baro)
    d = simulate(cfg, 3)
    est = EKFRTS().run(d)
    m = est.trajectory.t > 30.0  # after alignment and heading acquisition
    h, a = _horiz_alt_err(est.trajectory, d)
    tr = d.truth.at(est.trajectory.t)
    # GNSS at 1 cm / 1 mm/s and ideal IMU: position to 2 cm, velocity to 5 mm/s
    assert np.max(h[m]) < 0.02 and np.max(np.abs(a[m])) < 0.02
    assert np.max(np.abs(est.trajectory.vel_n - tr.vel_n)[m]) < 0.005
    # baro scale 1 % and latency 0.1 s recovered (relief of the 120 s drive is tens of m)
    assert abs(est.baro.scale.est - 0.01) < 3 * est.baro.scale.sd + 1e-4
    assert abs(est.baro.latency_s.est - 0.1) < 3 * est.baro.latency_s.sd + 1e-3


@pytest.fixture(scope="module")
def sortie_outage():
    # first outage of the sortie (400-460 s); the drive ends 20 s after it. (Seed 2 is a
    # known 3-sigma draw of the scale/bias split: its outage altitude error reaches 2.5 m at
    # sigma 0.85 m.)
    d = simulate("sortie", 0, duration_s=480.0)
    return d, EKF().run(d)


def test_outage_vertical_bounded_by_baro(sortie_outage):
    d, est = sortie_outage
    t0, t1 = d.meta["gnss_outages"][0]
    tr = est.trajectory
    m = (tr.t >= t0) & (tr.t < t1)
    _, a = _horiz_alt_err(tr, d)
    sd_alt = np.sqrt(np.interp(tr.t[m], est.t_cov, est.cov[:, 2, 2]))
    # baro-aided vertical channel: altitude error stays within its 3-sigma and below 2 m
    # (baro noise 0.5 m, bias known to ~0.3 m at the outage start; free inertial would
    # diverge with the 570 s vertical time constant)
    assert np.all(np.abs(a[m]) < 3 * sd_alt + 0.1)
    assert np.max(np.abs(a[m])) < 2.0
    # bounded by the baro: without GNSS the altitude sigma can only grow by the drift of the
    # Gauss-Markov baro bias, σ² ≤ σ0² + σ_b²(1 − exp(−2T/τ_b)) (10 % margin for the noise
    # and the scale/latency terms) — free-inertial it would grow without bound
    spec = d.baro.spec
    drift = gm_process_var(t1 - t0, spec.bias_tau, spec.bias_sd)
    assert sd_alt[-1] < 1.1 * np.sqrt(sd_alt[0] ** 2 + drift)


def test_outage_horizontal_growth_matches_imu_grade(sortie_outage):
    d, est = sortie_outage
    t0, t1 = d.meta["gnss_outages"][0]
    k0 = np.searchsorted(est.t_cov, t0)
    k1 = np.searchsorted(est.t_cov, t1) - 1
    p0 = est.cov[k0]
    T = est.t_cov[k1] - est.t_cov[k0]
    g = 9.79
    # free-inertial closed form over T << Schuler period (Groves eq. 14.xx, short-term):
    # σ_N² ≈ σ_p² + σ_v² T² + (g σ_ψ² + σ_ba²)(T²/2)² + (g σ_bg T³/6)², per horizontal axis
    sig = []
    for ax, tilt in ((0, 7), (1, 6)):
        s2 = (p0[ax, ax] + p0[3 + ax, 3 + ax] * T**2
              + (g**2 * p0[tilt, tilt] + p0[12 + ax, 12 + ax]) * (T**2 / 2) ** 2
              + g**2 * max(p0[9, 9], p0[10, 10]) * (T**3 / 6) ** 2)
        sig.append(np.sqrt(s2))
    sd_end = np.sqrt(np.diagonal(est.cov[k1])[:2])
    # the filter's horizontal sigma at the outage end agrees with the closed form within a
    # factor 2 (the closed form ignores correlations and the turns of the sortie)
    assert np.all(sd_end < 2.0 * np.array(sig)) and np.all(sd_end > 0.5 * np.array(sig))
    # and the actual error at the outage end is inside 3 sigma
    tr = est.trajectory.at(est.t_cov[k1:k1 + 1])
    e = tr.pos_n(d.origin_lla) - d.truth.at(tr.t).pos_n(d.origin_lla)
    assert np.all(np.abs(e[0, :2]) < 3 * sd_end)


def test_gnss_outliers_are_gated():
    gnss = GnssSpec(outlier_prob=0.02, outlier_sd=30.0)
    cfg = load_scenario("hill-drive", duration_s=120.0)
    cfg = type(cfg)(**{**cfg.__dict__, "gnss": gnss})
    d = simulate(cfg, 5)
    est = EKF().run(d)
    g = d.gnss
    err = lla_to_ned(g.lla, d.origin_lla) - d.truth.at(g.t).pos_n(d.origin_lla)
    nz = np.linalg.norm(err / g.pos_sd, axis=1)
    rejected = np.isin(g.t, est.info["gnss_rejected_t"])
    gross = nz > 10.0  # a fix off by > 10 sigma is an outlier by any standard
    assert d.meta["gnss_outliers"] >= 10  # 2 % of 1200 fixes: the test has outliers to find
    assert np.all(rejected[gross])  # every gross outlier is refused
    # and hardly any good fix is: the gate at p = 0.9995 refuses 0.05 % of clean fixes
    assert np.sum(rejected & (nz < 4.0)) <= 2
    assert est.info["gnss_rejected"] == int(rejected.sum())


def test_nominal_biases_decay_as_the_gauss_markov_model_says():
    """Without measurements (a GNSS outage on a drive without baro or compass) the ekf's
    nominal gyro and accelerometer biases follow the mean of their Gauss-Markov model,
    b(t1) = e^{−(t1 − t0)/τ}·b(t0) (``kernel.decay_gm``), the step the graph's bias link takes
    (``sensors.noise.imu_bias_step``)."""
    d = simulate(load_scenario("hill-drive", duration_s=380.0), 3).replace(baro=None)
    assert d.mag is None
    est = EKF().run(d)
    tr = est.trajectory
    t0, t1 = d.imu.t[0] + 310.0, d.imu.t[0] + 350.0  # inside the 300–360 s outage
    gap = d.gnss.t[(d.gnss.t > t0 - 5.0) & (d.gnss.t < t1 + 5.0)]
    assert gap.size == 0, "the window must be free of fixes"
    i0, i1 = np.searchsorted(tr.t, [t0, t1])
    dt = tr.t[i1] - tr.t[i0]
    spec = d.imu.spec
    for b, tau in ((tr.bias_gyro, spec.gyro_bias_tau), (tr.bias_accel, spec.accel_bias_tau)):
        assert np.all(np.abs(b[i0]) > 0)  # estimated, not the zero prior mean
        np.testing.assert_allclose(b[i1], np.exp(-dt / tau) * b[i0], rtol=1e-9)
        assert np.all(np.abs(b[i1]) < np.abs(b[i0]))  # it can fail: a held bias does
