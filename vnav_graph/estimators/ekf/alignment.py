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
- ``moving_start`` — in-motion levelling when GNSS shows the vehicle moving from the start:
  the vehicle's acceleration from GNSS is removed from the specific force before levelling.
- ``initial_state`` — the kernel's initial nominal state, covariance and parameters
  (``Alignment``): levelling over the static start (or in motion), position and velocity from
  the median of the first ``START_FIXES`` fixes, heading given, from the compass or unknown.
- ``track_heading`` — course over ground of each GNSS fix from its velocity (or, when the
  receiver gives no velocity, from the chord of the last 2 s of positions brought forward by
  the gyro), with a one-sigma heading uncertainty. Heading = track assumes no sideslip (car,
  coordinated flight, no wind): the in-flight alignment of seed 004 §5.4.

Angles in radians, NED navigation frame, FRD body frame.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ...config import BaroSpec
from ...geo.earth import gravity
from ...geo.frames import lla_to_ned, quat_to_mat, rph_to_quat
from ...nav.course import COURSE_SNR, course_heading, course_sd, gyro_yaw
from ...nav.levelling import coarse_level
from ...sensors.model import BaroPrior, SensorModel
from ...types import Drive
from ...types.streams import FloatArray, GnssStream, ImuStream
from . import model as km
from .magnetometer import initial_heading
from .settings import EkfConfig

# the initial position is the median of the first START_FIXES fixes, so the filter's
# estimate before the last of them is not causal (its online estimate starts there:
# info["online_from_s"], with the end of the levelling window)
START_FIXES = 9
# ``start_position``: a first fix whose step to the second exceeds the next step by this
# many σ is an outlier
START_OUTLIER = 5.0


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
TRACK_SNR = COURSE_SNR
# in-motion levelling (``moving_start``): window [s] and the floor of its acceleration σ
MOVING_LEVEL_S = 1.0
MOVING_ACCEL_SD_MIN = 0.2
# position-only motion test: the parabola is fitted over the first MOVING_FIT_S seconds, or
# longer until it holds MOVING_FIT_FIXES fixes (a 1 Hz receiver has 4 fixes in 4 s, too few)
MOVING_FIT_S = 4.0
MOVING_FIT_FIXES = 6


@dataclass(frozen=True)
class Track:
    """Per-fix course over ground: yaw [rad], horizontal speed [m/s], yaw one-sigma [rad]."""

    yaw: FloatArray
    speed: FloatArray
    yaw_sd: FloatArray


def track_heading(gnss: GnssStream, sideslip_sd: float, imu: ImuStream | None = None,
                  base_s: float = POS_ONLY_BASE_S) -> Track:
    """Course over ground of every fix, shape (N,), from data up to the fix (causal), as a
    heading with its σ by the rule of ``nav.course`` (σ_ψ² = σ_v²/|v_h|² + σ_β²; no course
    below ``COURSE_SNR`` σ_v of speed).

    With velocity: ψ = atan2(v_E, v_N), σ_β the larger of ``sideslip_sd`` and the scatter of
    course minus the gyro heading over the last ``SWAY_WINDOW_S`` (``nav.course.sway_sd``;
    with ``imu``). Without velocity: the chord from the position ``2·base_s`` earlier to the
    fix (interpolated between fixes) gives the course at ``t − base_s`` with a cross-track
    velocity σ of σ_pos/(√2·base_s); the heading turned since then, integrated from the gyro
    z axis (``imu``; level vehicle), brings it to the fix time. Neighbouring-fix differences
    (0.1 s at 10 Hz, σ_v ≈ 7 m/s at 1 m noise) gave a course from noise at standstill, which
    the EKF took as its heading (hill-drive without GNSS velocity: 1,400 to 2,700 of 5,400
    fixes then rejected, 40–180 m horizontal RMSE). Fixes without 2·base_s of history get
    σ = π.
    """
    if gnss.vel_n is not None and gnss.vel_sd is not None:
        vsd = np.hypot(gnss.vel_sd[:, 0], gnss.vel_sd[:, 1]) / np.sqrt(2.0)
        yaw_g = None
        if imu is not None:
            yaw_g = gyro_yaw(imu.t, imu.gyro_b[:, 2], gnss.t)
        c = course_heading(gnss.t, gnss.vel_n[:, :2], vsd, sideslip_sd, yaw_g)
        return Track(c.yaw, c.speed, c.yaw_sd)
    # tangent plane at the first fix (lat·(R + h), used before, leaked the height noise,
    # σ_v 2 m × 0.8 rad, into "north")
    north, east = lla_to_ned(gnss.lla, gnss.lla[0])[:, :2].T
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
        turn = gyro_yaw(imu.t, imu.gyro_b[:, 2], gnss.t) - gyro_yaw(
            imu.t, imu.gyro_b[:, 2], gnss.t - base_s)
    speed = np.hypot(v[:, 0], v[:, 1])
    yaw = np.arctan2(v[:, 1], v[:, 0]) + turn
    yaw = np.arctan2(np.sin(yaw), np.cos(yaw))
    # a speed within COURSE_SNR σ of zero can be noise alone (P = exp(−k²/2) per fix: a
    # standstill read as a 3 m/s course, seen at 6.9 s of a 20 s standstill): no course
    sd = np.where(valid, course_sd(speed, vsd, sideslip_sd), np.pi)
    return Track(yaw, speed, sd)


