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
- ``track_heading`` — course over ground of each GNSS fix from its velocity (or, when the
  receiver gives no velocity, from the chord of the last 2 s of positions brought forward by
  the gyro), with a one-sigma heading uncertainty. Heading = track assumes no sideslip (car,
  coordinated flight, no wind): the in-flight alignment of seed 004 §5.4.

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


# half the baseline of a position-only course: the chord over 2 s [s]
POS_ONLY_BASE_S = 1.0
# a course counts only when the speed exceeds this many σ of its velocity noise
TRACK_SNR = 5.0


@dataclass(frozen=True)
class Track:
    """Per-fix course over ground: yaw [rad], horizontal speed [m/s], yaw one-sigma [rad]."""

    yaw: FloatArray
    speed: FloatArray
    yaw_sd: FloatArray


def track_heading(gnss: GnssStream, sideslip_sd: float, imu: ImuStream | None = None,
                  base_s: float = POS_ONLY_BASE_S) -> Track:
    """Course over ground of every fix, shape (N,), from data up to the fix (causal).

    With velocity: ψ = atan2(v_E, v_N), σ_ψ² = σ_v²/|v_h|² + σ_β² (σ_β = ``sideslip_sd``
    allows for sideslip/crab). Without velocity: the chord from the position ``2·base_s``
    earlier to the fix (interpolated between fixes) gives the course at ``t − base_s`` with a
    cross-track velocity σ of σ_pos/(√2·base_s); the heading turned since then, integrated
    from the gyro z axis (``imu``; level vehicle), brings it to the fix time. Neighbouring-fix
    differences (0.1 s at 10 Hz, σ_v ≈ 7 m/s at 1 m noise) gave a course from noise at
    standstill, which the EKF took as its heading (hill-drive without GNSS velocity: 1,400 to
    2,700 of 5,400 fixes then rejected, 40–180 m horizontal RMSE). Fixes without 2·base_s of
    history, or slower than ``TRACK_SNR`` σ of their velocity noise, get σ = π.
    """
    if gnss.vel_n is not None and gnss.vel_sd is not None:
        v = gnss.vel_n[:, :2]
        vsd = np.hypot(gnss.vel_sd[:, 0], gnss.vel_sd[:, 1]) / np.sqrt(2.0)
        turn = np.zeros(gnss.t.size)
        valid = np.ones(gnss.t.size, dtype=bool)
    else:
        lat, lon = gnss.lla[:, 0], gnss.lla[:, 1]
        rn, re = radii(lat)
        # relative to the first fix: lat·(R + h) would leak the height noise (σ_v 2 m ×
        # 0.8 rad) into "north"
        north = (lat - lat[0]) * (rn + gnss.lla[:, 2])
        east = (lon - lon[0]) * (re + gnss.lla[:, 2]) * np.cos(lat)
        if gnss.t.size < 3:
            z = np.zeros(gnss.t.size)
            return Track(z, z, np.full(gnss.t.size, np.pi))
        t0 = gnss.t - 2.0 * base_s
        valid = t0 >= gnss.t[0]
        v = np.column_stack([north - np.interp(t0, gnss.t, north),
                             east - np.interp(t0, gnss.t, east)]) / (2.0 * base_s)
        sd_p = np.hypot(gnss.pos_sd[:, 0], gnss.pos_sd[:, 1]) / np.sqrt(2.0)
        vsd = sd_p / (np.sqrt(2.0) * base_s)
        turn = np.zeros(gnss.t.size)
        if imu is not None and imu.t.size > 1:
            yaw_int = np.concatenate([[0.0], np.cumsum(
                0.5 * (imu.gyro_b[1:, 2] + imu.gyro_b[:-1, 2]) * np.diff(imu.t))])
            turn = np.interp(gnss.t, imu.t, yaw_int) - np.interp(gnss.t - base_s, imu.t,
                                                                 yaw_int)
    speed = np.hypot(v[:, 0], v[:, 1])
    yaw = np.arctan2(v[:, 1], v[:, 0]) + turn
    yaw = np.arctan2(np.sin(yaw), np.cos(yaw))
    with np.errstate(divide="ignore"):
        sd = np.sqrt((vsd / np.maximum(speed, 1e-9)) ** 2 + sideslip_sd**2)
    # a speed within TRACK_SNR σ of zero can be noise alone (P = exp(−k²/2) per fix: a
    # standstill read as a 3 m/s course, seen at 6.9 s of a 20 s standstill): no course
    sd = np.where(valid & (speed > TRACK_SNR * vsd), sd, np.pi)
    return Track(yaw, speed, np.minimum(sd, np.pi))
