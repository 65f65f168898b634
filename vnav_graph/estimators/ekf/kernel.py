"""The forward EKF kernel: one compiled pass over the whole drive (``run_filter``).

The error-state model, its measurement rows and the update steps it calls are in
``ekf.model`` (whose docstring describes the filter); this module holds only the loop that
strings them together, a documented numba kernel kept whole so that it compiles once.

Its inputs are eight typed records (``NamedTuple``s of arrays and scalars, which numba passes
as tuples: a field read is resolved at compile time and costs nothing): :class:`Grids`,
:class:`Initial`, :class:`Noise`, :class:`Events`, :class:`GnssData`, :class:`BaroData`,
:class:`MagData` and :class:`Settings`, built by ``ekf.filter``. Every field keeps one numba
type (float64 arrays, C-contiguous; int64 counts; float scalars; bools) so that the kernel
compiles once.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit
from numpy.typing import NDArray

from ...geo.earth import radii_scalar
from ...nav.arrays import put
from ...nav.gnss_gate import REFUSE, USE_INFLATE, height_gate
from ...nav.rotations import cross3, quat_mul, quat_to_dcm, rpy_quat, skew3
from ...nav.rotations import yaw_of as _yaw
from ...nav.strapdown import nav_rates, strapdown_step
from ...sensors.magnetometer import MIN_HORIZONTAL_UT, mag_heading_row
from .model import (
    IATT,
    IBB,
    IBG,
    IGH,
    IMB,
    IPOS,
    ISC,
    ITD,
    IVEL,
    NING,
    NPACK,
    NPAR,
    NX,
    PBA,
    PBB,
    PBG,
    PGH,
    PKA,
    PMB,
    PSC,
    PTD,
    apply_correction,
    baro_predict,
    baro_row,
    build_f,
    pack,
    reset_jacobian,
    scalar_update,
    step_phi,
    vector_update,
)

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]


class Grids(NamedTuple):
    """The IMU samples (N) and where each lands: covariance grid, outputs, gaps."""

    t: FloatArray  # (N,) IMU stamps [s]
    gyro: FloatArray  # (N, 3) angular rate in b [rad/s]
    accel: FloatArray  # (N, 3) specific force in b [m/s²]
    grid_of: IntArray  # (N,) grid epoch of IMU sample i, −1 if none
    out_of: IntArray  # (N,) output-trajectory slot of IMU sample i, −1 if none
    n_grid: int  # number of grid epochs K
    n_out: int  # number of output-trajectory epochs
    cov_out_of: IntArray  # (K,) covariance-output slot of grid epoch k, −1 if none
    n_cov_out: int  # number of covariance-output epochs
    gap_step: BoolArray  # (N−1,) IMU interval i → i+1 is a gap (a grid interval of its own)
    gap_rp: FloatArray  # (N, 2) roll, pitch re-levelled at a gap's end sample [rad], else NaN


class Initial(NamedTuple):
    """The state at the first IMU sample (alignment)."""

    lla0: FloatArray  # (3,) latitude, longitude [rad], height [m]
    v0: FloatArray  # (3,) velocity in n [m/s]
    q0: FloatArray  # (4,) attitude q_nb
    par0: FloatArray  # (NPAR,) biases, baro, accel scale, mag hard iron (ekf.model P*)
    p0: FloatArray  # (NX, NX) error covariance
    heading_known: bool  # the heading is given (else acquired in flight)


class Noise(NamedTuple):
    """Process noise and Gauss-Markov time constants."""

    q_diag: FloatArray  # (K, NX) discrete process-noise variances per grid interval
    tau_g: float  # gyro bias correlation time [s]
    tau_a: float  # accel bias correlation time [s]
    tau_b: float  # baro bias correlation time [s]
    tau_h: float  # GNSS height error correlation time [s] (inf: the state is off)
    yaw_unknown_var: float  # yaw variance while the heading is unknown [rad²]
    tilt_rate_sd: float  # tilt growth while the heading is unknown [rad/s]
    b_prior_var: float  # baro-bias prior variance [m²] (GNSS-height gate widening)


class Events(NamedTuple):
    """GNSS fixes and baro samples merged and sorted by time."""

    t: FloatArray  # (E,) event stamps [s]
    kind: IntArray  # (E,) 0 GNSS fix, 1 baro sample, 2 magnetometer sample
    idx: IntArray  # (E,) index into the GNSS or baro arrays
    max_pending: int  # most events inside one grid interval, + 1


class GnssData(NamedTuple):
    """Per-fix GNSS data (G fixes; zero rows without GNSS)."""

    lla: FloatArray  # (G, 3) antenna position [rad, rad, m]
    pos_sd: FloatArray  # (G, 3) NED position σ [m] (shared model, floored)
    vel: FloatArray  # (G, 3) velocity in n [m/s]
    vel_sd: FloatArray  # (G, 3) velocity σ [m/s]
    has_vel: bool  # the velocity is used
    lever: FloatArray  # (3,) antenna lever arm in b [m]
    track_yaw: FloatArray  # (G,) course over ground [rad]
    track_speed: FloatArray  # (G,) horizontal speed [m/s]
    track_sd: FloatArray  # (G,) σ of the course as a heading [rad]


class BaroData(NamedTuple):
    """Baro samples (B; zero without a barometer)."""

    alt: FloatArray  # (B,) baro altitude [m]
    sd: float  # white baro noise σ [m]
    h0: float  # reference height of the baro model [m]
    has_baro: bool


class MagData(NamedTuple):
    """Magnetometer samples (M; zero rows without one), heading model ``sensors.magnetometer``."""

    field: FloatArray  # (M, 3) field in b [µT]
    sd_ut: float  # white noise per axis [µT]
    declination: float  # of the Earth's field at the origin [rad]
    floor_var: float  # heading variance floor (declination, soft iron) [rad²]
    gate: float  # χ²₁ gate of the heading innovation
    max_consec: int  # refusals after which a heading is forced in


class Settings(NamedTuple):
    """Gates, re-acceptance and heading-acquisition settings (``EkfConfig``)."""

    gate_pos: float  # χ²₂ gate of the horizontal position pair
    gate_vel: float  # χ²₂ gate of the horizontal velocity pair
    gate_v: float  # χ²₁ gate of the GNSS height and vertical velocity
    gate_baro: float  # χ²₁ gate of the baro
    max_consec: int  # refusals after which a horizontal pair is forced in
    max_consec_baro: int  # refusals after which a baro sample is forced in
    max_sd_v: float  # GNSS heights with a larger σ are not used [m]
    probation_s: float  # GNSS-height probation [s]
    heading_v_min: float  # speed above which the track gives the heading [m/s]
    heading_accel: bool  # acquire the heading by acceleration matching
    align_chunk_s: float
    align_forget_s: float
    align_sd_max: float  # [rad]
    align_acc_sd: float  # specific-force error of a chunk [m/s²]
    gap_forget_s: float  # IMU gaps this long make the heading unknown [s]
    store_rts: bool  # keep what the RTS smoother needs


@njit(cache=True)
def decay_gm(par, dt, tau_g, tau_a, tau_b, tau_h):
    """The nominal Gauss-Markov states over ``dt``: gyro and accelerometer biases, baro bias
    and the GNSS height error each times exp(−dt/τ) (τ = inf: unchanged)."""
    if np.isfinite(tau_g):
        f = np.exp(-dt / tau_g)
        for a in range(3):
            par[PBG + a] *= f
    if np.isfinite(tau_a):
        f = np.exp(-dt / tau_a)
        for a in range(3):
            par[PBA + a] *= f
    if np.isfinite(tau_b):
        par[PBB] *= np.exp(-dt / tau_b)
    if np.isfinite(tau_h):
        par[PGH] *= np.exp(-dt / tau_h)


@njit(cache=True)
def run_filter(grids, init, noise, events, gnss, baro, mag, settings):
    """Forward error-state EKF over the whole drive (see module docstring).

    The records are described by their classes (:class:`Grids` ... :class:`Settings`).
    Returns the output trajectory, packed covariances and, when ``settings.store_rts``, what
    the RTS smoother needs.
    """
    # the loop below reads plain names (numba resolves the record fields at compile time)
    t, gyro, accel = grids.t, grids.gyro, grids.accel
    grid_of, out_of, n_grid, n_out = grids.grid_of, grids.out_of, grids.n_grid, grids.n_out
    cov_out_of, n_cov_out = grids.cov_out_of, grids.n_cov_out
    gap_step, gap_rp = grids.gap_step, grids.gap_rp
    lla0, v0, q0, par0, p0 = init.lla0, init.v0, init.q0, init.par0, init.p0
    heading_known = init.heading_known
    q_diag, tau_g, tau_a, tau_b = noise.q_diag, noise.tau_g, noise.tau_a, noise.tau_b
    tau_h = noise.tau_h
    yaw_unknown_var, tilt_rate_sd = noise.yaw_unknown_var, noise.tilt_rate_sd
    b_prior_var = noise.b_prior_var
    ev_t, ev_type, ev_idx, max_pending = events.t, events.kind, events.idx, events.max_pending
    g_lla, g_pos_sd, g_vel, g_vel_sd = gnss.lla, gnss.pos_sd, gnss.vel, gnss.vel_sd
    has_vel, lever = gnss.has_vel, gnss.lever
    tr_yaw, tr_speed, tr_sd = gnss.track_yaw, gnss.track_speed, gnss.track_sd
    b_alt, b_sd, h0, has_baro = baro.alt, baro.sd, baro.h0, baro.has_baro
    m_field, m_sd, m_decl, m_floor_var = mag.field, mag.sd_ut, mag.declination, mag.floor_var
    gate_mag, max_consec_mag = mag.gate, mag.max_consec
    gate_pos, gate_vel, gate_v, gate_baro = (settings.gate_pos, settings.gate_vel,
                                             settings.gate_v, settings.gate_baro)
    max_consec, max_consec_baro = settings.max_consec, settings.max_consec_baro
    max_sd_v, probation_s = settings.max_sd_v, settings.probation_s
    heading_v_min, heading_accel = settings.heading_v_min, settings.heading_accel
    align_chunk_s, align_forget_s = settings.align_chunk_s, settings.align_forget_s
    align_sd_max, align_acc_sd = settings.align_sd_max, settings.align_acc_sd
    gap_forget_s, store_rts = settings.gap_forget_s, settings.store_rts

    n = t.size
    # False, typed as a plain bool: a literal False argument compiles vector_update a second
    # time (1.5 s of a first run)
    no_force = n < 0
    out_lla = np.empty((n_out, 3))
    out_v = np.empty((n_out, 3))
    out_q = np.empty((n_out, 4))
    out_par = np.empty((n_out, NPAR))
    cov_out = np.empty((n_cov_out, NPACK))
    ks = n_grid if store_rts else 1
    rts_p = np.zeros((ks, NPACK))
    rts_ing = np.zeros((ks, NING))
    rts_q = np.zeros((ks, NX))
    corr = np.zeros((ks, NX))
    reset_at = np.full(n_grid, np.nan)
    ng = g_lla.shape[0]
    nb = b_alt.size
    inn_pos = np.full((ng, 3), np.nan)
    inn_vel = np.full((ng, 3), np.nan)
    inn_baro = np.full(nb, np.nan)
    rej_pos = np.zeros(ng, dtype=np.bool_)
    rej_vel = np.zeros(ng, dtype=np.bool_)
    rej_baro = np.zeros(nb, dtype=np.bool_)
    nm = m_field.shape[0]
    inn_mag = np.full(nm, np.nan)
    rej_mag = np.zeros(nm, dtype=np.bool_)
    consec_mag = 0

    lla = lla0.copy()
    v = v0.copy()
    q = q0.copy()
    par = par0.copy()
    p = p0.copy()
    heading_ok = heading_known
    t_heading = t[0] if heading_known else np.nan
    consec_pos = 0
    v_gate = np.array([0.0, 0.0, np.nan])  # nav.gnss_gate state
    consec_baro = 0
    rej_v = np.zeros(ng, dtype=np.bool_)

    # pending measurements of the current grid interval
    pend_type = np.zeros(max_pending, dtype=np.int64)
    pend_idx = np.zeros(max_pending, dtype=np.int64)
    pend_t = np.zeros(max_pending)
    pend_y = np.zeros((max_pending, 6))
    pend_h = np.zeros((max_pending, 6, NX))
    pend_r = np.zeros((max_pending, 6))
    pend_m = np.zeros(max_pending, dtype=np.int64)
    n_pend = 0
    reset_delta = np.nan
    reset_sd = 0.0
    # heading from acceleration matching (module docstring): specific-force integral in the
    # nominal frame since the last GNSS velocity fix, current chunk, weighted sums
    sf_acc = np.zeros(2)
    s_i = np.zeros(2)
    ch_u = np.zeros(2)
    ch_w = np.zeros(2)
    ch_t = 0.0
    al_dot = 0.0
    al_cross = 0.0
    al_uu = 0.0
    al_n = 0
    prev_vfix = -1
    pend_tv = 0.0

    # interval accumulators
    acc_fn = np.zeros(3)
    acc_fb = np.zeros(3)
    acc_n = 0
    t_prev_grid = t[0]
    je = 0
    while je < ev_t.size and ev_t[je] <= t[0]:
        je += 1

    if out_of[0] >= 0:
        o = out_of[0]
        put(out_lla[o], lla)
        put(out_v[o], v)
        put(out_q[o], q)
        put(out_par[o], par)
    if grid_of[0] >= 0:
        if store_rts:
            pack(p, rts_p[0])
        if cov_out_of[0] >= 0:
            pack(p, cov_out[cov_out_of[0]])

    for i in range(n - 1):
        dt = t[i + 1] - t[i]
        sc = 1.0 / (1.0 + par[PKA:PKA + 3])
        w0 = gyro[i] - par[PBG:PBG + 3]
        w1 = gyro[i + 1] - par[PBG:PBG + 3]
        f0 = (accel[i] - par[PBA:PBA + 3]) * sc
        f1 = (accel[i + 1] - par[PBA:PBA + 3]) * sc
        lla_p, v_p, q_p = lla, v, q
        if gap_step[i]:
            # IMU gap: constant velocity and attitude (module docstring)
            rn0, re0 = radii_scalar(lla_p[0])
            lla = lla_p.copy()
            lla[0] += v_p[0] * dt / (rn0 + lla_p[2])
            lla[1] += v_p[1] * dt / ((re0 + lla_p[2]) * np.cos(lla_p[0]))
            lla[2] -= v_p[2] * dt
            v = v_p.copy()
            # re-levelled from the first samples after the gap, yaw kept
            q = rpy_quat(gap_rp[i + 1, 0], gap_rp[i + 1, 1], _yaw(q_p))
            if dt >= gap_forget_s:
                # long gap: the vehicle may have turned (Loiter_RTL: a crash); the heading is
                # re-acquired afterwards (module docstring)
                heading_ok = False
                reset_delta = np.nan
            # acceleration matching restarts after a gap (no specific force over it)
            s_i[:] = 0.0
            sf_acc[:] = 0.0
            ch_u[:] = 0.0
            ch_w[:] = 0.0
            ch_t = 0.0
            prev_vfix = -1
        else:
            lla, v, q = strapdown_step(lla_p, v_p, q_p, w0, w1, f0, f1, dt)
            fm = 0.5 * (f0 + f1)
            acc_fb += fm
            fnm = quat_to_dcm(q) @ fm
            acc_fn += fnm
            acc_n += 1
            s_i[0] = fnm[0] * dt
            s_i[1] = fnm[1] * dt
            sf_acc += s_i

        # measurements with time in (t_i, t_{i+1}]: predict from the interpolated nominal
        while je < ev_t.size and ev_t[je] <= t[i + 1]:
            tm = ev_t[je]
            al = (tm - t[i]) / dt
            lm = (1.0 - al) * lla_p + al * lla
            vm = (1.0 - al) * v_p + al * v
            qm = q if al > 0.5 else q_p
            cm = quat_to_dcm(qm)
            rn, re = radii_scalar(lm[0])
            idx = ev_idx[je]
            if ev_type[je] == 0:
                # GNSS antenna position: r + C l ; innovation in NED metres
                d = cm @ lever
                y = np.zeros(6)
                hm = np.zeros((6, NX))
                r = np.zeros(6)
                y[0] = -(g_lla[idx, 0] - lm[0]) * (rn + lm[2]) + d[0]
                y[1] = -(g_lla[idx, 1] - lm[1]) * (re + lm[2]) * np.cos(lm[0]) + d[1]
                # down: −h + (C l)_D + ĝ (GNSS height error state, zero variance when off)
                y[2] = (g_lla[idx, 2] - lm[2]) + d[2] + par[PGH]
                sk = skew3(d)
                lev2 = 0.0 if heading_ok else lever @ lever
                for a in range(3):
                    hm[a, IPOS + a] = 1.0
                    for b in range(3):
                        hm[a, IATT + b] = -sk[a, b]
                    r[a] = g_pos_sd[idx, a] ** 2 + lev2
                hm[2, IGH] = 1.0
                mm = 3
                if has_vel:
                    w_ie, w_en = nav_rates(lm[0], lm[2], vm)
                    # (w_ie + w_en) @ cm is cm.T @ (...) and cross3 np.cross: the same
                    # numbers without two more compiled specialisations (~4 s of a first run)
                    wnb = 0.5 * (w0 + w1) - (w_ie + w_en) @ cm
                    u = cm @ cross3(wnb, lever)
                    su = skew3(u)
                    cl = cm @ skew3(lever)
                    for a in range(3):
                        y[3 + a] = vm[a] + u[a] - g_vel[idx, a]
                        hm[3 + a, IVEL + a] = 1.0
                        for b in range(3):
                            hm[3 + a, IATT + b] = -su[a, b]
                            hm[3 + a, IBG + b] = cl[a, b]
                        r[3 + a] = g_vel_sd[idx, a] ** 2
                    mm = 6
                if not heading_ok:
                    for a in range(6):
                        hm[a, IATT + 2] = 0.0
                if not heading_ok and heading_accel and has_vel:
                    # acceleration matching: W = R_z(δ) U per chunk of ≥ align_chunk_s
                    u_part = sf_acc - (1.0 - al) * s_i
                    sf_acc = (1.0 - al) * s_i
                    if prev_vfix >= 0:
                        dtf = tm - pend_tv
                        ch_u += u_part
                        for a in range(2):
                            ch_w[a] += g_vel[idx, a] - g_vel[prev_vfix, a]
                        ch_t += dtf
                        if ch_t >= align_chunk_s:
                            sv2 = 0.5 * (g_vel_sd[idx, 0] ** 2 + g_vel_sd[idx, 1] ** 2
                                         + g_vel_sd[prev_vfix, 0] ** 2
                                         + g_vel_sd[prev_vfix, 1] ** 2)
                            var = sv2 + (align_acc_sd * ch_t) ** 2
                            uu = ch_u[0] ** 2 + ch_u[1] ** 2
                            ww = ch_w[0] ** 2 + ch_w[1] ** 2
                            # rotation keeps the norm: a chunk whose |W| and |U| disagree
                            # by > 4σ is a GNSS velocity fault, not information
                            if abs(np.sqrt(ww) - np.sqrt(uu)) <= 4.0 * np.sqrt(var):
                                fg = np.exp(-ch_t / align_forget_s)
                                al_dot = fg * al_dot + (ch_u[0] * ch_w[0]
                                                        + ch_u[1] * ch_w[1]) / var
                                al_cross = fg * al_cross + (ch_u[0] * ch_w[1]
                                                            - ch_u[1] * ch_w[0]) / var
                                al_uu = fg * al_uu + uu / var
                                al_n += 1
                            ch_u[:] = 0.0
                            ch_w[:] = 0.0
                            ch_t = 0.0
                            sd_al = 1.0 / np.sqrt(max(al_uu, 1e-12))
                            if al_n >= 3 and sd_al <= align_sd_max and np.isnan(reset_delta):
                                reset_delta = np.arctan2(al_cross, al_dot)
                                reset_sd = 2.0 * sd_al
                    prev_vfix = idx
                    pend_tv = tm
                elif not heading_ok:
                    # the course is the heading only when moving and known well enough
                    if (tr_speed[idx] > heading_v_min and tr_sd[idx] <= align_sd_max
                            and np.isnan(reset_delta)):
                        dlt = tr_yaw[idx] - _yaw(qm)
                        reset_delta = np.arctan2(np.sin(dlt), np.cos(dlt))
                        reset_sd = tr_sd[idx]
            elif ev_type[je] == 1:
                hb = lm[2]
                vup = -vm[2]
                y = np.zeros(6)
                hm = np.zeros((6, NX))
                r = np.zeros(6)
                y[0] = baro_predict(hb, vup, par[PSC], par[PTD], par[PBB], h0) - b_alt[idx]
                jb = baro_row(hb, vup, par[PSC], par[PTD], h0)
                hm[0, IPOS + 2] = -jb[0]
                hm[0, IVEL + 2] = -jb[1]
                hm[0, ISC] = jb[2]
                hm[0, ITD] = jb[3]
                hm[0, IBB] = jb[4]
                r[0] = b_sd * b_sd
                mm = 1
            else:
                # magnetometer heading (sensors.magnetometer): azimuth of the bias-corrected
                # field in n minus the declination; it acquires an unknown heading directly
                y = np.zeros(6)
                hm = np.zeros((6, NX))
                r = np.zeros(6)
                mm = 0
                res_m, h_psi, h_bias, hor = mag_heading_row(
                    m_field[idx], par[PMB:PMB + 3].copy(), cm, m_decl)
                if hor >= MIN_HORIZONTAL_UT:
                    r[0] = (m_sd / hor) ** 2 + m_floor_var
                    if heading_ok:
                        y[0] = res_m
                        for a in range(3):
                            hm[0, IATT + a] = h_psi[a]
                            hm[0, IMB + a] = h_bias[a]
                        mm = 1
                    elif np.isnan(reset_delta):
                        # σ of the acquired heading: noise, the hard-iron prior and the tilt
                        var = r[0]
                        for a in range(3):
                            var += h_bias[a] ** 2 * p[IMB + a, IMB + a]
                        for a in range(2):
                            for b in range(2):
                                var += h_psi[a] * p[IATT + a, IATT + b] * h_psi[b]
                        reset_delta = -res_m
                        reset_sd = np.sqrt(var)
            if mm > 0 and n_pend < max_pending:
                pend_type[n_pend] = ev_type[je]
                pend_idx[n_pend] = idx
                pend_t[n_pend] = tm
                put(pend_y[n_pend], y)
                put(pend_h[n_pend], hm)
                put(pend_r[n_pend], r)
                pend_m[n_pend] = mm
                n_pend += 1
            je += 1

        k = grid_of[i + 1]
        if k >= 0:
            dtg = t[i + 1] - t_prev_grid
            ing = np.zeros(NING)
            put(ing[0:9], quat_to_dcm(q).copy().reshape(9))
            put(ing[9:12], acc_fn / max(acc_n, 1))
            put(ing[12:15], acc_fb / max(acc_n, 1))
            ing[15] = lla[0]
            ing[16] = lla[2]
            put(ing[17:20], v)
            ing[20] = 0.0 if heading_ok else 1.0
            ing[21] = dtg
            ing[22] = 1.0 if gap_step[i] else 0.0
            fmat = build_f(ing, tau_g, tau_a, tau_b, tau_h)
            phi = step_phi(ing, tau_g, tau_a, tau_b, tau_h)
            qd = q_diag[k].copy()
            if gap_step[i] and not heading_ok:
                qd[IATT + 2] = yaw_unknown_var
            if not heading_ok:
                el = t[i + 1] - t[0]
                qd[IATT] += 2.0 * tilt_rate_sd**2 * el * dtg
                qd[IATT + 1] += 2.0 * tilt_rate_sd**2 * el * dtg
                fh2 = ing[9] ** 2 + ing[10] ** 2
                qd[IVEL] += 8.0 * fh2 * dtg * dtg
                qd[IVEL + 1] += 8.0 * fh2 * dtg * dtg
            p = phi @ p @ phi.T
            for a in range(NX):
                p[a, a] += qd[a]
            # the nominal Gauss-Markov states follow the same model as their errors (Φ's
            # −1/τ): b ← exp(−Δt/τ)·b. Held constant, the mean of a Gauss-Markov bias would
            # not follow the model the covariance assumes; the graph's bias link decays it
            # alike (sensors.noise.imu_bias_step)
            decay_gm(par, dtg, tau_g, tau_a, tau_b, tau_h)
            if not heading_ok and not np.isnan(reset_delta):
                # heading acquired from the GNSS track: reset yaw, rotate tilt covariance
                jr = reset_jacobian(reset_delta)
                p = jr @ p @ jr.T
                p[IATT + 2, IATT + 2] = reset_sd**2
                qz = np.array([np.cos(0.5 * reset_delta), 0.0, 0.0, np.sin(0.5 * reset_delta)])
                q = quat_mul(qz, q)
                q /= np.sqrt(np.sum(q * q))
                qd[IATT + 2] = reset_sd**2
                reset_at[k] = reset_delta
                heading_ok = True
                t_heading = t[i + 1]
                reset_delta = np.nan
            if store_rts:
                put(rts_ing[k], ing)
                put(rts_q[k], qd)
            # measurement updates at the grid epoch
            dx = np.zeros(NX)
            for e in range(n_pend):
                mm = pend_m[e]
                idx = pend_idx[e]
                lag = t[i + 1] - pend_t[e]
                back = np.eye(NX) - fmat * lag
                heff = pend_h[e, :mm] @ back
                if lag > 0.0:
                    # process noise between t_m and t_k enters the measurement:
                    # R_eff = R + diag(H Q(t_m→t_k) Hᵀ), Q(t_m→t_k) ≈ Q_k · lag/Δt_k
                    for a in range(mm):
                        extra = 0.0
                        for b in range(NX):
                            extra += heff[a, b] ** 2 * qd[b]
                        pend_r[e, a] += extra * lag / dtg
                if pend_type[e] == 0:
                    # horizontal pair: after max_consec refusals a position jump of the
                    # observed size is added to P and Q (horizontal re-initialisation, no leak
                    # into tilt / vertical through stale correlations), until a fix passes
                    force_h = consec_pos >= max_consec
                    if force_h:
                        for a in range(2):
                            nu_a = pend_y[e, a] - heff[a] @ dx
                            p[IPOS + a, IPOS + a] += nu_a * nu_a
                            if store_rts:
                                rts_q[k, IPOS + a] += nu_a * nu_a
                    ok, nis, nrm = vector_update(
                        p, dx, heff[:2].copy(), pend_y[e, :2].copy(), pend_r[e, :2].copy(),
                        gate_pos, force_h)
                    put(inn_pos[idx, :2], nrm)
                    rej_pos[idx] = not ok
                    consec_pos = 0 if nis <= gate_pos else consec_pos + 1
                    # height: fault detection and exclusion (module docstring)
                    hv = heff[2].copy()
                    rv = pend_r[e, 2]
                    nu_v = pend_y[e, 2] - hv @ dx
                    s_v = hv @ p @ hv + rv
                    inn_pos[idx, 2] = -nu_v / np.sqrt(s_v)
                    usable = g_pos_sd[idx, 2] <= max_sd_v
                    code = height_gate(v_gate, pend_t[e], usable, nu_v * nu_v, s_v, gate_v,
                                       probation_s, max_consec, b_prior_var, not has_baro)
                    use_v = code != REFUSE
                    if use_v:
                        if code == USE_INFLATE:
                            p[IBB, IBB] += b_prior_var
                        scalar_update(p, dx, hv, pend_y[e, 2], rv)
                    else:
                        rej_v[idx] = True
                        rej_pos[idx] = True
                    if mm == 6:
                        ok, nis, nrm = vector_update(
                            p, dx, heff[3:5].copy(), pend_y[e, 3:5].copy(),
                            pend_r[e, 3:5].copy(), gate_vel, no_force)
                        put(inn_vel[idx, :2], nrm)
                        rej_vel[idx] = not ok
                        if use_v:
                            ok, nis, nrm = vector_update(
                                p, dx, heff[5:6].copy(), pend_y[e, 5:6].copy(),
                                pend_r[e, 5:6].copy(), gate_v, no_force)
                            inn_vel[idx, 2] = nrm[0]
                            rej_vel[idx] = rej_vel[idx] or not ok
                        else:
                            rej_vel[idx] = True
                elif pend_type[e] == 1:
                    ok, nis, nrm = vector_update(
                        p, dx, heff[:1].copy(), pend_y[e, :1].copy(), pend_r[e, :1].copy(),
                        gate_baro, consec_baro >= max_consec_baro)
                    inn_baro[idx] = nrm[0]
                    rej_baro[idx] = not ok
                    consec_baro = 0 if nis <= gate_baro else consec_baro + 1
                else:
                    ok, nis, nrm = vector_update(
                        p, dx, heff[:1].copy(), pend_y[e, :1].copy(), pend_r[e, :1].copy(),
                        gate_mag, consec_mag >= max_consec_mag)
                    inn_mag[idx] = nrm[0]
                    rej_mag[idx] = not ok
                    consec_mag = 0 if nis <= gate_mag else consec_mag + 1
            n_pend = 0
            apply_correction(lla, v, q, par, dx)
            if store_rts:
                put(corr[k], dx)
                pack(p, rts_p[k])
            if cov_out_of[k] >= 0:
                pack(p, cov_out[cov_out_of[k]])
            acc_fn[:] = 0.0
            acc_fb[:] = 0.0
            acc_n = 0
            t_prev_grid = t[i + 1]

        o = out_of[i + 1]
        if o >= 0:
            put(out_lla[o], lla)
            put(out_v[o], v)
            put(out_q[o], q)
            put(out_par[o], par)

    return (out_lla, out_v, out_q, out_par, cov_out, rts_p, rts_ing, rts_q, corr, reset_at,
            inn_pos, inn_vel, inn_baro, rej_pos, rej_vel, rej_baro, t_heading, rej_v,
            inn_mag, rej_mag)