@dataclass(frozen=True)
class MovingStart:
    """Levelling window and vehicle acceleration when GNSS shows motion from the start."""

    i_end: int  # end (exclusive) of the levelling window, IMU samples
    accel_b: FloatArray  # (3,) acceleration of the vehicle in b to remove from f_b [m/s²]
    accel_sd: float  # one-sigma of that removal per axis [m/s²]
    accel_sd_y: float | None = None  # its lateral one-sigma when it differs [m/s²]


def moving_start(imu: ImuStream, gnss: GnssStream | None, i_static: int,
                 window_s: float = MOVING_LEVEL_S) -> MovingStart | None:
    """In-motion levelling (a vehicle that starts moving without a static period), or None
    when GNSS shows no motion during the IMU's static window ``[0, i_static)``.

    A car pulling away at 2 m/s² looks static to the IMU (|f| changes by a²/2g = 0.2 m/s²,
    the gyros are quiet), so the levelling took its acceleration for gravity: a 6.6° pitch
    error on cold-start seed 0, with which acceleration matching then locked the heading
    180° off and the EKF rejected 4,971 of 6,000 fixes. Here GNSS decides whether the
    vehicle moves. With GNSS velocity, the mean acceleration over the first ``window_s``
    seconds is the speed change across them (exact whatever the jerk), taken along body x,
    with the centripetal v·ω_z along body y (no sideslip: the assumption of
    ``track_heading``), and removed from the mean specific force of the window; σ from the
    velocity noise, at least 0.2 m/s² (1.2° of tilt). With positions alone (motion = a
    parabola through the distance from the first fix rising by > 3σ over 4 s) nothing is
    removed and σ covers the parabola's mean acceleration.
    """
    if gnss is None or gnss.t.size < 4:
        return None
    t = imu.t
    t0 = t[0]
    t_static = t[max(i_static - 1, 0)]
    has_vel = gnss.vel_n is not None and gnss.vel_sd is not None
    i_end = max(2, int(np.searchsorted(t, t0 + window_s, side="right")))
    t1 = t[i_end - 1]
    if has_vel:
        speed = np.hypot(gnss.vel_n[:, 0], gnss.vel_n[:, 1])
        v_sd = float(np.median(np.hypot(gnss.vel_sd[:, 0], gnss.vel_sd[:, 1])))
        m = (gnss.t >= t0) & (gnss.t <= t_static)
        if not np.any(m) or np.max(speed[m]) <= max(0.3, TRACK_SNR * v_sd):
            return None
        # the mean acceleration over the window is the velocity change across it (exact
        # whatever the jerk); the speed change is along the track = body x
        v0, v1 = np.interp(t0, gnss.t, speed), np.interp(t1, gnss.t, speed)
        a_along = float(v1 - v0) / (t1 - t0)
        v_mid = 0.5 * float(v0 + v1)
        a_sd = np.sqrt(2.0) * v_sd / (t1 - t0)
    else:
        # the distance from the first fix; moving when the fitted parabola's increase over
        # 4 s exceeds 3 σ of that increase (a standstill's noise gives none; P = 0.13 %)
        dist = np.hypot(*lla_to_ned(gnss.lla, gnss.lla[0])[:, :2].T)
        j0 = int(np.searchsorted(gnss.t, t0))
        t_fit = max(t0 + MOVING_FIT_S, gnss.t[min(j0 + MOVING_FIT_FIXES, gnss.t.size) - 1])
        fit_m = (gnss.t >= t0) & (gnss.t <= t_fit)
        if fit_m.sum() < MOVING_FIT_FIXES:
            return None
        tt = gnss.t[fit_m] - t0
        coef, cov = np.polyfit(tt, dist[fit_m], 2, cov=True)
        jd = np.array([tt[-1] ** 2 - tt[0] ** 2, tt[-1] - tt[0], 0.0])
        rise = float(jd @ coef)
        if rise <= 3.0 * float(np.sqrt(max(jd @ cov @ jd, 1e-12))):
            return None
        # positions alone cannot say how the acceleration is spread over the first second
        # (a car's rises from 0): nothing is removed, and the tilt σ covers the mean
        # acceleration of the 4 s (a parabola through a ramp: cold-start seed 3 removed
        # 2.0 m/s² where 0.3 was true, a 9.7° pitch error)
        a_along, v_mid = 0.0, 0.0
        a_sd = abs(2.0 * float(coef[0])) + 2.0 * float(np.sqrt(max(cov[0, 0], 0.0)))
        # laterally only the centripetal v·ω_z is unknown (no sideslip): v bounded by the
        # parabola's speed at the window's end + 2σ, ω_z measured. Seed 7 of
        # cold-start-phone: 0.2 instead of 2.7 m/s², so the roll (16° σ before) no longer
        # takes the lateral misfit of a 10° heading error at the acquisition
        jv = np.array([2.0 * (t1 - t0), 1.0, 0.0])
        v_max = abs(float(jv @ coef)) + 2.0 * float(np.sqrt(max(jv @ cov @ jv, 0.0)))
        w_z = float(np.mean(imu.gyro_b[:i_end, 2]))
        a_sd_y = max(v_max * abs(w_z), MOVING_ACCEL_SD_MIN)
        return MovingStart(i_end, np.zeros(3), max(a_sd, MOVING_ACCEL_SD_MIN), a_sd_y)
    w_z = float(np.mean(imu.gyro_b[:i_end, 2]))
    accel_b = np.array([a_along, max(v_mid, 0.0) * w_z, 0.0])
    return MovingStart(i_end, accel_b, max(a_sd, MOVING_ACCEL_SD_MIN))


