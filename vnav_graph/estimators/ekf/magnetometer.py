"""The EKF's magnetometer set-up (the measurement model is ``sensors.magnetometer``).

- :func:`initial_heading`: compass alignment over the levelling window;
- :func:`one_per_interval`: the samples the filter uses (the errors are correlated over
  seconds, so at most one heading per ``mag_interval_s``).

The filter's magnetometer record, heading row and update are in ``ekf.updates``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ...geo.frames import quat_to_mat, rph_to_quat
from ...sensors.magnetometer import MIN_HORIZONTAL_UT, wrap_pi
from ...types import Drive
from ...types.streams import FloatArray


def initial_heading(drive: Drive, t_end: float, roll: float, pitch: float, fm: Any,
                    floor: float, bias_sd: float) -> tuple[float, float] | None:
    """Initial heading [rad] and its σ from the magnetometer samples up to ``t_end`` (the
    levelling window; at least the first sample) with the levelled roll and pitch: the
    field's azimuth is yaw + that of the levelled field, and must equal the declination of
    the field reference ``fm``. σ² = floor² + (σ_m²/N + 2 σ_b²)/H² (noise, the two
    horizontal hard-iron components of prior σ ``bias_sd`` [µT]). None without a sample
    near the start or with a horizontal field below ``MIN_HORIZONTAL_UT``."""
    mag = drive.mag
    assert mag is not None
    t0 = drive.imu.t[0]
    sel = (mag.t >= t0) & (mag.t <= max(t_end, t0))
    if not sel.any():
        j = int(np.searchsorted(mag.t, t0))
        if j >= mag.t.size or mag.t[j] - t0 > 1.0:
            return None
        sel = np.zeros(mag.t.size, bool)
        sel[j] = True
    c_tilt = quat_to_mat(rph_to_quat([roll, pitch, 0.0])[0])
    m_h = c_tilt @ mag.field_b[sel].mean(axis=0)
    hor = float(np.hypot(m_h[0], m_h[1]))
    if hor < MIN_HORIZONTAL_UT:
        return None
    yaw = float(wrap_pi(fm.declination_rad - np.arctan2(m_h[1], m_h[0])))
    var = floor**2 + (mag.sd_ut**2 / sel.sum() + 2.0 * bias_sd**2) / hor**2
    return yaw, float(np.sqrt(var))


def one_per_interval(t: FloatArray, interval_s: float) -> np.ndarray:
    """Indices of the magnetometer samples used: the first of every ``interval_s``."""
    slot = np.floor((t - t[0]) / interval_s).astype(np.int64)
    return np.flatnonzero(np.r_[True, np.diff(slot) > 0])
