"""Inputs of the classical vertical-channel estimators: vertical specific force, gravity, C33.

The seed papers (000, 001, 003, 004) all assume that "the INS" hands the vertical channel its
specific force resolved along the local vertical: seed 001 eq. 5 uses C_b(3,3)^n·F_z and the
vertical specific force, seed 003 "the acceleration component along the gravity vector". To
produce it the vertical estimators need an attitude. They must not use the simulator's truth,
so this module provides a small **GNSS-aided attitude and heading reference (AHRS)** that
stands for "the INS attitude" of the papers:

1. **Coarse levelling.** The mean specific force f̄_b over the first ``level_s`` seconds
   (the vehicle must be at rest or unaccelerated there; every simulated scenario begins with a
   10-20 s static period) gives roll φ = atan2(−f̄_y, −f̄_z),
   pitch θ = atan2(f̄_x, √(f̄_y² + f̄_z²)); yaw starts at 0 and is reset once to the GNSS course
   the first time the ground speed exceeds ``v_course_min``.
2. **Gyro integration** with the shared Earth-rate- and transport-rate-aware mechanisation
   (``strapdown.strapdown_step``; its position/velocity outputs are discarded, the GNSS
   position/velocity interpolated to the IMU epoch feed its ω_ie, ω_en), with the gyro
   corrected by an estimated bias b̂_g and a complementary feedback rate:
   ω_used = ω̃ − b̂_g − C_bn·K_p·ψ̂,   d b̂_g/dt = C_bn·K_i·ψ̂   (Mahony-type PI law), with
   K_p = diag(k_p, k_p, k_y), K_i = diag(k_i, k_i, k_y²/4).
3. **Tilt error by velocity matching.** Over each interval [t_j, t_{j+1}] between consecutive
   GNSS fixes (thinned to intervals ≥ ``match_interval_s``), the integral of the measured
   specific force resolved with the AHRS attitude,
   ΔF = ∫ C_nb f̃_b dt (IMU epochs, trapezoid, linearly interpolated to the fix times), is
   compared with what the GNSS velocities imply (Groves eq. 5.54 rearranged):
   f̄_ref = Δv_gnss/Δt − g_n + (2ω_ie + ω_en) × v̄,   δf = ΔF/Δt − f̄_ref ≈ ψ × f̄_ref.
   The tilt estimate is the component of ψ perpendicular to f̄_ref,
   ψ̂_{x,y} = [f̄_ref × δf]_{x,y} / |f̄_ref|².
   The raw ψ̂ is low-passed with time constant T_f (``tilt_filter_s``) and held as a
   feedback rate until the next fix (zeroed in GNSS outages). Because successive Δv
   telescope, GNSS velocity noise σ_v enters the tilt only as ≈ k_p·σ_v/g (no
   differentiation noise build-up).
   Without GNSS velocity (seed003 scenario) the reference velocity is the central difference
   of the GNSS positions.
4. **Heading** ψ̂_z = wrap(ψ_est − χ_gnss), the yaw minus the GNSS course over ground, when the
   ground speed exceeds ``v_course_min`` (assumes no sideslip/crab: true for the simulated car
   and aircraft; the threshold is raised to 5σ of the GNSS velocity noise so noise never
   fakes a course; the vertical specific force does not depend on heading, heading only keeps
   the velocity matching of step 3 consistent in turns).

Outputs at the IMU epochs (``VerticalInputs``): the AHRS attitude q_nb, the vertical specific
force f_D = [C_nb f̃_b]_3 (NED down, m/s², ≈ −g at rest), C33 = C_nb[2, 2], the body-z specific
force F_z = f̃_b,z (so f_D ≈ C33·F_z + C31·F_x + C32·F_y), the latitude, the normal gravity
g(lat, h_ref), and the vertical Coriolis/transport term, so that the free-inertial vertical
channel reads

    dv_D/dt = f_D + g(lat, h) + cor_D,   cor_D = −[(2ω_ie + ω_en) × v]_D.

Vertical estimators integrate their own height and should evaluate g at *their* height
(``gravity_scalar(lat, h)``) — that is where the 2g/R positive feedback of the vertical channel
comes from; ``gravity`` holds g at the reference (GNSS) height for convenience only. None of
the outputs uses truth; the accelerometer biases are *not* removed (the vertical estimators
estimate them).

The expected accuracy (tested in ``tests/integration/test_vertical_input.py``): the tilt
error is dominated by the horizontal accelerometer bias, |ψ_h| ≈ |b_a,h|/g (a tilted
platform cancels a horizontal bias: the classical levelling limit), i.e. ≈ 7 mrad for the
consumer preset (5 mg per axis), ≈ 1.4 mrad for the industrial one. The attitude-induced
error in f_D is ≈ |ψ_h|·|a_h| + g·|ψ_h|²/2, i.e. millimetres per second squared.

References: Groves, 2nd ed., §5.4-5.6 (mechanisation, coarse levelling eq. 5.101-5.102),
§12.3 (vector matching); Mahony, Hamel, Pflimlin (2008) IEEE TAC 53(5) (complementary PI
attitude filter).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from numba import njit

from ..geo.earth import OMEGA_IE, gravity, radii
from ..types import Drive, FloatArray
from .strapdown import quat_exp, quat_mul, quat_to_dcm, strapdown_step


@dataclass(frozen=True)
class AhrsConfig:
    """Gains of the GNSS-aided attitude reference.

    level_s : duration of the initial coarse-levelling average [s]
    tilt_omega : natural frequency ω_t of the tilt PI loop [rad/s]; k_p = 2ζω_t, k_i = ω_t²
    tilt_zeta : damping ζ of the tilt loop [-]
    yaw_gain : proportional gain k_y of the course-over-ground heading correction [1/s]; the
        z-gyro bias integrator gain is k_y²/4 (critically damped heading loop)
    v_course_min : ground speed above which the GNSS course is trusted as heading [m/s]
    max_correction : clamp on |ψ̂| per update [rad], only against gross GNSS errors (a tight
        clamp would break the telescoping of the velocity noise, see step 3 above)
    gap_factor : a fix pair further apart than gap_factor × the nominal fix interval is an
        outage; no correction is made across it
    a_static : before the heading is initialised, tilt is corrected only over fix intervals
        whose horizontal reference acceleration is below this [m/s²] (plus 3σ of the
        differenced GNSS velocity noise, 3·√2·σ_v/``match_interval_s``)
    match_interval_s : minimum length of a velocity-matching interval [s]; faster fixes are
        thinned (at 10 Hz with σ_v = 0.1 m/s, matching every fix gave 3-5× larger tilt noise
        on the simulated hill-drive than matching every 0.5 s, because the body-frame bias
        integrator does not telescope the differenced noise while the vehicle turns)
    tilt_filter_s : time constant T_f of the first-order low-pass on the raw tilt
        observation ψ̂ [s]; it turns the differenced GNSS velocity noise σ_v·√2/(Δt·g) per fix
        into ≈ σ_v/(T_f·g) before it reaches the body-frame gyro-bias integrator
    """

    level_s: float = 2.0
    tilt_omega: float = 0.05
    tilt_zeta: float = 1.0
    yaw_gain: float = 0.1
    v_course_min: float = 5.0
    max_correction: float = 1.0
    gap_factor: float = 2.5
    a_static: float = 0.3
    match_interval_s: float = 0.5
    tilt_filter_s: float = 2.0

    def __post_init__(self) -> None:
        for n in ("level_s", "tilt_omega", "tilt_zeta", "v_course_min", "max_correction",
                  "gap_factor", "tilt_filter_s"):
            if not getattr(self, n) > 0:
                raise ValueError(f"AhrsConfig.{n}: must be > 0")
        if self.yaw_gain < 0:
            raise ValueError("AhrsConfig.yaw_gain: must be >= 0")


@dataclass(frozen=True)
class VerticalInputs:
    """Vertical-channel inputs at the IMU epochs (see module docstring for the equations).

    Parameters
    ----------
    t : (N,) IMU epochs [s]
    f_down : (N,) vertical specific force f_D = [C_nb f̃_b]_3, NED down [m/s²] (≈ −g at rest)
    gravity : (N,) normal gravity g(lat, h_ref) at the reference (GNSS) height [m/s²], +down
    c33 : (N,) C_nb[2, 2] of the AHRS attitude [-]
    f_z_b : (N,) measured specific force along body z (down) [m/s²]
    coriolis_down : (N,) cor_D = −[(2ω_ie + ω_en) × v]_D from GNSS horizontal velocity [m/s²]
    lat : (N,) latitude used for gravity [rad] (GNSS, interpolated; origin without GNSS)
    q_nb : (N, 4) AHRS attitude (w, x, y, z), b → n
    bias_gyro : (N, 3) AHRS gyro-bias estimate [rad/s]
    """

    t: FloatArray
    f_down: FloatArray
    gravity: FloatArray
    c33: FloatArray
    f_z_b: FloatArray
    coriolis_down: FloatArray
    lat: FloatArray
    q_nb: FloatArray
    bias_gyro: FloatArray
    runtime_s: float = 0.0

    @property
    def accel_down(self) -> FloatArray:
        """Free-inertial vertical acceleration f_D + g(h_ref) + cor_D [m/s², +down]."""
        return self.f_down + self.gravity + self.coriolis_down


@njit(cache=True)
def _wrap_nb(a):
    return (a + np.pi) % (2.0 * np.pi) - np.pi


@njit(cache=True)
def _ahrs(t, gyro, accel, q0, lla_i, vel_i, t_g, v_g, g_g, cor_g, ok_g,
          kp, ki, k_yaw, ki_yaw, v_min, max_corr, a_static, t_filt, gap, yaw_init_done):
    """Numba kernel. lla_i, vel_i: (N, 3) GNSS position/velocity at IMU epochs (for the
    Earth/transport rates and the course); t_g (M,), v_g (M, 3) reference velocities at fixes,
    g_g (M,) gravity at fixes, cor_g (M, 3) (2ω_ie+ω_en)×v at fixes, ok_g (M,) bool: the
    interval [j-1, j] is usable."""
    n = t.size
    m = t_g.size
    q = np.empty((n, 4))
    bg_out = np.empty((n, 3))
    f_n = np.empty((n, 3))
    q[0] = q0
    bg = np.zeros(3)
    psi = np.zeros(3)  # current attitude-error estimate (n frame), applied as a rate
    c = quat_to_dcm(q0)
    f_n[0] = c @ accel[0]
    cum = np.zeros(3)  # ∫ f_n dt from t[0]
    cum_prev = np.zeros(3)
    j = 0
    while j < m and t_g[j] <= t[0]:
        j += 1
    f_at_last = np.zeros(3)  # ∫ f_n up to the previous fix time
    have_last = False
    if j > 0:
        have_last = True  # a fix at or before t[0]: integral there is 0
    yaw_done = yaw_init_done
    skip = False
    psi_until = -np.inf
    for k in range(n - 1):
        dt = t[k + 1] - t[k]
        c = quat_to_dcm(q[k])
        if t[k] > psi_until:  # no fix for a while (outage): no tilt correction
            psi[0] = 0.0
            psi[1] = 0.0
        # PI feedback, tilt gains (kp, ki) on ψ_x, ψ_y and heading gains (k_yaw, ki_yaw) on ψ_z
        corr_p = c.T @ np.array([kp * psi[0], kp * psi[1], k_yaw * psi[2]])
        corr_i = c.T @ np.array([ki * psi[0], ki * psi[1], ki_yaw * psi[2]])
        bg = bg + corr_i * dt
        w0 = gyro[k] - bg - corr_p
        w1 = gyro[k + 1] - bg - corr_p
        _, _, qn = strapdown_step(lla_i[k], vel_i[k], q[k], w0, w1, accel[k], accel[k + 1], dt)
        q[k + 1] = qn
        bg_out[k] = bg
        c1 = quat_to_dcm(qn)
        f_n[k + 1] = c1 @ accel[k + 1]
        cum_prev = cum.copy()
        cum = cum + 0.5 * (f_n[k] + f_n[k + 1]) * dt
        # heading: one-time reset to the GNSS course, then proportional correction
        vh = np.sqrt(vel_i[k + 1, 0] ** 2 + vel_i[k + 1, 1] ** 2)
        yaw = np.arctan2(c1[1, 0], c1[0, 0])
        if vh > v_min:
            course = np.arctan2(vel_i[k + 1, 1], vel_i[k + 1, 0])
            if not yaw_done:
                dq = quat_exp(np.array([0.0, 0.0, _wrap_nb(course - yaw)]))
                q[k + 1] = quat_mul(dq, qn)
                yaw_done = True
                psi[2] = 0.0
                skip = True  # the current fix interval mixes two headings
            else:
                e = _wrap_nb(yaw - course)
                if e > max_corr:
                    e = max_corr
                elif e < -max_corr:
                    e = -max_corr
                psi[2] = e
        else:
            psi[2] = 0.0
        # tilt: velocity matching at each GNSS fix passed in (t[k], t[k+1]]
        while j < m and t_g[j] <= t[k + 1]:
            a = (t_g[j] - t[k]) / dt
            f_here = cum_prev + a * (cum - cum_prev)
            if have_last and ok_g[j] and not skip:
                dtg = t_g[j] - t_g[j - 1]
                f_meas = (f_here - f_at_last) / dtg
                f_ref = (v_g[j] - v_g[j - 1]) / dtg + 0.5 * (cor_g[j] + cor_g[j - 1])
                f_ref[2] -= 0.5 * (g_g[j] + g_g[j - 1])
                # before the heading is known a horizontal acceleration would be read as tilt
                # (δf = ψ_z × a_h); then only quasi-static intervals level the platform
                if not yaw_done and f_ref[0] ** 2 + f_ref[1] ** 2 > a_static**2:
                    psi[0] = 0.0
                    psi[1] = 0.0
                    have_last = True
                    skip = False
                    f_at_last = f_here
                    j += 1
                    continue
                d = f_meas - f_ref
                cr = np.array([f_ref[1] * d[2] - f_ref[2] * d[1],
                               f_ref[2] * d[0] - f_ref[0] * d[2]])
                nf2 = f_ref[0] ** 2 + f_ref[1] ** 2 + f_ref[2] ** 2
                # first-order low-pass (time constant t_filt) of the raw tilt observation
                alpha = dtg / t_filt if dtg < t_filt else 1.0
                for i in range(2):
                    p = cr[i] / nf2
                    if p > max_corr:
                        p = max_corr
                    elif p < -max_corr:
                        p = -max_corr
                    psi[i] += alpha * (p - psi[i])
                psi_until = t_g[j] + gap * dtg
            f_at_last = f_here
            have_last = True
            skip = False
            j += 1
    bg_out[n - 1] = bg
    return q, f_n, bg_out


def _thin(t: FloatArray, min_dt: float) -> FloatArray:
    """Indices of a greedy subset of the increasing times ``t`` spaced at least ``min_dt``
    (within 1 % to tolerate stamp jitter)."""
    keep = [0]
    for i in range(1, t.size):
        if t[i] - t[keep[-1]] >= 0.99 * min_dt:
            keep.append(i)
    return np.asarray(keep, dtype=np.int64)


def _coarse_level(accel_b: FloatArray) -> FloatArray:
    """Roll/pitch from a mean specific force at rest (Groves eq. 5.101), yaw 0; returns q_nb."""
    from ..geo.frames import rph_to_quat

    f = np.mean(accel_b, axis=0)
    roll = np.arctan2(-f[1], -f[2])
    pitch = np.arctan2(f[0], np.hypot(f[1], f[2]))
    return rph_to_quat(np.array([[roll, pitch, 0.0]]))[0]


def vertical_inputs(drive: Drive, config: AhrsConfig | None = None) -> VerticalInputs:
    """Vertical specific force, gravity, C33 and F_z at the IMU epochs from a GNSS-aided AHRS.

    Parameters
    ----------
    drive : the drive; uses ``imu`` and, when present, ``gnss`` (positions, and velocities if
        given). Truth is never read.
    config : AHRS gains (``AhrsConfig()`` by default: tilt loop ω_t = 0.05 rad/s, ζ = 1)

    Returns
    -------
    VerticalInputs
        arrays of shape (N,) (``q_nb`` (N, 4), ``bias_gyro`` (N, 3)) at ``drive.imu.t``.
    """
    cfg = config or AhrsConfig()
    t0 = time.perf_counter()
    imu = drive.imu
    t = imu.t
    n = t.size
    lev = t <= t[0] + cfg.level_s
    q0 = _coarse_level(imu.accel_b[lev])
    gn = drive.gnss
    if gn is not None and gn.t.size >= 3:
        t_g = gn.t
        lla_g = gn.lla
        if gn.vel_n is not None:
            v_g = gn.vel_n
        else:
            # central differences of the GNSS positions (NED metres via the radii)
            rn, re = radii(lla_g[:, 0])
            pn = np.column_stack([
                (lla_g[:, 0] - lla_g[0, 0]) * (rn + lla_g[:, 2]),
                (lla_g[:, 1] - lla_g[0, 1]) * (re + lla_g[:, 2]) * np.cos(lla_g[:, 0]),
                -(lla_g[:, 2] - lla_g[0, 2]),
            ])
            v_g = np.column_stack([np.gradient(pn[:, i], t_g) for i in range(3)])
        dt_nom = float(np.median(np.diff(t_g)))
        if gn.vel_sd is not None:
            sd_v = float(np.median(gn.vel_sd[:, :2]))
        else:  # central difference: σ_v = √2·σ_p / (2Δt)
            sd_v = float(np.median(gn.pos_sd[:, :2])) / (np.sqrt(2.0) * dt_nom)
        ok = np.concatenate([[False], np.diff(t_g) <= cfg.gap_factor * dt_nom])
        lla_i = np.column_stack([np.interp(t, t_g, lla_g[:, i]) for i in range(3)])
        vel_i = np.column_stack([np.interp(t, t_g, v_g[:, i]) for i in range(3)])
        # inside outages the interpolated velocity is not a measurement: no course there
        in_gap = np.zeros(n, dtype=bool)
        for i in np.flatnonzero(~ok[1:]) + 1:
            in_gap |= (t > t_g[i - 1]) & (t < t_g[i])
        vel_i[in_gap, :2] = 0.0
        # velocity matching over intervals of at least match_interval_s (fewer, longer Δv)
        keep = _thin(t_g, cfg.match_interval_s)
        t_g, lla_g, v_g = t_g[keep], lla_g[keep], v_g[keep]
        ok = np.concatenate(
            [[False], np.diff(t_g) <= cfg.gap_factor * max(dt_nom, cfg.match_interval_s)])
        g_g = gravity(lla_g[:, 0], lla_g[:, 2])
        w_ie = np.column_stack([OMEGA_IE * np.cos(lla_g[:, 0]), np.zeros(t_g.size),
                                -OMEGA_IE * np.sin(lla_g[:, 0])])
        rn, re = radii(lla_g[:, 0])
        w_en = np.column_stack([v_g[:, 1] / (re + lla_g[:, 2]), -v_g[:, 0] / (rn + lla_g[:, 2]),
                                -v_g[:, 1] * np.tan(lla_g[:, 0]) / (re + lla_g[:, 2])])
        cor_g = np.cross(2 * w_ie + w_en, v_g)
    else:
        t_g = np.empty(0)
        v_g = np.zeros((0, 3))
        g_g = np.empty(0)
        cor_g = np.zeros((0, 3))
        ok = np.zeros(0, dtype=bool)
        lla_i = np.tile(drive.origin_lla, (n, 1))
        vel_i = np.zeros((n, 3))
        sd_v = 0.0
    # the course is trusted only when the speed is far above the velocity noise (5σ)
    v_course = max(cfg.v_course_min, 5.0 * sd_v)
    # "quasi-static" threshold raised by 3σ of the differenced velocity noise per interval
    a_static_eff = cfg.a_static + 3.0 * np.sqrt(2.0) * sd_v / cfg.match_interval_s
    kp = 2.0 * cfg.tilt_zeta * cfg.tilt_omega
    ki = cfg.tilt_omega**2
    q, f_n, bg = _ahrs(
        t, imu.gyro_b, imu.accel_b, q0, np.ascontiguousarray(lla_i),
        np.ascontiguousarray(vel_i), np.ascontiguousarray(t_g, dtype=float),
        np.ascontiguousarray(v_g, dtype=float), np.ascontiguousarray(g_g, dtype=float),
        np.ascontiguousarray(cor_g, dtype=float), ok, kp, ki, cfg.yaw_gain, 0.25 * cfg.yaw_gain**2,
        v_course, cfg.max_correction, a_static_eff, cfg.tilt_filter_s, cfg.gap_factor, False,
    )
    lat = lla_i[:, 0]
    h_ref = lla_i[:, 2]
    x, y = q[:, 1], q[:, 2]
    c33 = 1.0 - 2.0 * (x * x + y * y)
    # cor_D = −[(2ω_ie + ω_en) × v]_D with v from GNSS (horizontal components only matter)
    rn_i, re_i = radii(lat)
    wx = 2 * OMEGA_IE * np.cos(lat) + vel_i[:, 1] / (re_i + h_ref)
    wy = -vel_i[:, 0] / (rn_i + h_ref)
    cor_d = -(wx * vel_i[:, 1] - wy * vel_i[:, 0])
    q = np.where(q[:, :1] < 0, -q, q)
    return VerticalInputs(
        t=t, f_down=f_n[:, 2].copy(), gravity=gravity(lat, h_ref), c33=c33,
        f_z_b=imu.accel_b[:, 2].copy(), coriolis_down=cor_d, lat=lat, q_nb=q, bias_gyro=bg,
        runtime_s=time.perf_counter() - t0,
    )


__all__ = ["AhrsConfig", "VerticalInputs", "vertical_inputs"]