@dataclass(frozen=True)
class StartPosition:
    """Antenna position (lla, height not yet moved to the IMU) and velocity at the first IMU
    epoch, with their variances per NED axis."""

    lla: FloatArray
    pos_var: FloatArray
    vel: FloatArray
    vel_var: FloatArray


def start_position(lla: FloatArray, tg: FloatArray, t0: float, pos_sd: FloatArray,
                   moving: bool) -> StartPosition:
    """The initial position from the first fixes ``lla`` (K, 3) at times ``tg``.

    Standing or with GNSS velocity: the component-wise median (one outlier cannot become the
    initial position) with the variance σ² of the first fix; velocity zero with σ 1 m/s (the
    caller replaces it by the GNSS velocity and adds the motion at that speed).

    Moving without GNSS velocity (``moving_start`` found motion from positions): a car
    pulling away from rest at 2 m/s² is 20 m from the median of nine 1 Hz fixes at t0, so
    the first fix is taken, unless its step to the second exceeds the next step by
    ``START_OUTLIER`` σ (an outlier); that step over its interval bounds the speed ``u``,
    which sets the velocity σ (max(1 m/s, u)) and adds (u·(t_fix − t0))² to the position
    variance. With an outlier first: the median, with the largest squared distance of a fix
    from it added. A parabola through the fixes was tried and dropped: a ramp-then-cruise
    start is no parabola, and its velocity at t0 (4–6 m/s for a car at rest, σ 0.6) sent
    the filter off on 3 of 10
    cold-start-phone seeds.
    """
    med = np.median(lla, axis=0)
    ned = lla_to_ned(lla, med)
    var0 = pos_sd[0] ** 2
    if not moving:
        return StartPosition(med, var0, np.zeros(3), np.ones(3))
    step = np.linalg.norm(np.diff(ned[:3, :2], axis=0), axis=1)
    if lla.shape[0] < 3 or step[0] > step[1] + START_OUTLIER * np.hypot(pos_sd[0, 0],
                                                                         pos_sd[0, 1]):
        return StartPosition(med, var0 + np.max(ned**2, axis=0), np.zeros(3), np.ones(3))
    u = float(step[0] / max(tg[1] - tg[0], 1e-3))
    drift = (u * max(tg[0] - t0, 0.0)) ** 2
    return StartPosition(lla[0].copy(), var0 + np.array([drift, drift, 0.0]), np.zeros(3),
                         np.full(3, max(1.0, u * u)))


