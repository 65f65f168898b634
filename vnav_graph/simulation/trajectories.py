"""Truth trajectories from closed-form kinematics, and the IMU readings they imply.

A trajectory is described by three smooth scalar functions of time — ground/air speed v(t),
heading ψ(t) and flight-path angle γ(t) — each a sum of C²-continuous "smootherstep" ramps,
with analytic first and second derivatives. From them, exactly:

    v_n  = v·[cosγ cosψ, cosγ sinψ, −sinγ]                       (NED velocity)
    v̇_n  = analytic derivative of the above
    roll = atan(v·ψ̇/g) (coordinated turn, aircraft) or 0 (car), pitch = γ + α, yaw = ψ − β
    β = k_β·a_lat, a_lat = v·cosγ·ψ̇  (side-slip, off by default: k_β = 0)
    ω_nb^b from Euler-angle rates, ω_ib^b = ω_nb^b + C_bn(ω_ie^n + ω_en^n)
    f_n  = v̇_n + (2ω_ie^n + ω_en^n) × v_n − [0, 0, γ_g(lat, h)]     (Groves eq. 5.54)
    f_b  = C_bn f_n

Latitude, longitude and height follow from integrating v_n (trapezoidal on the dense truth
grid, with the radii of curvature), so truth, IMU and the mechanisation of
``vnav_graph.nav.strapdown`` agree to integration accuracy.

Side-slip β (``slip_gain`` k_β [rad per m/s²]): the body points β to the left of the velocity
(β > 0 in a right turn), so the body-frame lateral velocity is v·cosγ·sinβ instead of the
zero a non-holonomic constraint assumes. ``mount_imu`` turns the IMU by a fixed mounting
misalignment relative to the vehicle: the readings and the truth attitude are then the
sensor's (what every estimator estimates), the vehicle's attitude is C_nb·C_vbᵀ.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..geo.earth import G0, earth_rate_n, gravity, radii, transport_rate_n
from ..geo.frames import mat_to_quat, rph_to_quat
from ..types import Trajectory
from ..types.streams import FloatArray


def _smootherstep(x: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    x = np.clip(x, 0.0, 1.0)
    s = x**3 * (10 - 15 * x + 6 * x**2)
    d1 = 30 * x**2 * (1 - x) ** 2
    d2 = 60 * x * (1 - x) * (1 - 2 * x)
    return s, d1, d2


@dataclass
class SmoothProfile:
    """f(t) = f0 + Σ Δ_i · S((t − t_i)/T_i), S the C² smootherstep; value, f', f''."""

    f0: float
    ramps: list[tuple[float, float, float]]  # (t_start, duration, delta)

    def add(self, t_start: float, duration: float, delta: float) -> None:
        self.ramps.append((t_start, duration, delta))

    def eval(self, t: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        f = np.full(t.shape, self.f0)
        d1 = np.zeros(t.shape)
        d2 = np.zeros(t.shape)
        for t0, T, dlt in self.ramps:
            m = t > t0
            if not np.any(m):
                continue
            s, s1, s2 = _smootherstep((t[m] - t0) / T)
            f[m] += dlt * s
            d1[m] += dlt * s1 / T
            d2[m] += dlt * s2 / T**2
        return f, d1, d2


@dataclass(frozen=True)
class Kinematics:
    """Truth trajectory plus the ideal IMU readings at the same times."""

    truth: Trajectory
    gyro_b: FloatArray  # ω_ib^b (N, 3) [rad/s]
    accel_b: FloatArray  # f_ib^b (N, 3) [m/s^2]
    omega_nb_b: FloatArray  # ω_nb^b (N, 3) [rad/s], for lever-arm velocities


def kinematics(
    t: FloatArray,
    speed: SmoothProfile,
    heading: SmoothProfile,
    fpa: SmoothProfile,
    origin_lla: FloatArray,
    *,
    coordinated_turns: bool,
    alpha: float = 0.0,
    slip_gain: float = 0.0,
) -> Kinematics:
    """Evaluate the trajectory defined by speed, heading and flight-path-angle profiles;
    ``slip_gain``: side-slip per lateral acceleration k_β [rad per m/s²] (module docstring)."""
    v, vd, _ = speed.eval(t)
    psi, psid, psidd = heading.eval(t)
    gam, gamd, _ = fpa.eval(t)
    n = t.size
    vel_n = np.empty((n, 3))
    for a, b in _chunks(n):
        vv, cg, sg = v[a:b], np.cos(gam[a:b]), np.sin(gam[a:b])
        ps = psi[a:b]
        vel_n[a:b] = np.column_stack([vv * cg * np.cos(ps), vv * cg * np.sin(ps), -vv * sg])
    # position: integrate NED velocity on the dense grid (trapezoid), lat/lon via radii
    dt = np.diff(t)
    dh = np.cumsum(0.5 * (vel_n[1:, 2] + vel_n[:-1, 2]) * dt)
    h = origin_lla[2] - np.concatenate([[0.0], dh])
    del dh
    lat = np.empty_like(t)
    lat[0] = origin_lla[0]
    # sequential in latitude only through R_N(lat), which varies by 1e-9 per metre: a first
    # pass with the origin radii, then one fixed-point refinement with the pass's latitudes.
    for _ in range(2):
        rn, re = radii(lat if _ else np.full_like(t, origin_lla[0]))
        fn = vel_n[:, 0] / (rn + h)
        lat = origin_lla[0] + np.concatenate([[0.0], np.cumsum(0.5 * (fn[1:] + fn[:-1]) * dt)])
    rn, re = radii(lat)
    fe = vel_n[:, 1] / ((re + h) * np.cos(lat))
    del rn, re, fn
    lon = origin_lla[1] + np.concatenate([[0.0], np.cumsum(0.5 * (fe[1:] + fe[:-1]) * dt)])
    del fe, dt
    lla = np.column_stack([lat, lon, h])
    del lat, lon, h

    # attitude and IMU readings, sample by sample: evaluated in chunks of KIN_CHUNK samples
    # (the same elementwise formulas; the whole drive at once held ~30 temporaries of the
    # drive's length: 440 MB of peak on a 1-hour 200 Hz drive)
    q_nb = np.empty((n, 4))
    omega_nb_b = np.empty((n, 3))
    accel_b = np.empty((n, 3))
    gyro_b = np.empty((n, 3))
    for a, b in _chunks(n):
        vv, vdd, cg, sg = v[a:b], vd[a:b], np.cos(gam[a:b]), np.sin(gam[a:b])
        cp, sp = np.cos(psi[a:b]), np.sin(psi[a:b])
        pd, gd = psid[a:b], gamd[a:b]
        vn = vel_n[a:b]
        acc_n = np.column_stack(
            [
                vdd * cg * cp - vv * sg * gd * cp - vv * cg * sp * pd,
                vdd * cg * sp - vv * sg * gd * sp + vv * cg * cp * pd,
                -vdd * sg - vv * cg * gd,
            ]
        )
        if coordinated_turns:
            k = vv * pd / G0
            roll = np.arctan(k)
            rolld = (vdd * pd + vv * psidd[a:b]) / G0 / (1 + k**2)
        else:
            roll = np.zeros(b - a)
            rolld = np.zeros(b - a)
        pitch, pitchd = gam[a:b] + alpha, gd
        yaw, yawd = psi[a:b], pd
        if slip_gain:
            beta, betad = side_slip(slip_gain, vv, vdd, gam[a:b], gd, pd, psidd[a:b])
            yaw, yawd = yaw - beta, yawd - betad
        sr, cr, sth, cth = np.sin(roll), np.cos(roll), np.sin(pitch), np.cos(pitch)
        omega_nb_b[a:b] = np.column_stack(
            [rolld - yawd * sth, pitchd * cr + yawd * sr * cth, -pitchd * sr + yawd * cr * cth]
        )
        q_nb[a:b] = rph_to_quat(np.column_stack([roll, pitch, yaw]))
        # C_nb = Rz(yaw) Ry(pitch) Rx(roll)
        c_nb = _rph_to_mat(roll, pitch, yaw)
        la, hh = lla[a:b, 0], lla[a:b, 2]
        w_ie = earth_rate_n(la)
        w_en = transport_rate_n(la, hh, vn)
        f_n = acc_n + np.cross(2 * w_ie + w_en, vn)
        f_n[:, 2] -= gravity(la, hh)
        accel_b[a:b] = np.einsum("nji,nj->ni", c_nb, f_n)
        gyro_b[a:b] = omega_nb_b[a:b] + np.einsum("nji,nj->ni", c_nb, w_ie + w_en)
    for a in (lla, vel_n, q_nb):
        a.setflags(write=False)  # shared with the Trajectory instead of copied (streams.as_array)
    truth = Trajectory(t, lla, vel_n, q_nb)
    return Kinematics(truth, gyro_b, accel_b, omega_nb_b)


KIN_CHUNK = 1 << 16  # samples per chunk of ``kinematics``


def side_slip(gain: float, v: FloatArray, vd: FloatArray, gam: FloatArray, gamd: FloatArray,
              psid: FloatArray, psidd: FloatArray) -> tuple[FloatArray, FloatArray]:
    """β = k_β·v·cosγ·ψ̇ [rad] and its exact time derivative [rad/s]."""
    cg = np.cos(gam)
    beta = gain * v * cg * psid
    betad = gain * (vd * cg * psid - v * np.sin(gam) * gamd * psid + v * cg * psidd)
    return beta, betad


def mount_imu(kin: Kinematics, rph_vb: FloatArray) -> Kinematics:
    """The same motion sensed by an IMU turned by the fixed mounting misalignment ``rph_vb``
    (roll, pitch, yaw [rad] of the IMU axes in the vehicle frame, C_vb): readings and
    ω_nb^b become C_bv·(vehicle's), the truth attitude C_nb = C_nv·C_vb."""
    from ..geo.frames import quat_to_mat

    c_vb = _rph_to_mat(*(np.array([x], float) for x in rph_vb))[0]
    c_nb = quat_to_mat(kin.truth.q_nb) @ c_vb
    tr = kin.truth
    truth = Trajectory(tr.t, tr.lla, tr.vel_n, mat_to_quat(c_nb))
    return Kinematics(truth, kin.gyro_b @ c_vb, kin.accel_b @ c_vb, kin.omega_nb_b @ c_vb)


def _chunks(n: int) -> list[tuple[int, int]]:
    return [(a, min(a + KIN_CHUNK, n)) for a in range(0, n, KIN_CHUNK)]


def _rph_to_mat(roll: FloatArray, pitch: FloatArray, yaw: FloatArray) -> FloatArray:
    cr, sr, cp, sp, cy, sy = (np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch),
                              np.cos(yaw), np.sin(yaw))
    m = np.empty(roll.shape + (3, 3))
    m[:, 0, 0] = cy * cp
    m[:, 0, 1] = cy * sp * sr - sy * cr
    m[:, 0, 2] = cy * sp * cr + sy * sr
    m[:, 1, 0] = sy * cp
    m[:, 1, 1] = sy * sp * sr + cy * cr
    m[:, 1, 2] = sy * sp * cr - cy * sr
    m[:, 2, 0] = -sp
    m[:, 2, 1] = cp * sr
    m[:, 2, 2] = cp * cr
    return m


