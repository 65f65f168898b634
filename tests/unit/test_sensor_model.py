"""The shared sensor layer: noise inference, baro prior, gap rule and the GNSS-height gate."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from vnav_graph.config import REAL_LOG_BARO, BaroSpec
from vnav_graph.nav.gaps import GAP_MIN_S, cv_bridge_noise, gap_threshold, imu_gaps
from vnav_graph.nav.gnss_gate import (
    NO_LIMIT,
    REFUSE,
    USE,
    USE_INFLATE,
    height_gate,
    new_gate_state,
)
from vnav_graph.sensors.model import (
    DEFICIT_LIMIT,
    K_VRE_DEFICIT,
    REAL_LOG_IMU,
    baro_prior,
    infer_imu_spec,
    measured_white_sd,
    robust_white_sd,
    specific_force_deficit,
)

G0 = 9.80665


def _imu(rate: float, accel_sd: float, gyro_sd: float, n: int, rng) -> SimpleNamespace:
    t = np.arange(n) / rate
    acc = np.array([0.0, 0.0, -G0]) + accel_sd * rng.standard_normal((n, 3))
    gyr = gyro_sd * rng.standard_normal((n, 3))
    return SimpleNamespace(t=t, accel_b=acc, gyro_b=gyr, rate_hz=rate)


def test_white_noise_sigma_is_recovered_both_ways(rng) -> None:
    x = 0.3 * rng.standard_normal((200_000, 3))
    # Δx of white noise has σ√2: both scales return σ (sampling error ~ 1/√N)
    np.testing.assert_allclose(measured_white_sd(x, 100.0), 0.3, rtol=0.01)
    np.testing.assert_allclose(robust_white_sd(x), 0.3, rtol=0.01)


def test_heavy_tails_count_at_high_rate_not_at_low_rate(rng) -> None:
    """Vibration with rare large spikes: the variance (what a filter propagates) sees them,
    the robust scale used for manoeuvre-dominated 1 Hz logs does not."""
    x = 0.1 * rng.standard_normal((100_000, 1))
    x[::50] += 3.0 * rng.standard_normal((2000, 1))
    var_sd = float(np.std(np.diff(x, axis=0))) / np.sqrt(2.0)
    assert measured_white_sd(x, 100.0)[0] == pytest.approx(var_sd, rel=1e-12)
    assert measured_white_sd(x, 1.0)[0] == pytest.approx(robust_white_sd(x)[0], rel=1e-12)
    assert measured_white_sd(x, 100.0)[0] > 2.0 * measured_white_sd(x, 1.0)[0]


def test_inferred_density_is_sigma_over_root_rate(rng) -> None:
    imu = _imu(200.0, 0.5, 0.02, 100_000, rng)
    spec = infer_imu_spec(imu, G0)
    assert spec.accel_noise_density == pytest.approx(0.5 / np.sqrt(200.0), rel=0.03)
    assert spec.gyro_noise_density == pytest.approx(0.02 / np.sqrt(200.0), rel=0.03)
    assert spec.accel_bias_rw == REAL_LOG_IMU.accel_bias_rw  # no vibration walk by default
    # a user's vibration bias walk k·σ uses the robust scale of the differences
    assert infer_imu_spec(imu, G0, k_vre=0.14).accel_bias_rw == pytest.approx(0.07, rel=0.03)


def test_quiet_imu_keeps_the_prior_and_low_rate_has_no_vibration_walk(rng) -> None:
    quiet = infer_imu_spec(_imu(100.0, 1e-6, 1e-8, 10_000, rng), G0)
    assert quiet.accel_noise_density == REAL_LOG_IMU.accel_noise_density
    assert quiet.gyro_noise_density == REAL_LOG_IMU.gyro_noise_density
    slow = infer_imu_spec(_imu(1.0, 0.5, 0.02, 5000, rng), G0)
    assert slow.accel_bias_rw == REAL_LOG_IMU.accel_bias_rw


def test_accel_bias_sigma_covers_the_specific_force_magnitude_error(rng) -> None:
    imu = _imu(100.0, 0.01, 1e-4, 5000, rng)
    imu.accel_b[:, 2] -= 0.4  # |f| reads 0.4 m/s² high at rest
    assert infer_imu_spec(imu, G0).accel_bias_sd == pytest.approx(0.8, rel=0.01)


def _climb(rng, loss: float = 0.0, rate: float = 100.0, dur: float = 120.0):
    """A level vehicle going up and down, h = 20·(1 − cos(2πt/40)) (a_up up to ±0.49 m/s²),
    its IMU at ``rate`` with 1 m/s² vibration, a 20 Hz baro with 0.3 m noise; from 40 to
    70 s the accelerometer z loses ``loss`` m/s² of specific force."""
    t = np.arange(int(dur * rate)) / rate
    w = 2 * np.pi / 40.0
    a_up = 20.0 * w**2 * np.cos(w * t)
    acc = np.zeros((t.size, 3))
    acc[:, 2] = -(G0 + a_up) + np.where((t > 40) & (t < 70), loss, 0.0)
    acc += rng.standard_normal(acc.shape)
    imu = SimpleNamespace(t=t, accel_b=acc, gyro_b=1e-3 * rng.standard_normal(acc.shape),
                          rate_hz=rate)
    tb = np.arange(int(dur * 20)) / 20.0
    baro = SimpleNamespace(t=tb, altitude=20.0 * (1 - np.cos(w * tb))
                           + 0.3 * rng.standard_normal(tb.size))
    return imu, baro


def test_specific_force_deficit_sees_a_lost_specific_force_not_a_climb(rng) -> None:
    """|f| ≥ |g + a_up| for a working accelerometer: climbing and descending (a_up ±0.49
    m/s²) leave the deficit near 0 (its noise: 1 m/s² vibration over ~400 samples, the baro's
    second difference); an accelerometer that reads 2 m/s² low for 30 s of the 120 s gives
    its 5th percentile ≈ −2."""
    imu, baro = _climb(rng)
    ok = specific_force_deficit(imu, baro, G0)
    assert ok is not None and abs(ok) < 0.2
    imu, baro = _climb(rng, loss=2.0)
    bad = specific_force_deficit(imu, baro, G0)
    assert bad is not None and bad == pytest.approx(-2.0, abs=0.3)
    assert specific_force_deficit(imu, None, G0) is None


def test_rectifying_accelerometer_gets_the_vibration_bias_walk(rng) -> None:
    imu, baro = _climb(rng)
    assert infer_imu_spec(imu, G0, baro=baro).accel_bias_rw == REAL_LOG_IMU.accel_bias_rw
    imu, baro = _climb(rng, loss=3 * DEFICIT_LIMIT)
    spec = infer_imu_spec(imu, G0, baro=baro)
    assert spec.name.endswith("-rectifying")
    sd = float(np.max(robust_white_sd(imu.accel_b)))
    assert spec.accel_bias_rw == pytest.approx(K_VRE_DEFICIT * sd, rel=1e-12)
    # at 1 Hz the differences are manoeuvres: no vibration walk, whatever the deficit
    slow, baro = _climb(rng, loss=3 * DEFICIT_LIMIT, rate=1.0, dur=600.0)
    assert infer_imu_spec(slow, G0, baro=baro).accel_bias_rw == REAL_LOG_IMU.accel_bias_rw


def test_baro_prior_closed_forms() -> None:
    p = baro_prior(BaroSpec(scale_sd=0.02, latency_range_s=(0.1, 0.3), bias_sd=3.0,
                            bias_tau=900.0, noise_sd=0.3))
    assert p.latency_mean == pytest.approx(0.2)
    assert p.latency_sd == pytest.approx(0.2 / np.sqrt(12.0))  # uniform: width/√12
    assert (p.scale_sd, p.bias_sd, p.bias_tau, p.noise_sd) == (0.02, 3.0, 900.0, 0.3)
    # a spec that fixes the truth (a scale, a zero scale σ, a fixed latency) does not leak it:
    # the estimators get the documented real-log prior
    dflt = baro_prior(REAL_LOG_BARO)
    for fixed in (BaroSpec(scale=-0.05, scale_sd=0.0, latency_s=0.25, latency_range_s=None),
                  BaroSpec(scale_sd=0.0, latency_s=0.0, latency_range_s=None)):
        p = baro_prior(fixed)
        assert p.scale_sd == dflt.scale_sd == 0.02
        assert (p.latency_mean, p.latency_sd) == (dflt.latency_mean, dflt.latency_sd)
        assert dflt.latency_mean == pytest.approx(0.1) and dflt.latency_sd == pytest.approx(0.1)


def test_gap_rule() -> None:
    t = np.arange(0.0, 10.0, 0.01)
    t = np.r_[t[:300], t[306:700], t[760:]]  # 70 ms (under the 0.25 s floor) and 0.61 s
    assert gap_threshold(t) == GAP_MIN_S
    np.testing.assert_array_equal(imu_gaps(t), [693])
    slow = np.r_[np.arange(0.0, 20.0, 1.0), np.arange(26.0, 40.0, 1.0)]  # 1 Hz, a 7 s gap
    assert gap_threshold(slow) == pytest.approx(5.0)
    np.testing.assert_array_equal(imu_gaps(slow), [19])
    assert imu_gaps(np.array([0.0])).size == 0


def test_constant_velocity_bridge_matches_integrated_white_acceleration(rng) -> None:
    """q·T³/3, q·T²/2, q·T: the covariance of (∫∫a, ∫a) for white a of PSD q (MC check)."""
    q, T, m = 0.7, 3.0, 400
    dt = T / m
    a = rng.standard_normal((20_000, m)) * np.sqrt(q / dt)
    v = np.cumsum(a, axis=1) * dt
    p = np.cumsum(v, axis=1) * dt
    c = np.cov(np.c_[p[:, -1], v[:, -1]].T)
    pp, pv, vv = cv_bridge_noise(q, T)
    np.testing.assert_allclose([c[0, 0], c[0, 1], c[1, 1]], [pp, pv, vv], rtol=0.05)


def _decide(seq, **kw):
    st = new_gate_state()
    args = dict(gate=9.0, probation_s=3.0, max_consec=NO_LIMIT, widen_var=0.0, force=False)
    args.update(kw)
    return [height_gate(st, t, True, nu2, 1.0, args["gate"], args["probation_s"],
                        args["max_consec"], args["widen_var"], args["force"])
            for t, nu2 in seq]


def test_gate_isolated_refusal_is_only_a_refusal() -> None:
    seq = [(0, 1.0), (1, 100.0), (2, 1.0), (3, 1.0)]
    assert _decide(seq) == [USE, REFUSE, USE, USE]


def test_gate_two_refusals_start_probation() -> None:
    # refused twice → on probation: passing fixes are refused until 3 s of passes
    seq = [(0, 1.0), (1, 100.0), (2, 100.0), (3, 1.0), (4, 1.0), (5, 1.0), (6, 1.0), (7, 1.0)]
    assert _decide(seq) == [USE, REFUSE, REFUSE, REFUSE, REFUSE, REFUSE, USE, USE]
    # a failing fix during probation restarts the clock
    seq = [(0, 100.0), (1, 100.0), (2, 1.0), (3, 1.0), (4, 100.0), (5, 1.0), (8, 1.0)]
    assert _decide(seq) == [REFUSE] * 6 + [USE]


def test_gate_unusable_sigma_is_refused() -> None:
    st = new_gate_state()
    assert height_gate(st, 0.0, False, 0.0, 1.0, 9.0, 3.0, NO_LIMIT, 0.0, False) == REFUSE


def test_gate_long_run_widens_and_inflates_or_forces() -> None:
    # after max_consec refusals the test is widened by widen_var: ν² = 50 passes 9·(1 + 10)
    seq = [(t, 50.0) for t in range(6)]
    out = _decide(seq, max_consec=3, widen_var=10.0, probation_s=1.0)
    assert out == [REFUSE, REFUSE, REFUSE, REFUSE, USE_INFLATE, REFUSE]
    # without a barometer a long run ends by accepting the fix
    out = _decide([(t, 1e6) for t in range(5)], max_consec=3, force=True)
    assert out == [REFUSE, REFUSE, REFUSE, USE, REFUSE]