@dataclass(frozen=True)
class Alignment:
    """Initial nominal state, covariance and parameters from the alignment (what filter.py
    hands to the kernel as ``kernel.Initial`` and keeps for its report)."""

    lla0: FloatArray
    v0: FloatArray
    q0: FloatArray
    par0: FloatArray
    p0: FloatArray
    heading_known: bool
    yaw_unknown_var: float
    i_static: int  # end of the static levelling window (IMU samples)
    g_latency: float  # GNSS latency [s] subtracted from the fix stamps
    lever: FloatArray  # GNSS antenna lever arm in b [m]
    heading_from_mag: bool  # the initial heading is the magnetometer's
    # the last sample the alignment read [s]: the levelling window's end, the last of the
    # START_FIXES fixes; the filter's estimate is causal from here on (``online_from_s``)
    t_ready: float = -np.inf


def _start_from_fixes(drive: Drive, model: SensorModel, bp: BaroPrior, c0: FloatArray,
                      lever: FloatArray, heading_known: bool, moving: bool, g_latency: float,
                      ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, float]:
    """IMU position, its variance, velocity and its variance at the first IMU epoch from the
    first ``START_FIXES`` fixes (``start_position``), and the stamp of the last fix read;
    ``c0``: the initial attitude (b → n), ``lever``: the antenna lever arm in b. Without GNSS
    the drive's origin with a 100 m horizontal σ and the baro bias σ vertically."""
    gnss, t = drive.gnss, drive.imu.t
    v0 = np.zeros(3)
    if gnss is not None:
        tg = gnss.t - g_latency
        j0 = int(min(np.searchsorted(tg, t[0]), tg.size - 1))
        j9 = min(j0 + START_FIXES, tg.size)
        assert model.gnss_pos_sd is not None
        has_vel = gnss.vel_n is not None and model.gnss_vel_sd is not None
        sp = start_position(gnss.lla[j0:j9], tg[j0:j9], float(t[0]),
                            model.gnss_pos_sd[j0:j9], moving and not has_vel)
        lla0 = sp.lla
        d_n = c0 @ lever
        lla0[2] += d_n[2]  # antenna → IMU, vertical part (heading may be unknown)
        pos_var = sp.pos_var + (0.0 if heading_known else lever @ lever)
        if has_vel:
            v0 = gnss.vel_n[j0].copy()
            vel_var = model.gnss_vel_sd[j0] ** 2
            # motion between t0 and the fixes used
            pos_var = pos_var + (np.linalg.norm(v0) * abs(tg[j9 - 1] - t[0])) ** 2
        else:
            v0, vel_var = sp.vel, sp.vel_var
        t_fixes = float(gnss.t[j9 - 1])
    else:
        t_fixes = -np.inf
        lla0 = drive.origin_lla.copy()
        pos_var = np.array([100.0**2, 100.0**2, bp.bias_sd**2])
        vel_var = np.full(3, 1.0)
    return lla0, pos_var, v0, vel_var, t_fixes


