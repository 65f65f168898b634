"""Sensor error models: noise statistics, stationary IMU, the baro model and its Jacobian."""

import numpy as np
import pytest

from vnav_graph.config import IMU_PRESETS, BaroSpec
from vnav_graph.geo.earth import OMEGA_IE, gravity
from vnav_graph.sensors.baro import baro_arrays, baro_predict, baro_row
from vnav_graph.sensors.noise import white_sd
from vnav_graph.simulation import noise, simulate
from vnav_graph.simulation.measurements import simulate_baro
from vnav_graph.simulation.noise import gauss_markov, linear_recurrence, random_walk


def test_gauss_markov_is_stationary_with_right_correlation(rng):
    t = np.arange(0, 2000.0, 1.0)
    x = gauss_markov(t, tau=50.0, sd=2.0, rng=rng, size=400)
    # 400 x 2000 samples: the variance estimate has ~1-2 % sampling error (correlated samples)
    assert np.var(x) == pytest.approx(4.0, rel=0.06)
    # lag-50 autocorrelation of a GM process is exp(-1)
    r = np.mean(x[50:] * x[:-50]) / np.var(x)
    assert r == pytest.approx(np.exp(-1), abs=0.04)


@pytest.mark.parametrize("m, block", [(0, 4096), (1, 4096), (2, 4096), (7, 4096),
                                      (64, 4096), (1000, 4096), (1000, 64), (1000, 7)])
def test_linear_recurrence_equals_the_sequential_loop(rng, monkeypatch, m, block):
    monkeypatch.setattr(noise, "SCAN_BLOCK", block)  # several blocks: the carry between them
    a = rng.uniform(0.0, 1.0, m)
    a[::5] = 1.0  # random-walk steps
    w = rng.normal(size=(m, 3))
    ref = np.zeros((m, 3))
    prev = np.zeros(3)
    for k in range(m):
        prev = a[k] * prev + w[k]
        ref[k] = prev
    np.testing.assert_allclose(linear_recurrence(a, w), ref, rtol=1e-12, atol=1e-12)


def test_gauss_markov_long_uniform_series_path_equals_the_scan(monkeypatch):
    # the scipy.signal.lfilter path of long uniform series, forced on a short one
    t = np.arange(700) * 0.01
    ref = gauss_markov(t, tau=5.0, sd=1.0, rng=np.random.default_rng(3), size=3)
    monkeypatch.setattr(noise, "LFILTER_MIN_ROWS", 10)
    long = gauss_markov(t, tau=5.0, sd=1.0, rng=np.random.default_rng(3), size=3)
    np.testing.assert_allclose(long, ref, rtol=1e-12, atol=1e-12)


def test_gauss_markov_irregular_steps_and_start_value(rng):
    # non-uniform Δt: same recursion as the uniform case, x0 carried by the first step
    t = np.cumsum(rng.uniform(0.05, 0.15, 2001))
    x = gauss_markov(t, tau=5.0, sd=0.0, rng=rng, size=2, x0=np.array([1.0, -2.0]))
    np.testing.assert_allclose(x[:, 0], np.exp(-(t - t[0]) / 5.0), rtol=1e-12)
    np.testing.assert_allclose(x[:, 1], -2.0 * np.exp(-(t - t[0]) / 5.0), rtol=1e-12)


def test_random_walk_and_white_noise_scale(rng):
    t = np.arange(0, 100.0, 0.01)
    rw = random_walk(t, density=0.3, rng=rng, size=2000)
    # var(RW(T)) = q²·T = 0.09·100 = 9 (2000 runs → ±6 % at 2σ... use 10 %)
    assert np.var(rw[-1]) == pytest.approx(9.0, rel=0.1)
    assert white_sd(0.01, 0.005) == pytest.approx(0.01 / np.sqrt(0.005))


def test_stationary_imu_reads_earth_rate_and_minus_gravity():
    d = simulate("seed003", 0, duration_s=8.0, imu=IMU_PRESETS["tactical"].noiseless())
    # seed003 starts with 10 s static, level platform
    lat, h = d.origin_lla[0], d.origin_lla[2]
    np.testing.assert_allclose(d.imu.accel_b[0], [0.0, 0.0, -gravity(lat, h)], atol=1e-12)
    np.testing.assert_allclose(
        d.imu.gyro_b[0], [OMEGA_IE * np.cos(lat), 0.0, -OMEGA_IE * np.sin(lat)], atol=1e-15)