# --------------------------------------------------------------------------------------------
# Profile generators (deterministic given the rng)
# --------------------------------------------------------------------------------------------


def hill_drive_profiles(
    duration_s: float, rng: np.random.Generator, *, max_grade: float = 0.10,
    static_s: float = 20.0, radius_m: float = 3000.0, relief_m: float = 250.0,
    accel_mps2: float = 1.5, speed_range_mps: tuple[float, float] = (8.0, 25.0),
) -> tuple[SmoothProfile, SmoothProfile, SmoothProfile]:
    """Car drive: stops, accelerations to cruise speeds drawn in ``speed_range_mps`` [m/s],
    turns of 30-120°, grades up to ±max_grade.

    Segments are planned on a coarse dead-reckoned position so the drive stays within
    ``radius_m`` of the start and within ``relief_m`` of the start height. The car stands
    still for ``static_s`` [s] (0: it starts from rest and accelerates at once, a cold start
    without a standstill to level on); a speed change takes |Δv|/``accel_mps2`` [s] (mean
    acceleration; the C² ramp peaks at 1.875 times that), at least 3 s.
    """
    if not static_s >= 0 or not accel_mps2 > 0:
        raise ValueError(f"hill-drive: static_s must be >= 0 and accel_mps2 > 0, "
                         f"got {static_s!r}, {accel_mps2!r}")
    v_lo, v_hi = (float(x) for x in speed_range_mps)
    if not 0 < v_lo <= v_hi:
        raise ValueError(f"hill-drive: speed_range_mps must be (lo, hi) with 0 < lo <= hi, "
                         f"got {speed_range_mps!r}")
    speed = SmoothProfile(0.0, [])
    heading = SmoothProfile(float(rng.uniform(-np.pi, np.pi)), [])
    fpa = SmoothProfile(0.0, [])
    t = static_s
    v = 0.0
    psi = heading.f0
    gam = 0.0
    n_pos = e_pos = h_rel = 0.0
    while t < duration_s:
        seg = float(rng.uniform(15.0, 45.0))
        # speed: stop now and then, else a new cruise speed
        if v > 0 and rng.random() < 0.15:
            dur = max(v / 2.0, 4.0)
            speed.add(t, dur, -v)
            n_pos += 0.5 * v * dur * np.cos(psi)
            e_pos += 0.5 * v * dur * np.sin(psi)
            h_rel += 0.5 * v * dur * np.sin(gam)
            t += dur + float(rng.uniform(5.0, 20.0))
            v = 0.0
            continue
        v_new = float(rng.uniform(v_lo, v_hi))
        dur_v = max(abs(v_new - v) / accel_mps2, 3.0)
        speed.add(t, dur_v, v_new - v)
        # grade: stay inside the relief band
        target = float(rng.uniform(-max_grade, max_grade))
        if h_rel > 0.6 * relief_m:
            target = -abs(target)
        elif h_rel < -0.6 * relief_m:
            target = abs(target)
        g_new = float(np.arctan(target))
        fpa.add(t, float(rng.uniform(8.0, 20.0)), g_new - gam)
        # heading: turn toward home when far out
        if v_new > 5.0 and rng.random() < 0.7:
            dpsi = float(rng.uniform(np.pi / 6, 2 * np.pi / 3)) * (1 if rng.random() < 0.5 else -1)
            dist = np.hypot(n_pos, e_pos)
            if dist > 0.5 * radius_m:
                home = np.arctan2(-e_pos, -n_pos)
                dpsi = float(np.angle(np.exp(1j * (home - psi))))
            t_turn = t + dur_v
            heading.add(t_turn, max(abs(dpsi) * 10.0, 4.0), dpsi)
            psi += dpsi
        v_mean = 0.5 * (v + v_new)
        n_pos += v_mean * seg * np.cos(psi)
        e_pos += v_mean * seg * np.sin(psi)
        h_rel += v_mean * seg * np.sin(0.5 * (gam + g_new))
        v, gam = v_new, g_new
        t += seg
    return speed, heading, fpa


