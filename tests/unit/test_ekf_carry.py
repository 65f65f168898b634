"""``ekf.carry.carried_heading`` against its closed form: the heading at t0 is the forward
pass's, turned by the reset Δ and the smoother's correction δ_s at the acquisition, plus the
down-axis gyro-bias correction integrated over [t0, t_h]; its variance is the smoothed yaw's
at t_h plus (σ_bD (t_h − t0))² from the smoothed bias covariance, not the bias prior."""

from __future__ import annotations

import numpy as np
import pytest

from vnav_graph.estimators.ekf.carry import CARRY_SD_MAX, carried_heading, rerun_config
from vnav_graph.estimators.ekf.settings import EkfConfig
from vnav_graph.geo.frames import rph_to_quat
from vnav_graph.types import Estimate, Trajectory


def _case(db_z: float, sd_bz: float, sd_yaw: float, level: bool = True):
    """A 20 s run at 10 Hz, heading acquired at t_h = 12 s by a reset of Δ = 1.0 rad;
    the smoother's gyro z bias exceeds the forward pass's by ``db_z`` [rad/s] everywhere."""
    t = np.arange(0.0, 20.0 + 1e-9, 0.1)
    n = t.size
    yaw_f = 0.3 + 0.01 * t  # forward yaw: turning slowly
    k_h = 120
    yaw_f[k_h:] += 1.0  # the reset
    roll = 0.0 if level else np.radians(20.0)
    q_f = rph_to_quat(np.column_stack([np.full(n, roll), np.zeros(n), yaw_f]))
    q_s = rph_to_quat(np.column_stack([np.full(n, roll), np.zeros(n), yaw_f + 0.05]))
    bg_f = np.zeros((n, 3))
    bg_s = np.tile([0.0, 0.0, db_z], (n, 1))
    reset_at = np.full(n, np.nan)
    reset_at[k_h] = 1.0
    cov = np.zeros((n, 18, 18))
    cov[:, 8, 8] = sd_yaw**2
    cov[:, 9:12, 9:12] = np.diag([1e-6, 1e-6, sd_bz**2])
    tr = Trajectory(t, np.zeros((n, 3)), np.zeros((n, 3)), q_s, bg_s, np.zeros((n, 3)))
    est = Estimate(estimator="ekf-rts", trajectory=tr, provides=frozenset(), cov=cov, t_cov=t)
    return t, reset_at, q_f, bg_f, est


def test_heading_at_t0_adds_the_integrated_bias_correction() -> None:
    db_z, sd_bz, sd_yaw = 0.002, 1e-4, 0.01
    t, reset_at, q_f, bg_f, est = _case(db_z, sd_bz, sd_yaw)
    ch = carried_heading(t, reset_at, t, q_f, bg_f, est)
    assert ch is not None and ch.t_acquired == pytest.approx(12.0)
    # ψ_f(t0) + Δ + δ_s + ∫ db_z dt = 0.3 + 1.0 + 0.05 + 0.002·12
    assert ch.yaw0 == pytest.approx(0.3 + 1.0 + 0.05 + db_z * 12.0, abs=1e-9)
    assert ch.sd == pytest.approx(np.hypot(sd_yaw, sd_bz * 12.0), rel=1e-9)
    # no bias correction: the same heading without the integral (the check can fail)
    ch0 = carried_heading(t, reset_at, t, q_f, bg_f, _case(0.0, sd_bz, sd_yaw)[4])
    assert ch.yaw0 - ch0.yaw0 == pytest.approx(0.024, abs=1e-9)


def test_a_tilted_body_projects_the_bias_on_the_down_axis() -> None:
    db_z, sd_bz, sd_yaw = 0.002, 1e-4, 0.01
    t, reset_at, q_f, bg_f, est = _case(db_z, sd_bz, sd_yaw, level=False)
    ch = carried_heading(t, reset_at, t, q_f, bg_f, est)
    c = np.cos(np.radians(20.0))  # body z against the down axis at 20° of roll
    assert ch.yaw0 == pytest.approx(0.3 + 1.0 + 0.05 + c * db_z * 12.0, abs=1e-6)
    assert ch.sd == pytest.approx(np.hypot(sd_yaw, np.hypot(c * sd_bz, np.sin(
        np.radians(20.0)) * 1e-3) * 12.0), rel=1e-6)


def test_the_smoothed_bias_sigma_decides_whether_the_heading_is_carried() -> None:
    info = {"heading_source": "accel-matching", "heading_time_s": 12.0, "imu_gaps": []}
    cfg = EkfConfig()
    t, reset_at, q_f, bg_f, est = _case(0.0, np.radians(0.02), 0.01)
    redo = rerun_config(cfg, info, t, reset_at, t, q_f, bg_f, est)
    assert redo is not None
    assert redo[0].initial_heading == pytest.approx(1.35, abs=1e-9)
    assert redo[1]["heading_source"] == "accel-matching, carried back"
    # a smoothed bias known to 0.5 °/s only (the real-log prior): 6° over 12 s, not carried
    t, reset_at, q_f, bg_f, est = _case(0.0, np.radians(0.5), 0.01)
    assert np.radians(0.5) * 12.0 > CARRY_SD_MAX
    assert rerun_config(cfg, info, t, reset_at, t, q_f, bg_f, est) is None
