"""Heading acquisition of ``ekf`` when course over ground ≠ heading (multicopter, crab).

The IMU of a simulated hill-drive is turned by 90° about its z axis (mounted sideways), so the
body heading is the course + 90° while the GNSS track is unchanged: the no-sideslip track
heading is wrong by 90°, the acceleration matching of ``ekf_model`` (GNSS velocity increments
against the specific-force integral) is not affected by it.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.spatial.transform import Rotation

from vnav_graph.estimators.ekf.filter import EKF, EkfConfig
from vnav_graph.simulation.scenario import simulate


def _yaw(q):
    return Rotation.from_quat(q, scalar_first=True).as_euler("ZYX")[:, 0]


def _sideways_drive(seed: int):
    d = simulate("hill-drive", seed, duration_s=120.0)
    a = 0.5 * np.pi
    m = Rotation.from_euler("z", a).as_matrix().T  # b -> b' with C_nb' = C_nb R_z(a)
    imu = replace(d.imu, gyro_b=d.imu.gyro_b @ m.T, accel_b=d.imu.accel_b @ m.T)
    gnss = replace(d.gnss, lever_arm_b=m @ np.asarray(d.gnss.lever_arm_b, float))
    q_true = (Rotation.from_quat(d.truth.q_nb, scalar_first=True)
              * Rotation.from_euler("z", a)).as_quat(scalar_first=True)
    return d.replace(imu=imu, gnss=gnss), d.truth.t, q_true


def test_heading_from_acceleration_matching_ignores_sideslip() -> None:
    drive, t_true, q_true = _sideways_drive(3)
    est = EKF().run(drive)
    assert est.info["heading_source"] == "accel-matching"
    th = est.info["heading_time_s"]
    assert th is not None and th < 60.0  # the drive accelerates within the first minute
    tr = est.trajectory
    k = tr.t > th + 5.0
    dy = _yaw(tr.q_nb[k]) - np.interp(tr.t[k], t_true, np.unwrap(_yaw(q_true)))
    dy = np.angle(np.exp(1j * dy))
    # measured 0.3° (seed 3) / 0.5° (seed 5) rms; 5°: the alignment accepts σ_δ ≤ 15° and the
    # filter refines it, 5° is still 18× below the 90° error the track heading gives
    assert np.sqrt(np.mean(dy**2)) < np.radians(5.0)
    # the no-sideslip track heading starts 90° off on the same data (the failure mode)
    trk = EKF(EkfConfig(heading_source="track")).run(drive)
    j = int(np.searchsorted(trk.trajectory.t, trk.info["heading_time_s"] + 0.5))
    d0 = _yaw(trk.trajectory.q_nb[j:j + 1])[0] - np.interp(
        trk.trajectory.t[j], t_true, np.unwrap(_yaw(q_true)))
    assert abs(np.angle(np.exp(1j * d0))) > np.radians(60.0)
