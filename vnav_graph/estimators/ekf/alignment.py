"""Initial alignment for the INS/GNSS EKF: coarse levelling and heading from GNSS track.

Contents
--------
- coarse levelling (roll and pitch from the mean specific force of a static window) is
  ``vnav_graph.nav.levelling.coarse_level``, shared with the AHRS and the graph.
- ``level_tilt_bias_jacobian`` — the linear relation between the residual tilt of that
  levelling and the accelerometer-bias error, used to correlate the initial covariance
  (the classic tilt/horizontal-accel-bias ambiguity: levelling nulls the *sum* of both).
- ``static_window_end`` — end of the initial static period (simulated drives stand still
  for about 20 s; real logs may not).
- ``track_heading`` — course over ground of each GNSS fix from its velocity (or from central
  differences of positions when the receiver gives no velocity), with a one-sigma heading
  uncertainty. Heading = track assumes no sideslip (car, coordinated flight, no wind): the
  in-flight alignment of seed 004 §5.4.

Angles in radians, NED navigation frame, FRD body frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...geo.earth import radii
from ...types import FloatArray, GnssStream, ImuStream


def static_window_end(imu: ImuStream, max_s: float, min_s: float = 0.5,
                      gyro_thresh: float = 0.05, accel_thresh: float = 0.5) -> int:
    """Index (exclusive) of the end of the initial static window, at most ``max_s`` long.

    The window stops at the first sample whose gyro magnitude exceeds ``gyro_thresh`` [rad/s]
    or whose specific-force magnitude departs from the window's first-second median by more
    than ``accel_thresh`` [m/s²]; it is at least ``min_s`` long (a moving start then gives a
    coarse levelling from the first ``min_s`` seconds only).
    """
    t = imu.t
    n_max = int(np.searchsorted(t, t[0] + max_s, side="right"))
    n_min = max(2, int(np.searchsorted(t, t[0] + min_s, side="right")))
    g_ref = float(np.median(np.linalg.norm(imu.accel_b[:n_min], axis=1)))
    moving = (np.linalg.norm(imu.gyro_b[:n_max], axis=1) > gyro_thresh) | (
        np.abs(np.linalg.norm(imu.accel_b[:n_max], axis=1) - g_ref) > accel_thresh)
    idx = np.flatnonzero(moving[n_min:])
    return int(n_min + idx[0]) if idx.size else n_max


def level_tilt_bias_jacobian(mat_nb: FloatArray, g: float) -> FloatArray:
    """M (3, 3) with ψ ≈ M δb_a for the tilt error ψ (n, estimated minus true) left by
    levelling with an accelerometer-bias error δb_a (b, estimated minus true).

    Levelling makes C̃ f̃ vertical; with C̃ = (I + [ψ×]) C and f̃ = f + b_a = f − δb_a (the
    bias is not removed yet) the horizontal part of ψ × f_n − C δb_a vanishes, f_n = (0,0,−g):
    −g ψ_E − (C δb_a)_N = 0 and g ψ_N − (C δb_a)_E = 0. Heading error is unaffected.
    """
    c = np.asarray(mat_nb, dtype=float)
    m = np.zeros((3, 3))
    m[0] = c[1] / g
    m[1] = -c[0] / g
    return m


@dataclass(frozen=True)
class Track:
    """Per-fix course over ground: yaw [rad], horizontal speed [m/s], yaw one-sigma [rad]."""

    yaw: FloatArray
    speed: FloatArray
    yaw_sd: FloatArray


def track_heading(gnss: GnssStream, sideslip_sd: float) -> Track:
    """Course over ground of every fix, shape (N,).

    With velocity: ψ = atan2(v_E, v_N), σ_ψ² = σ_v²/|v_h|² + σ_β² (σ_β = ``sideslip_sd``
    allows for sideslip/crab). Without velocity: central differences of positions over
    neighbouring fixes, σ_v = √2·σ_pos/Δt.
    """
    if gnss.vel_n is not None and gnss.vel_sd is not None:
        v = gnss.vel_n[:, :2]
        vsd = np.hypot(gnss.vel_sd[:, 0], gnss.vel_sd[:, 1]) / np.sqrt(2.0)
    else:
        lat, lon = gnss.lla[:, 0], gnss.lla[:, 1]
        rn, re = radii(lat)
        north = lat * (rn + gnss.lla[:, 2])
        east = lon * (re + gnss.lla[:, 2]) * np.cos(lat)
        if gnss.t.size < 3:
            z = np.zeros(gnss.t.size)
            return Track(z, z, np.full(gnss.t.size, np.pi))
        v = np.column_stack([np.gradient(north, gnss.t), np.gradient(east, gnss.t)])
        dt = np.gradient(gnss.t)
        vsd = np.sqrt(2.0) * np.hypot(gnss.pos_sd[:, 0], gnss.pos_sd[:, 1]) / np.sqrt(2.0) / (
            2.0 * dt)
    speed = np.hypot(v[:, 0], v[:, 1])
    yaw = np.arctan2(v[:, 1], v[:, 0])
    with np.errstate(divide="ignore"):
        sd = np.sqrt((vsd / np.maximum(speed, 1e-9)) ** 2 + sideslip_sd**2)
    return Track(yaw, speed, np.minimum(sd, np.pi))
