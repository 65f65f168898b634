"""Urban GNSS error model (Gauss-Markov errors, multipath bursts, random outages) and the
hot-day barometer (``BaroSpec.isa_offset_k``), each against its defining statistic or a
closed form; plus the guarantee that with those fields off a drive keeps its random draws."""

from dataclasses import replace

import numpy as np
import pytest

from vnav_graph.config import BaroSpec, GnssSpec
from vnav_graph.geo.atmosphere import T0
from vnav_graph.geo.frames import lla_to_ned
from vnav_graph.simulation import load_scenario, simulate
from vnav_graph.simulation.gnss import simulate_gnss
from vnav_graph.simulation.measurements import simulate_baro
from vnav_graph.types import Trajectory

ORIGIN = np.array([np.radians(48.1), np.radians(11.6), 520.0])


def _static_truth(duration_s: float, dt: float = 1.0) -> Trajectory:
    t = np.arange(0.0, duration_s + 0.5 * dt, dt)
    n = t.size
    return Trajectory(t, np.tile(ORIGIN, (n, 1)), np.zeros((n, 3)),
                      np.tile([1.0, 0.0, 0.0, 0.0], (n, 1)))


def _errors_n(stream) -> np.ndarray:
    return lla_to_ned(stream.lla, ORIGIN)  # truth sits at the origin


# a receiver with (almost) no white noise, so the urban errors are seen alone
QUIET = GnssSpec(rate_hz=1.0, pos_sd_h=1e-3, pos_sd_v=1e-3, vel_sd=1e-3)


def test_burst_fraction_matches_the_spec_over_a_long_stream():
    spec = replace(QUIET, burst_fraction=0.1, burst_len_s=(5.0, 30.0), burst_err_m=(5.0, 50.0))
    stream, log = simulate_gnss(_static_truth(40000.0), None, spec, np.random.default_rng(1))
    # ≈ 230 bursts; the renewal-reward estimate of the fraction has σ ≈ 0.0065 (gaps are
    # exponential with mean 157.5 s), so ±0.025 is about 4σ
    assert log.in_burst.mean() == pytest.approx(0.1, abs=0.025)
    inside = np.zeros(stream.t.size, dtype=bool)
    for a, b in log.burst_windows:
        assert 5.0 <= b - a <= 30.0 or b == pytest.approx(40000.0)
        inside |= (stream.t >= a) & (stream.t < b)
    np.testing.assert_array_equal(inside, log.in_burst)
    e = _errors_n(stream)
    # per burst: the mean error is the burst's offset (magnitude in [5, 50] m up to the
    # jitter's mean, σ ≤ 0.2·m·√(2τ/L) ≈ 0.15·m for L = 5 s) and mostly horizontal (|el| ≤ 30°)
    norms, vert = [], []
    for a, b in log.burst_windows:
        k = (stream.t >= a) & (stream.t < b)
        if k.sum() < 5:
            continue
        m = e[k].mean(axis=0)
        norms.append(np.linalg.norm(m))
        vert.append(abs(m[2]) / np.linalg.norm(m))
    assert 0.5 * 5.0 < min(norms) and max(norms) < 1.5 * 50.0
    assert np.median(vert) < np.sin(np.radians(30.0))
    # outside bursts only the 1 mm white noise
    assert np.max(np.abs(e[~log.in_burst])) < 0.01


def test_reported_sd_stays_nominal_inside_bursts():
    spec = GnssSpec(rate_hz=5.0, pos_sd_h=0.8, pos_sd_v=1.5, vel_sd=0.2, burst_fraction=0.2,
                    burst_vel_sd=0.5)
    stream, log = simulate_gnss(_static_truth(3000.0), None, spec, np.random.default_rng(2))
    assert log.in_burst.any()
    np.testing.assert_array_equal(stream.pos_sd, np.tile([0.8, 0.8, 1.5], (stream.t.size, 1)))
    np.testing.assert_array_equal(stream.vel_sd, np.full((stream.t.size, 3), 0.2))
    e = _errors_n(stream)
    # the bursts' error (≥ 5 m) is far beyond the reported 0.8 m: the sd understates there
    assert np.median(np.hypot(e[log.in_burst, 0], e[log.in_burst, 1])) > 3 * 0.8
    # Doppler velocity: white σ 0.2 outside, sqrt(0.2² + 0.5²) = 0.54 inside (±10 %: > 1000
    # samples per axis)
    v = stream.vel_n
    assert np.std(v[~log.in_burst]) == pytest.approx(0.2, rel=0.1)
    assert np.std(v[log.in_burst]) == pytest.approx(np.hypot(0.2, 0.5), rel=0.1)