def test_baro_simulation_follows_the_shared_model(rng):
    t_truth = np.arange(0, 300.0, 0.01)
    h = 500.0 + 100.0 * np.sin(2 * np.pi * t_truth / 120.0)
    spec = BaroSpec(rate_hz=10.0, scale=0.02, latency_s=0.2, bias_sd=0.0, noise_sd=0.0)
    t = np.arange(1.0, 299.0, 0.1)
    stream, truth, bias = simulate_baro(t, t_truth, h, 500.0, spec, rng)
    v_up = np.interp(t, t_truth, np.gradient(h, t_truth))
    pred = baro_arrays(np.interp(t, t_truth, h), v_up, truth.scale, truth.latency_s, bias,
                       500.0)[0]
    # model vs simulation differ only by the first-order latency expansion:
    # |h''|·τ²/2 ≤ 100·(2π/120)²·0.04/2 ≈ 5.5 mm, times (1+s)
    assert np.max(np.abs(pred - stream.alt)) < 6e-3


def test_baro_physical_mode_reproduces_scale_and_bias(rng):
    t_truth = np.arange(0, 600.0, 0.1)
    h0 = 800.0
    h = h0 + 300.0 * t_truth / 600.0
    spec = BaroSpec(rate_hz=1.0, scale=-0.02, latency_s=0.0, bias_sd=5.0, bias_tau=600.0,
                    noise_sd=0.0, physical=True)
    t = np.arange(0, 600.0, 1.0)
    stream, truth, bias = simulate_baro(t, t_truth, h, h0, spec, rng)
    assert stream.pressure is not None
    lin = h0 + (1 + truth.scale) * (np.interp(t, t_truth, h) - h0) + bias
    # ISA nonlinearity over 300 m and the bias/scale interaction: a few decimetres at most
    assert np.max(np.abs(stream.altitude - lin)) < 0.5


def test_baro_jacobian_matches_finite_differences():
    x = np.array([812.0, -7.5, 0.013, 0.12, -3.0])  # h, v_up, s, tau, b
    h0 = 640.0
    jac = baro_arrays(*x, h0=h0)[1]
    eps = 1e-6
    fd = []
    for i in range(5):
        xp, xm = x.copy(), x.copy()
        xp[i] += eps
        xm[i] -= eps
        fd.append((baro_arrays(*xp, h0=h0)[0] - baro_arrays(*xm, h0=h0)[0]) / (2 * eps))
    np.testing.assert_allclose(jac, fd, rtol=1e-7, atol=1e-7)  # model is bilinear: FD exact-ish


def test_baro_arrays_map_the_one_compiled_model_over_broadcast_inputs(rng):
    # the array forms (the graph's) are the scalar model (the filters') sample by sample,
    # bitwise, and broadcast a scalar scale/latency as numpy would
    h0 = 500.0
    h, vup, b = rng.uniform(0, 3000, 40), rng.normal(0, 10, 40), rng.normal(0, 5, 40)
    s, tau = rng.normal(0, 0.02), rng.uniform(0, 0.5)
    pred = baro_arrays(h, vup, s, tau, b, h0)[0]
    jac = baro_arrays(h.reshape(8, 5), vup.reshape(8, 5), s, tau, 0.0, h0)[1]
    assert pred.shape == (40,) and jac.shape == (8, 5, 5)
    for i in range(40):
        assert pred[i] == baro_predict(h[i], vup[i], s, tau, b[i], h0)
        np.testing.assert_array_equal(jac.reshape(40, 5)[i], baro_row(h[i], vup[i], s, tau, h0))
    # the closed form of docs/design.md's model, in the same operation order
    np.testing.assert_array_equal(pred, h0 + (1.0 + s) * (h - h0 - vup * tau) + b)
    assert np.ndim(baro_arrays(1.0, 2.0, 0.0, 0.0, 0.0, 0.0)[0]) == 0


def test_simulation_is_deterministic_per_seed():
    a = simulate("hill-drive", 7, duration_s=60.0)
    b = simulate("hill-drive", 7, duration_s=60.0)
    c = simulate("hill-drive", 8, duration_s=60.0)
    np.testing.assert_array_equal(a.imu.accel_b, b.imu.accel_b)
    np.testing.assert_array_equal(a.baro.alt, b.baro.alt)
    assert not np.array_equal(a.imu.accel_b, c.imu.accel_b)
