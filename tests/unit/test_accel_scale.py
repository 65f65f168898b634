"""The accelerometer scale factors of the graph smoothers (``problem.AccelScale``,
``builders.bias_link``) and the rule every estimator shares (``sensors.model.accel_scale_sd``):
closed forms for the interval mean force, the effective bias and the bias link's residual."""

from __future__ import annotations

from dataclasses import replace

import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import A, B

from vnav_graph.config import IMU_PRESETS
from vnav_graph.estimators.graph import GraphConfig
from vnav_graph.estimators.graph.model import cpp_factors as gb
from vnav_graph.estimators.graph.model import problem as gp
from vnav_graph.sensors.model import MIN_INFERRED_ACCEL_SCALE_SD, accel_scale_sd, sensor_model
from vnav_graph.simulation.scenario import load_scenario, simulate


@pytest.fixture(scope="module")
def P():
    return gp.setup(simulate(load_scenario("hill-drive", duration_s=30.0), seed=0), GraphConfig())


def test_the_rule_real_log_simulated_and_forced():
    drive = simulate(load_scenario("hill-drive", duration_s=10.0), seed=0)
    m = sensor_model(drive)
    assert accel_scale_sd(m) == m.imu.accel_scale_sd > 0  # the spec's σ
    assert accel_scale_sd(m, False) == 0.0
    zero = replace(m, imu=replace(m.imu, accel_scale_sd=0.0))
    assert accel_scale_sd(zero) == 0.0  # no scale error in the spec: not carried
    real = replace(zero, imu_inferred=True)
    assert accel_scale_sd(real) == MIN_INFERRED_ACCEL_SCALE_SD  # a real log: carried, floored


def test_interval_mean_force_closed_form():
    """ā_k is the time average of the midpoint samples; a gap interval takes its
    predecessor's, the last keyframe its interval's."""
    t = np.r_[0.0, 0.5, 1.0, 1.5, 2.0, 12.0, 12.5, 13.0]
    acc = np.zeros((t.size, 3))
    acc[:, 0] = np.r_[0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0]
    kf = np.array([0, 2, 4, 5, 7])
    gap = np.array([False, False, True, False])
    f = gp.interval_mean_force(t, acc, kf, gap)
    np.testing.assert_allclose(f[:, 0], [1.0, 3.0, 3.0, 6.0, 6.0])


def test_true_bias_removes_the_scale_term(P):
    assert P.ka is not None and P.ka.sd == IMU_PRESETS[P.imu_spec.name].accel_scale_sd
    ka = np.array([1e-3, -2e-3, 5e-4])
    k = np.arange(4)
    b_a = np.array([[0.01, 0.02, -0.03]] * 4)
    eff = b_a + P.ka.f_mean[k] * ka
    np.testing.assert_allclose(P.ka.true_bias(eff, ka, k), b_a, atol=1e-15)


def _values(b0, b1, keys_a):
    v = gtsam.Values()
    v.insert(B(5), gtsam.imuBias.ConstantBias(b0[:3], b0[3:]))
    v.insert(B(6), gtsam.imuBias.ConstantBias(b1[:3], b1[3:]))
    for key, a in keys_a:
        v.insert(key, a)
    return v


def _gm_step(spec, dt):
    """φ and var w of the IMU biases' Gauss-Markov step, written here from the spec: φ =
    exp(−Δt/τ), var w = σ²(1 − exp(−2Δt/τ)) + rw²·Δt (accel ×3, gyro ×3)."""
    phi, var = [], []
    for sd, tau, rw in ((spec.accel_bias_sd, spec.accel_bias_tau, spec.accel_bias_rw),
                        (spec.gyro_bias_sd, spec.gyro_bias_tau, spec.gyro_bias_rw)):
        phi += [np.exp(-dt / tau)] * 3
        var += [sd**2 * (1 - np.exp(-2 * dt / tau)) + rw**2 * dt] * 3
    return np.array(phi), np.array(var)


def test_bias_link_is_the_gauss_markov_step_of_the_effective_bias(P):
    """½‖r‖²_Σ with r = B(k+1) − φ·B(k) − [diag(ā_k+1)·k_a' − φ_a·diag(ā_k)·k_a; 0], i.e.
    b(k+1) − φ·b(k) for the true biases b = B − [diag(ā)·k_a; 0], Σ = var w of the ekf's
    discretisation: the 3-key link (one A) and the 4-key link across a segment boundary
    (A(0), A(1))."""
    rng = np.random.default_rng(1)
    a0, a1 = 1e-2 * rng.normal(size=3), 1e-2 * rng.normal(size=3)
    f0, f1 = P.ka.f_mean[5], P.ka.f_mean[6]
    phi, q = _gm_step(P.imu_spec, 0.7)
    assert np.all(phi < 1.0)  # a finite τ: the decay is tested, not only the walk
    # B(k+1) as the model with (k_a, k_a') = (a0, a1) predicts it, plus 1σ of noise
    b0 = 1e-2 * rng.normal(size=6)
    b1 = phi * b0 + np.sqrt(q) * rng.normal(size=6)
    b1[:3] += f1 * a1 - phi[:3] * f0 * a0

    def closed(a_k, a_k1):
        r = b1 - phi * b0
        r[:3] -= f1 * a_k1 - phi[:3] * f0 * a_k
        return 0.5 * float(np.sum(r**2 / q))

    e3 = gb.bias_link(P, 5, 0.7).error(_values(b0, b1, [(A(0), a0)]))
    assert e3 == pytest.approx(closed(a0, a0), rel=1e-12)
    e4 = gb.bias_link(P, 5, 0.7, (A(0), A(1))).error(_values(b0, b1, [(A(0), a0), (A(1), a1)]))
    # the 4-key form carries 1e-9 information per component (positive definite for QR)
    assert e4 == pytest.approx(closed(a0, a1), rel=1e-9)
    assert closed(a0, a0) > 10 * closed(a0, a1)  # the scale terms matter here: it can fail


def test_without_the_scale_factors_the_link_is_the_plain_gauss_markov_step():
    drive = simulate(load_scenario("hill-drive", duration_s=10.0), seed=0)
    P0 = gp.setup(drive, GraphConfig(accel_scale=False))
    assert P0.ka is None
    rng = np.random.default_rng(2)
    b0, b1 = 1e-2 * rng.normal(size=6), 1e-2 * rng.normal(size=6)
    phi, q = _gm_step(P0.imu_spec, 1.0)
    e = gb.bias_link(P0, 5, 1.0).error(_values(b0, b1, []))
    assert e == pytest.approx(0.5 * float(np.sum((b1 - phi * b0) ** 2 / q)), rel=1e-12)
    # a random-constant bias (τ = inf) is a pure random walk of rw²·Δt
    spec = P0.imu_spec
    rc = replace(spec, accel_bias_tau=np.inf, gyro_bias_tau=np.inf)
    e_rc = gb.bias_link(replace(P0, imu_spec=rc), 5, 1.0).error(_values(b0, b1, []))
    q_rc = np.r_[[spec.accel_bias_rw**2] * 3, [spec.gyro_bias_rw**2] * 3]
    assert e_rc == pytest.approx(0.5 * float(np.sum((b1 - b0) ** 2 / q_rc)), rel=1e-12)
