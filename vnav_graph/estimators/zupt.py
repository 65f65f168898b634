"""The standstill of a drive as both estimator families see it: ``nav.standstill``'s detector
fed with the shared sensor model (``sensors.model``), so that the ekf's ZUPT updates and the
graph's zero-velocity priors come from one decision (``EkfConfig.zupt`` /
``GraphConfig.zupt``; reported as ``info["zupt_intervals"]``)."""

from __future__ import annotations

import numpy as np

from ..geo.frames import lla_to_ned
from ..nav.standstill import Standstill, detect_standstill, no_standstill, position_velocity
from ..sensors.model import SensorModel
from ..types import Drive


def drive_standstill(drive: Drive, model: SensorModel) -> Standstill:
    """The detector on ``drive``: per-sample σ = density·√rate of the model's IMU noise; GNSS
    velocity and its model σ where the drive has them, else velocities from the GNSS
    positions; no standstill without GNSS (``nav.standstill`` docstring)."""
    imu = drive.imu
    spec = model.imu
    rate = float(imu.rate_hz)
    sd_a = float(spec.accel_noise_density * np.sqrt(rate))
    sd_g = float(spec.gyro_noise_density * np.sqrt(rate))
    gn = drive.gnss
    if gn is None or len(gn) == 0 or model.gnss_pos_sd is None:
        return no_standstill(imu.t)
    if gn.vel_n is not None and model.gnss_vel_sd is not None:
        return detect_standstill(imu.t, imu.accel_b, imu.gyro_b, sd_a, sd_g, gn.t,
                                 gn.vel_n, model.gnss_vel_sd)
    tv, vel, sd = position_velocity(gn.t, lla_to_ned(gn.lla, drive.origin_lla),
                                    model.gnss_pos_sd)
    return detect_standstill(imu.t, imu.accel_b, imu.gyro_b, sd_a, sd_g, tv, vel, sd,
                             mean_test=False)