def sortie_profiles(
    duration_s: float, rng: np.random.Generator, *, max_vz: float = 15.0,
    static_s: float = 20.0, radius_m: float = 10000.0, cruise_alt_m: float = 1500.0,
) -> tuple[SmoothProfile, SmoothProfile, SmoothProfile]:
    """Aircraft-like sortie: take-off roll, climb, cruise legs with coordinated turns, level
    changes and a final descent; |vertical speed| ≤ max_vz."""
    speed = SmoothProfile(0.0, [])
    heading = SmoothProfile(float(rng.uniform(-np.pi, np.pi)), [])
    fpa = SmoothProfile(0.0, [])
    t = static_s
    speed.add(t, 25.0, 60.0)  # take-off roll to 60 m/s
    t += 25.0
    v = 60.0
    alt = 0.0
    psi = heading.f0
    n_pos = e_pos = 0.0
    t_descent = 0.8 * duration_s

    def level_change(t: float, dh: float, v: float) -> float:
        gam = float(np.sign(dh) * np.arcsin(min(max_vz * rng.uniform(0.6, 1.0), 0.9 * v) / v))
        t_ramp = 10.0
        t_hold = max(abs(dh) / (v * abs(np.sin(gam))) - t_ramp, 1.0)
        fpa.add(t, t_ramp, gam)
        fpa.add(t + t_ramp + t_hold, t_ramp, -gam)
        return t + 2 * t_ramp + t_hold

    while t < t_descent:
        if alt < 0.5 * cruise_alt_m:
            dh = cruise_alt_m * rng.uniform(0.8, 1.2) - alt
        else:
            dh = float(rng.uniform(-400.0, 400.0))
        t_end = level_change(t, dh, v)
        alt += dh
        v_new = float(rng.uniform(60.0, 90.0))
        speed.add(t_end, 15.0, v_new - v)
        v = v_new
        leg = float(rng.uniform(40.0, 120.0))
        dist = np.hypot(n_pos, e_pos)
        dpsi = float(rng.uniform(np.pi / 4, np.pi)) * (1 if rng.random() < 0.5 else -1)
        if dist > 0.5 * radius_m:
            dpsi = float(np.angle(np.exp(1j * (np.arctan2(-e_pos, -n_pos) - psi))))
        # standard-rate-ish turn: 3 deg/s
        heading.add(t_end + 15.0, max(abs(dpsi) / np.radians(3.0), 5.0), dpsi)
        psi += dpsi
        seg_t = t_end + 15.0 + leg - t
        n_pos += v * seg_t * np.cos(psi)
        e_pos += v * seg_t * np.sin(psi)
        t = t_end + 15.0 + leg
    if t < duration_s and alt > 50.0:
        level_change(t, -0.9 * alt, v)
    return speed, heading, fpa


