"""Coarse levelling: roll and pitch from the specific force of a vehicle at rest.

At rest the accelerometers measure f_b = −C_bn g_n, so (Groves, *Principles of GNSS,
Inertial and Multisensor Integrated Navigation Systems*, 2nd ed., eq. 5.101)
φ = atan2(−f_y, −f_z), θ = atan2(f_x, √(f_y² + f_z²)); yaw is unobservable from gravity.
Used by the EKF's alignment, the vertical filters' AHRS and the graph's initial states.
"""

from __future__ import annotations

import numpy as np

from ..types.streams import FloatArray


def coarse_level(accel_mean_b: FloatArray) -> tuple[float, float]:
    """Roll and pitch [rad] from the mean specific force (3,) of a static window [m/s²]."""
    fx, fy, fz = (float(v) for v in accel_mean_b)
    return float(np.arctan2(-fy, -fz)), float(np.arctan2(fx, np.hypot(fy, fz)))