def test_gauss_markov_errors_have_the_configured_sigma_and_correlation_time():
    spec = replace(QUIET, gm_sd_h=2.0, gm_sd_v=3.0, gm_tau_s=30.0)
    stream, _ = simulate_gnss(_static_truth(60000.0), None, spec, np.random.default_rng(3))
    e = _errors_n(stream)
    # 60000 s / 30 s: ≈ 1000 correlation times per axis; variance to ±10 %, the lag-τ
    # autocorrelation (e^-1 for a first-order GM) to ±0.05 (σ ≈ 0.03 per axis)
    for j, sd in ((0, 2.0), (1, 2.0), (2, 3.0)):
        x = e[:, j]
        assert np.std(x) == pytest.approx(sd, rel=0.1)
        r = np.mean(x[30:] * x[:-30]) / np.mean(x * x)
        assert r == pytest.approx(np.exp(-1.0), abs=0.05)
    # the reported sd covers white and correlated errors: sqrt(0.001² + 2²)
    np.testing.assert_allclose(stream.pos_sd[0], [np.hypot(1e-3, 2.0)] * 2 + [np.hypot(1e-3, 3)])


def test_random_outages_have_lengths_in_range_and_no_fixes():
    spec = replace(QUIET, rate_hz=5.0, random_outages_per_hour=20.0,
                   random_outage_len_s=(5.0, 20.0))
    span = 36000.0
    stream, log = simulate_gnss(_static_truth(span), None, spec, np.random.default_rng(4))
    n = len(log.random_outages)
    assert abs(n - 200) < 4 * np.sqrt(200)  # Poisson(20 per hour · 10 h)
    for a, b in log.random_outages:
        assert 0.0 <= a < b <= span
        assert 5.0 <= b - a <= 20.0 or b == span
        assert not np.any((stream.t >= a) & (stream.t < b))
    # every gap between fixes longer than one period lies in an outage
    gaps = np.flatnonzero(np.diff(stream.t) > 0.2 + 1e-9)
    for i in gaps:
        mid = 0.5 * (stream.t[i] + stream.t[i + 1])
        assert any(a <= mid < b for a, b in log.random_outages)


def test_urban_draws_leave_the_rest_of_the_drive_unchanged():
    cfg = load_scenario("hill-drive", duration_s=60.0)
    base = simulate(cfg, 3)
    gm = simulate(replace(cfg, gnss=replace(cfg.gnss, gm_sd_h=2.0, gm_tau_s=30.0)), 3)
    # IMU, baro and truth bit-identical; the GNSS fixes differ only by the GM error
    np.testing.assert_array_equal(gm.imu.accel_b, base.imu.accel_b)
    np.testing.assert_array_equal(gm.baro.alt, base.baro.alt)
    np.testing.assert_array_equal(gm.gnss.t, base.gnss.t)
    np.testing.assert_array_equal(gm.gnss.vel_n, base.gnss.vel_n)
    np.testing.assert_array_equal(gm.gnss.lla[:, 2], base.gnss.lla[:, 2])  # gm_sd_v = 0
    dn = lla_to_ned(gm.gnss.lla, base.origin_lla) - lla_to_ned(base.gnss.lla, base.origin_lla)
    # the difference is the GM error: σ 2 m, τ 30 s, so over 60 s a slowly moving offset
    assert 0.2 < np.max(np.abs(dn[:, 0])) < 10.0
    # correlated, not white: a 0.1 s step has σ 2·sqrt(1 − e^(−0.2/30)) = 0.16 m (max of 600
    # ≈ 0.55 m), where white noise of σ 2 m would step by ≈ 2.8 m
    assert np.max(np.abs(np.diff(dn[:, 0]))) < 1.0
    assert base.meta["gnss_burst_windows"] == [] and base.meta["gnss_random_outages"] == []


def test_urban_fields_off_leave_the_default_draws_unchanged():
    # Reference numbers of a drive simulated without the urban and hot-day GnssSpec/BaroSpec
    # fields: with those fields off the random draws are the same. A shifted draw changes them
    # at the 1e-3 level; rtol 1e-9 leaves room for last-bit differences of libm between machines.
    d = simulate("hill-drive", 3, duration_s=60.0)
    got = [np.sum(d.imu.accel_b), np.sum(d.imu.gyro_b), np.mean(d.gnss.lla[:, 2]),
           np.sum(d.gnss.lla[:, 0]), np.sum(d.gnss.vel_n), np.mean(d.baro.alt),
           d.baro_truth.scale]
    ref = [-118136.95037754247, -183.51787950202475, 578.4066293700212, 494.9056453005379,
           -5882.496760680478, 580.4618366947755, 0.008732278276481981]
    np.testing.assert_allclose(got, ref, rtol=1e-9)
    d = simulate("sortie", 1, duration_s=60.0)
    got = [np.sum(d.imu.accel_b), np.mean(d.gnss.lla[:, 2]), np.sum(d.gnss.vel_n),
           np.mean(d.baro.alt), d.baro_truth.scale]
    ref = [-103887.97675949482, 900.8540077938083, -1500.6967265126984, 899.4071222211179,
           -0.0007358725264073726]
    np.testing.assert_allclose(got, ref, rtol=1e-9)
    # physical baro at isa_offset_k = 0
    t_truth = np.arange(0, 600.0, 0.1)
    h = 800.0 + 300.0 * np.sin(t_truth / 100.0)
    spec = BaroSpec(rate_hz=5.0, scale_sd=0.02, latency_s=0.2, bias_sd=5.0, bias_tau=600.0,
                    noise_sd=0.3, physical=True)
    st, tr, _ = simulate_baro(np.arange(0, 600.0, 0.2), t_truth, h, 800.0, spec,
                              np.random.default_rng(7))
    np.testing.assert_allclose([np.mean(st.pressure), st.pressure[100], tr.scale],
                               [92137.47831057139, 91430.19657753302, 2.4603067149651485e-05],
                               rtol=1e-9)


