"""The EKF's backward drive (``ekf.backward.reversed_drive``): strapdown of a noiseless drive
played backward, from the truth's last state, retraces the truth (the Earth-rate and Coriolis
terms of the reversal checked against the simulator); and ``fb_separation`` reaches the
summary block of ekf-rts only."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from vnav_graph.config import IMU_PRESETS
from vnav_graph.estimators.ekf import backward
from vnav_graph.estimators.ekf.filter import EKF, EKFRTS, EkfConfig
from vnav_graph.evaluation.metrics import evaluate
from vnav_graph.geo.frames import lla_to_ned
from vnav_graph.nav.strapdown import NavState, integrate
from vnav_graph.simulation import simulate


def _backward_error(d, turn_terms=True):
    tr = d.truth
    rev = backward.reversed_drive(d, tr, 0.0)
    if not turn_terms:  # the plain reversal, without the Earth-rate and Coriolis terms
        imu = rev.imu
        rev = rev.replace(imu=type(imu)(imu.t, (-d.imu.gyro_b * backward.TURN)[::-1],
                                        (d.imu.accel_b * backward.TURN)[::-1], imu.spec))
    # the backward body frame is turned 180° about z: q' = q ⊗ R_z(π)
    q_end = (Rotation.from_quat(tr.q_nb[-1], scalar_first=True)
             * Rotation.from_rotvec([0.0, 0.0, np.pi])).as_quat(scalar_first=True)
    est = integrate(rev.imu, NavState(tr.lla[-1], -tr.vel_n[-1], q_end))
    pos = lla_to_ned(est.lla[::-1], d.origin_lla) - lla_to_ned(tr.lla, d.origin_lla)
    return np.linalg.norm(pos, axis=1)


def test_reversed_noiseless_drive_retraces_the_truth():
    d = simulate("hill-drive", 1, duration_s=60.0, imu=IMU_PRESETS["consumer"].noiseless())
    err = _backward_error(d)
    # forward strapdown of the same drive: 0.05 mm after 60 s (test_roundtrip); the backward
    # terms use the truth's attitude and velocity, so only integration error remains
    # (measured 0.16 mm)
    assert err.max() < 1e-3
    # without the Earth-rate and Coriolis terms the same integration is 38 m off
    assert _backward_error(d, turn_terms=False).max() > 1.0


def test_fb_separation_in_the_summary_block():
    d = simulate("hill-drive", 3, duration_s=90.0)
    cfg = EkfConfig(carry_heading_back=False)
    sm, fw = evaluate(EKFRTS(cfg).run(d), d), evaluate(EKF(cfg).run(d), d)
    assert fw["fb_separation"] is None
    sep = sm["fb_separation"]
    assert set(sep) == {"alt_p95_m", "horiz_p95_m"}
    assert 0.0 < sep["alt_p95_m"] < 5.0 and 0.0 < sep["horiz_p95_m"] < 50.0