def vertical_kinematics(
    t: FloatArray, origin_lla: FloatArray, rng: np.random.Generator, *,
    amplitude_m: float = 50.0, static_s: float = 10.0,
) -> Kinematics:
    """Level platform at fixed lat/lon moving vertically by smooth up/down ramps."""
    prof = SmoothProfile(0.0, [])
    tt = static_s
    h_rel = 0.0
    while tt < t[-1]:
        target = float(rng.uniform(-amplitude_m, amplitude_m))
        dur = float(rng.uniform(20.0, 60.0))
        prof.add(tt, dur, target - h_rel)
        h_rel = target
        tt += dur + float(rng.uniform(10.0, 40.0))
    hr, hd, hdd = prof.eval(t)
    n = t.size
    lat = np.full(n, origin_lla[0])
    lla = np.column_stack([lat, np.full(n, origin_lla[1]), origin_lla[2] + hr])
    vel_n = np.column_stack([np.zeros(n), np.zeros(n), -hd])
    acc_n = np.column_stack([np.zeros(n), np.zeros(n), -hdd])
    w_ie = earth_rate_n(lat)
    w_en = transport_rate_n(lat, lla[:, 2], vel_n)
    f_n = acc_n + np.cross(2 * w_ie + w_en, vel_n)
    f_n[:, 2] -= gravity(lat, lla[:, 2])
    q = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    truth = Trajectory(t, lla, vel_n, q)
    return Kinematics(truth, w_ie + w_en, f_n, np.zeros((n, 3)))