@pytest.mark.parametrize("h0", [0.0, 890.0, 2500.0])
def test_hot_day_baro_reads_with_the_effective_scale(h0):
    t_truth = np.arange(0.0, 100.0 + 1e-9, 0.1)
    h = h0 + 5.0 * t_truth  # h0 .. h0 + 500 m
    spec = BaroSpec(rate_hz=1.0, scale=-0.03, scale_sd=0.0, latency_s=0.0, bias_sd=0.0,
                    noise_sd=0.0, physical=True, isa_offset_k=15.0)
    t = np.array([0.0, 100.0])
    st, truth, _ = simulate_baro(t, t_truth, h, h0, spec, np.random.default_rng(0))
    hi = st.altitude
    assert hi[0] == pytest.approx(h0, abs=1e-6)  # the reading is set exact at the origin
    measured = (hi[1] - hi[0]) / 500.0 - 1.0
    # in the ISA troposphere the standard-law reading is affine in h: the slope is exact
    assert measured == pytest.approx(truth.scale, abs=1e-9)
    # and close to the textbook (1 + s)·T0/(T0 + ΔT) − 1 = −7.80 %; the reference height moves
    # it by ≈ −L·h0·dT/(T0 + dT)², dT = 24.4 K the total offset (−1.5e-3 at 890 m, −4.1e-3 at
    # 2500 m)
    assert truth.scale == pytest.approx(0.97 * T0 / (T0 + 15.0) - 1.0, abs=5e-3)
    # and a hot day alone (s = 0) gives ≈ −ΔT/T0: the altimeter under-reads climbs
    st0, truth0, _ = simulate_baro(t, t_truth, h, h0, replace(spec, scale=0.0),
                                   np.random.default_rng(0))
    assert (st0.altitude[1] - st0.altitude[0]) / 500.0 - 1.0 == pytest.approx(
        truth0.scale, abs=1e-9)
    assert -0.06 < truth0.scale < -0.045


def test_hot_day_baro_with_a_drifting_bias_keeps_the_scale():
    t_truth = np.arange(0.0, 600.0 + 1e-9, 0.1)
    h = 890.0 + 2.0 * t_truth  # 1200 m climb
    spec = BaroSpec(rate_hz=1.0, scale=-0.03, scale_sd=0.0, latency_s=0.0, bias_sd=10.0,
                    bias_tau=300.0, noise_sd=0.0, physical=True, isa_offset_k=15.0)
    t = np.arange(0.0, 600.0 + 1e-9, 1.0)
    st, truth, bias = simulate_baro(t, t_truth, h, 890.0, spec, np.random.default_rng(5))
    lin = 890.0 + (1 + truth.scale) * (np.interp(t, t_truth, h) - 890.0) + bias
    # a bias b shifts the sea-level pressure, which tilts the reading by ≈ L·b/T0 relative
    # (≤ 2e-4 for |b| ≤ 3σ = 30 m): ≤ 0.3 m over the 1200 m climb
    assert np.max(np.abs(st.altitude - lin)) < 0.3


def test_isa_offset_needs_the_physical_mode():
    with pytest.raises(ValueError, match="isa_offset_k.*physical"):
        BaroSpec(isa_offset_k=15.0)
    with pytest.raises(ValueError, match="isa_offset_k"):
        BaroSpec(isa_offset_k=80.0, physical=True)
    BaroSpec(isa_offset_k=-10.0, physical=True)  # cold day: allowed


@pytest.mark.parametrize("field,value", [
    ("gm_tau_s", 0.0), ("gm_sd_h", -1.0), ("burst_fraction", 0.95), ("burst_len_s", (30.0, 5.0)),
    ("burst_err_m", (0.0, 5.0)), ("random_outages_per_hour", -1.0),
    ("random_outage_len_s", (5.0,)),
])
def test_gnss_spec_rejects_bad_urban_fields(field, value):
    with pytest.raises(ValueError, match=field):
        GnssSpec(**{field: value})
