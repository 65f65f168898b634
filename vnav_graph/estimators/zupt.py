"""The standstill of a drive as both estimator families see it: ``nav.standstill``'s detector
fed with the shared sensor model (``sensors.model``), so that the ekf's ZUPT updates and the
graph's zero-velocity priors come from one decision (``EkfConfig.zupt`` /
``GraphConfig.zupt``; reported as ``info["zupt_intervals"]``)."""

from __future__ import annotations

import numpy as np

from ..geo.earth import gravity
from ..nav.standstill import Standstill, detect_standstill
from ..sensors.model import SensorModel
from ..types import Drive


def drive_standstill(drive: Drive, model: SensorModel) -> Standstill:
    """The detector on ``drive``: per-sample σ = density·√rate of the model's IMU noise, with
    its turn-on bias σ in quadrature; g the normal gravity at the origin; GNSS velocity and
    its model σ where the drive has them (``nav.standstill`` docstring)."""
    imu = drive.imu
    spec = model.imu
    rate = float(imu.rate_hz)
    sd_a = float(np.hypot(spec.accel_noise_density * np.sqrt(rate), spec.accel_bias_sd))
    sd_g = float(np.hypot(spec.gyro_noise_density * np.sqrt(rate), spec.gyro_bias_sd))
    g = float(gravity(drive.origin_lla[0], drive.origin_lla[2]))
    gn = drive.gnss
    has_vel = gn is not None and gn.vel_n is not None and model.gnss_vel_sd is not None
    return detect_standstill(imu.t, imu.accel_b, imu.gyro_b, sd_a, sd_g, g,
                             gn.t if has_vel else None, gn.vel_n if has_vel else None,
                             model.gnss_vel_sd if has_vel else None)
