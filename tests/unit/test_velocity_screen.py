"""The attitude-free GNSS velocity screen (``nav.velocity_screen``): closed form of the
specific-force integral, invariance to the IMU's mounting, faults refused, clean fixes kept."""

from __future__ import annotations

import dataclasses

import numpy as np

from vnav_graph.estimators.graph import GraphConfig
from vnav_graph.estimators.graph.model.problem import setup
from vnav_graph.nav.rotations import so3_exp
from vnav_graph.nav.velocity_screen import specific_force_integral, velocity_screen
from vnav_graph.sensors.model import accel_scale_sd, sensor_model
from vnav_graph.simulation.scenario import simulate

G = 9.80665


def test_specific_force_integral_matches_closed_form_of_a_turn():
    # body x specific force a while the body turns at ω about z: S(t) = a/ω (sin ωt, 1 − cos ωt, 0)
    dt, a, w = 1e-4, 2.0, 0.5
    t = np.arange(0.0, 4.0 + dt / 2, dt)
    gyro = np.tile([0.0, 0.0, w], (t.size, 1))
    accel = np.tile([a, 0.0, 0.0], (t.size, 1))
    tq = np.array([0.5, 1.23456, 3.9])
    s, seg = specific_force_integral(t, gyro, accel, tq, 1.0)
    exact = a / w * np.column_stack([np.sin(w * tq), 1 - np.cos(w * tq), np.zeros(3)])
    np.testing.assert_allclose(s, exact, atol=2e-4)  # rectangle rule: O(a·dt) per second
    assert np.all(seg == 0)


def test_specific_force_integral_splits_at_an_imu_gap():
    t = np.r_[np.arange(0.0, 1.0, 0.01), np.arange(3.0, 4.0, 0.01)]
    z = np.zeros((t.size, 3))
    s, seg = specific_force_integral(t, z, z + 1.0, np.array([0.5, 2.0, 3.5, 5.0]), 0.05)
    assert list(seg) == [0, -1, 1, -1]
    assert np.isfinite(s[[0, 2]]).all() and np.isnan(s[[1, 3]]).all()


def _screen(drive, vel=None, accel=None, gyro=None):
    m, g = sensor_model(drive), drive.gnss
    imu = drive.imu
    return velocity_screen(g.t, g.vel_n if vel is None else vel, m.gnss_vel_sd, imu.t,
                           imu.gyro_b if gyro is None else gyro,
                           imu.accel_b if accel is None else accel, G, m.imu.accel_bias_sd,
                           accel_scale_sd(m), m.imu.accel_noise_density, 0.9999)


def test_screen_keeps_clean_fixes_refuses_a_velocity_fault_and_ignores_the_mounting():
    d = simulate("hill-drive", 0, duration_s=120.0)
    keep = _screen(d)
    assert (~keep).sum() <= 2  # χ²₁ at 0.9999 over 1 200 fixes: 0.1 expected
    # the IMU mounted turned by 40° about a tilted axis: the screen needs no attitude
    r = so3_exp(np.radians(40.0) * np.array([0.3, -0.5, 0.81]) / np.linalg.norm([0.3, -0.5, 0.81]))
    np.testing.assert_array_equal(
        _screen(d, accel=d.imu.accel_b @ r.T, gyro=d.imu.gyro_b @ r.T), keep)
    # receiver faults: 15 m/s east on 10 consecutive fixes (1 s at 10 Hz), and a short
    # 3 m/s step (3 fixes); the sensitivity to a horizontal error δ against a fix Δt
    # earlier is ≈ δ²/(2gΔt), so a small step is caught while it is short
    for bad, dv in ((np.arange(600, 610), 15.0), (np.arange(800, 803), 3.0)):
        vel = d.gnss.vel_n.copy()
        vel[bad, 1] += dv
        keep_f = _screen(d, vel=vel)
        assert not keep_f[bad].any()
        # the fixes around the fault stay (those refused anyway when clean excepted)
        near = np.r_[bad[0] - 10:bad[0], bad[-1] + 1:bad[-1] + 21]
        assert keep_f[near].sum() >= keep[near].sum() - 1


def test_graph_pregate_drops_the_faulty_fixes_only_with_the_screen_on():
    d = simulate("hill-drive", 0, duration_s=60.0)
    g = d.gnss
    vel = g.vel_n.copy()
    vel[300:305, 0] -= 15.0
    d = d.replace(gnss=dataclasses.replace(g, vel_n=vel))
    p_on = setup(d, GraphConfig())
    p_off = setup(d, GraphConfig(velocity_screen=False))
    on, off = p_on.g_use, p_off.g_use
    assert not on[300:305].any() and off[300:305].all()
    assert (off & ~on).sum() <= 7
    # counted apart (info["gnss_rejected_velocity_screen"]) and inside the pre-gate's count
    assert p_on.g_rej_vel >= 5 and p_off.g_rej_vel == 0
    assert p_on.g_rej_pre - p_off.g_rej_pre == (off & ~on).sum()