def initial_state(drive: Drive, cfg: EkfConfig, model: SensorModel, bp: BaroPrior,
                   ka_sd: float, fm: Any = None) -> Alignment:
    """Coarse levelling over the static start, position and velocity from the first fixes
    (heading given or unknown; variances from the shared model's floored GNSS sigmas), and
    the prior covariance of every state."""
    ispec = model.imu
    imu, gnss, baro = drive.imu, drive.gnss, drive.baro
    t = imu.t
    i_static = static_window_end(imu, cfg.align_max_s)
    mv = moving_start(imu, gnss, i_static)
    tilt_extra_var: float | FloatArray = 0.0
    if mv is None:
        roll, pitch = coarse_level(imu.accel_b[:i_static].mean(axis=0))
    else:  # moving from the start: level on f_b minus the GNSS-derived acceleration
        i_static = mv.i_end
        roll, pitch = coarse_level(imu.accel_b[:i_static].mean(axis=0) - mv.accel_b)
        tilt_extra_var = (mv.accel_sd / 9.81) ** 2
        if mv.accel_sd_y is not None:  # pitch from the along-track, roll from the lateral
            tilt_extra_var = np.array([(mv.accel_sd_y / 9.81) ** 2, tilt_extra_var])
    heading_known = cfg.initial_heading is not None
    yaw0 = float(cfg.initial_heading) if heading_known else 0.0
    heading_sd = cfg.initial_heading_sd
    mag_yaw = None
    if not heading_known and fm is not None:
        mag_yaw = initial_heading(drive, float(t[i_static - 1]), roll, pitch, fm,
                                  cfg.mag_heading_floor, cfg.mag_bias_sd)
        if mag_yaw is not None:  # compass alignment
            heading_known = True
            yaw0, heading_sd = mag_yaw
    q0 = rph_to_quat([roll, pitch, yaw0])[0]
    c0 = quat_to_mat(q0)
    # a writable copy: a read-only lever arm compiles a second specialisation of every
    # helper it reaches in the kernel (skew3, the products; ~1 s of a first run)
    lever = np.zeros(3) if gnss is None else np.array(gnss.lever_arm_b, dtype=float)
    p0 = np.zeros((km.NX, km.NX))
    g_latency = 0.0
    if gnss is not None and gnss.spec is not None:
        g_latency = float(getattr(gnss.spec, "latency_s", 0.0))
    lla0, pos_var, v0, vel_var, t_fixes = _start_from_fixes(
        drive, model, bp, c0, lever, heading_known, mv is not None, g_latency)
    pos, vel, att, ba = (slice(i, i + 3) for i in (km.IPOS, km.IVEL, km.IATT, km.IBA))
    p0[pos, pos] = np.diag(pos_var)
    p0[vel, vel] = np.diag(vel_var)
    p_ba = ispec.accel_bias_sd**2 * np.eye(3)
    m_tilt = level_tilt_bias_jacobian(c0, float(gravity(lla0[0], lla0[2])))
    if np.ndim(tilt_extra_var):  # per body axis (roll, pitch), turned into n by the yaw
        cy, sy = np.cos(yaw0), np.sin(yaw0)
        rz = np.array([[cy, -sy], [sy, cy]])
        p_tilt = np.zeros((3, 3))
        p_tilt[:2, :2] = rz @ np.diag(tilt_extra_var) @ rz.T + cfg.min_tilt_sd**2 * np.eye(2)
        p0[att, att] = m_tilt @ p_ba @ m_tilt.T + p_tilt
    else:
        p0[att, att] = m_tilt @ p_ba @ m_tilt.T + (
            cfg.min_tilt_sd**2 + tilt_extra_var) * np.diag([1.0, 1.0, 0.0])
    yaw_unknown_var = np.pi**2 / 3.0
    p0[km.IATT + 2, km.IATT + 2] = heading_sd**2 if heading_known else yaw_unknown_var
    p0[att, ba] = m_tilt @ p_ba
    p0[ba, att] = (m_tilt @ p_ba).T
    p0[km.IBG:km.IBG + 3, km.IBG:km.IBG + 3] = ispec.gyro_bias_sd**2 * np.eye(3)
    p0[ba, ba] = p_ba
    p0[km.IKA:km.IKA + 3, km.IKA:km.IKA + 3] = (ka_sd if ka_sd > 0 else 1e-7) ** 2 * np.eye(3)
    p0[km.IMB:km.IMB + 3, km.IMB:km.IMB + 3] = cfg.mag_bias_sd**2 * np.eye(3)
    par0 = np.zeros(km.NPAR)
    par0[km.PTD] = bp.latency_mean
    if baro is not None and not isinstance(baro.spec, BaroSpec):
        # real log: baro bias prior centred on the first sample (relative altimeters)
        jb = int(np.searchsorted(baro.t, t[0]))
        jb = min(jb, baro.t.size - 1)
        par0[km.PBB] = float(baro.altitude[jb]) - lla0[2]
    p0[km.ISC, km.ISC] = bp.scale_sd**2
    p0[km.ITD, km.ITD] = bp.latency_sd**2
    p0[km.IBB, km.IBB] = bp.bias_sd**2
    gm = cfg.gnss_gm
    if gm is not None:
        for ax, sd in zip(gm.axes, gm.sd, strict=True):
            i = km.IGE + ax
            p0[i, i] = sd**2
            if gnss is not None:
                # the first fixes carry the correlated error e: δr = e + w, δe = −e
                p0[ax, ax] += sd**2
                p0[ax, i] = p0[i, ax] = -(sd**2)
    return Alignment(lla0, v0, q0, par0, p0, heading_known, yaw_unknown_var, i_static,
                    g_latency, lever, mag_yaw is not None,
                    max(float(t[i_static - 1]), t_fixes))
