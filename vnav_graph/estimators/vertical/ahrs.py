"""Numba kernels of the GNSS-aided AHRS that feeds the classical vertical estimators.

The method, its parameters and its tested accuracy are described in docs/vertical_loops.md §1
(``vertical.inputs`` assembles the kernel inputs and owns ``AhrsConfig``); this module holds
only the compiled loops: ``ahrs_kernel`` (levelling, gyro integration with the shared strapdown
step, velocity-matching tilt feedback, gap handling) and ``poly_velocity`` (GNSS velocity from
positions)."""

from __future__ import annotations

from collections import namedtuple

import numpy as np
from numba import njit

from ...nav.arrays import outer, put
from ...nav.rotations import quat_exp, quat_mul, quat_to_dcm
from ...nav.rotations import rpy_quat as _rpy_quat
from ...nav.strapdown import strapdown_step


@njit(cache=True)
def _wrap_nb(a):
    return (a + np.pi) % (2.0 * np.pi) - np.pi


@njit(cache=True)
def _clamp(x, m):
    return m if x > m else (-m if x < -m else x)


@njit(cache=True)
def _across_gap(q_k, relevel_k):
    """Attitude after an IMU logging gap: roll/pitch re-levelled from the static samples after
    it (``relevel_k`` finite) with the yaw kept, else the attitude held."""
    if np.isfinite(relevel_k[0]):
        c0 = quat_to_dcm(q_k)
        return _rpy_quat(relevel_k[0], relevel_k[1], np.arctan2(c0[1, 0], c0[0, 0]))
    return q_k


@njit(cache=True)
def _tilt_update(psi, f_ref, d, r_j, r_nom, dtg, t_filt, max_corr, max_fb):
    """Velocity-matching tilt feedback (R3), in place on ψ_x, ψ_y: the tilt that turns the
    reference specific force ``f_ref`` by the residual ``d``, low-passed with gain dtg/T_f
    scaled by the inverse-variance weight r_nom / r_j."""
    cr = np.array([f_ref[1] * d[2] - f_ref[2] * d[1],
                   f_ref[2] * d[0] - f_ref[0] * d[2]])
    nf2 = f_ref[0] ** 2 + f_ref[1] ** 2 + f_ref[2] ** 2
    w = r_nom / r_j if r_j > r_nom else 1.0
    alpha = (dtg / t_filt if dtg < t_filt else 1.0) * w
    for i in range(2):
        p = _clamp(cr[i] / nf2, max_corr)
        psi[i] = _clamp(psi[i] + alpha * (p - psi[i]), max_fb)


@njit(cache=True)
def _accel_level(psi, fm, g_nom, alpha, max_corr, max_fb):
    """Accelerometer levelling (step 6), in place on ψ_x, ψ_y: the mean specific force ``fm``
    of a static window against the reference (0, 0, −g): ψ_x = d_E/g, ψ_y = −d_N/g
    (horizontal residual only), with gain min(alpha, 1)."""
    if alpha > 1.0:
        alpha = 1.0
    p0 = _clamp(fm[1] / g_nom, max_corr)
    p1 = _clamp(-fm[0] / g_nom, max_corr)
    psi[0] = _clamp(psi[0] + alpha * (p0 - psi[0]), max_fb)
    psi[1] = _clamp(psi[1] + alpha * (p1 - psi[1]), max_fb)


@njit(cache=True)
def _heading_feedback(q_next, c1, psi, vc0, vc1, v_thr, trusted, yaw_done, max_corr):
    """The heading step of ``ahrs_kernel``: with a course (velocity (vc0, vc1) above
    ``v_thr`` and ``trusted``: usable and recently consistent with the IMU) the first time,
    the yaw of ``q_next`` (attitude c1) is reset to it (in place); afterwards ψ_z is the
    yaw minus the course (clamped); without a course ψ_z = 0. Returns (yaw done, reset now)."""
    if np.sqrt(vc0 ** 2 + vc1 ** 2) > v_thr and trusted:
        course = np.arctan2(vc1, vc0)
        yaw = np.arctan2(c1[1, 0], c1[0, 0])
        if not yaw_done:
            dq = quat_exp(np.array([0.0, 0.0, _wrap_nb(course - yaw)]))
            put(q_next, quat_mul(dq, q_next))
            psi[2] = 0.0
            return True, True
        psi[2] = _clamp(_wrap_nb(yaw - course), max_corr)
        return True, False
    psi[2] = 0.0
    return yaw_done, False


@njit(cache=True)
def _gate(nu2, gate2, n_rej, t_rej0, t_j, reinit_s, cnt):
    """R2's χ²₂ gate on a levelling residual (``nu2``: its normalised square): accepted
    below ``gate2``; refused otherwise, unless refusals have spanned ``reinit_s`` (then
    accepted: a real drift cannot lock the GNSS out). Counts in ``cnt`` [1] refused, [2]
    re-initialised. Returns (accept, refusals in a row, time of the first of them)."""
    if nu2 <= gate2:
        return True, n_rej, t_rej0
    if n_rej == 0:
        t_rej0 = t_j
    n_rej += 1
    if n_rej >= 2 and t_j - t_rej0 >= reinit_s:
        cnt[2] += 1
        return True, n_rej, t_rej0
    cnt[1] += 1
    return False, n_rej, t_rej0


AhrsImu = namedtuple("AhrsImu", "t gyro accel q0 relevel")
AhrsImu.__doc__ = """The IMU side of ``ahrs_kernel``: epochs t (N,) [s], gyro (N, 3) [rad/s],
specific force accel (N, 3) [m/s²], start attitude q0 (4,) and relevel (N, 2): roll/pitch from
static samples after an IMU gap ending at that epoch (NaN elsewhere)."""

AhrsFixes = namedtuple("AhrsFixes",
                       "lla_i vel_i sdv_i t_g t_av v_g g_g cor_g ok_g r_g vert_g use_g")
AhrsFixes.__doc__ = """The GNSS side of ``ahrs_kernel`` (``gnss_reference.Matching``).

lla_i, vel_i (N, 3): the last GNSS position / known velocity at or before each IMU epoch
(latitude, height; vertical velocity); sdv_i (N,) horizontal velocity σ there (inf in
outages: no course); t_g (M,) the (thinned) fixes, t_av (M,) ≥ t_g the time each velocity
is known (t_g for a receiver's, later for a fit over later fixes: the interval ending at
fix j is matched at the first IMU epoch at or after t_av[j]), v_g (M, 3) their reference
velocities, g_g (M,) gravity, cor_g (M, 3) (2ω_ie+ω_en)×v, ok_g (M,) interval [j−1, j]
not across an outage, r_g (M,) horizontal residual variance per axis of that interval
[(m/s²)²], vert_g (M,) its vertical component is trusted, use_g (M,) the fix's velocity is
usable (σ ≤ sd_v_max)."""

AhrsGains = namedtuple("AhrsGains", "kp ki k_yaw ki_yaw v_min max_corr max_fb a_static t_filt "
                       "gap gate2 sd0 sd_bg sd_yaw r_nom reinit_s fb_after lvl_win lvl_tau "
                       "st_rate st_acc g_nom imu_gap")
AhrsGains.__doc__ = """The settings of ``ahrs_kernel`` (``inputs.AhrsConfig`` turned into
gains, SI units, all floats)."""


@njit(cache=True)
def ahrs_kernel(imu, fixes, gains):
    """Numba kernel (docs/vertical_loops.md §1, steps 2-8) on three records: ``imu`` (``AhrsImu``:
    the IMU samples, the start attitude and the re-levelling after gaps), ``fixes``
    (``AhrsFixes``: the GNSS reference) and ``gains`` (``AhrsGains``: the settings). The
    course is that of the propagated velocity after the yaw reset while fixes renew it,
    else ``vel_i``'s. Returns q (N, 4), f_n (N, 3), b̂_g (N, 3), propagated horizontal
    velocity (N, 2) and the counters [accepted, rejected, reinit, unusable, vertical
    dropped, accel-level, imu gaps]."""
    t, gyro, accel, q0, relevel = imu
    lla_i, vel_i, sdv_i, t_g, t_av, v_g, g_g, cor_g, ok_g, r_g, vert_g, use_g = fixes
    (kp, ki, k_yaw, ki_yaw, v_min, max_corr, max_fb, a_static, t_filt, gap, gate2, sd0, sd_bg,
     sd_yaw, r_nom, reinit_s, fb_after, lvl_win, lvl_tau, st_rate, st_acc, g_nom,
     imu_gap) = gains
    n = t.size
    m = t_g.size
    q = np.empty((n, 4))
    bg_out = np.empty((n, 3))
    f_n = np.empty((n, 3))
    vp_out = np.empty((n, 2))
    cnt = np.zeros(7, dtype=np.int64)
    put(q[0], q0)
    bg = np.zeros(3)
    psi = np.zeros(3)  # current attitude-error estimate (n frame), applied as a rate
    c = quat_to_dcm(q0)
    put(f_n[0], c @ accel[0])
    cum = np.zeros(3)  # ∫ f_n dt from t[0]
    cum_arr = np.zeros((n, 3))  # prefix integral of f_n (for the accelerometer fallback)
    gyr_arr = np.zeros((n, 3))  # prefix integral of the raw gyro
    acc_arr = np.zeros((n, 3))  # prefix integral of the raw specific force
    # horizontal velocity propagated from the last usable GNSS velocity (Coriolis, ω_en)
    vp = np.zeros(2)
    vp_valid = False
    vp_fresh = False  # the last fix processed renewed vp
    j = 0
    while j < m and t_g[j] <= t[0]:
        if use_g[j]:
            vp[0] = v_g[j, 0]
            vp[1] = v_g[j, 1]
            vp_valid = True
        j += 1
    put(vp_out[0], vp)
    f_at_last = np.zeros(3)  # ∫ f_n up to the previous fix time
    have_last = j > 0  # a fix at or before t[0]: integral there is 0
    yaw_done = False
    t_yaw = np.inf  # IMU epoch before the one-time yaw reset (inf: not yet)
    psi_until = -np.inf
    t_acc = t[0]  # last accepted levelling update (GNSS or fallback)
    t_gnss_acc = -np.inf  # last accepted GNSS levelling update
    t_vel_ok = -np.inf  # last fix whose velocity was usable and consistent
    t_gap_end = -np.inf  # end of the last IMU logging gap
    n_rej = 0
    t_rej0 = 0.0
    t_lvl = t[0]
    ks = 0  # start index of the fallback window
    for k in range(n - 1):
        dt = t[k + 1] - t[k]
        c = quat_to_dcm(q[k])
        if t[k] > psi_until:  # no fix for a while (outage): no tilt correction
            psi[0] = 0.0
            psi[1] = 0.0
        # PI feedback, tilt gains (kp, ki) on ψ_x, ψ_y and heading gains (k_yaw, ki_yaw) on ψ_z
        corr_p = c.T @ np.array([kp * psi[0], kp * psi[1], k_yaw * psi[2]])
        corr_i = c.T @ np.array([ki * psi[0], ki * psi[1], ki_yaw * psi[2]])
        vel_k = np.array([vp[0], vp[1], vel_i[k, 2]])
        if dt > imu_gap:
            # logging gap: no rate samples inside it (the vehicle may have been handled,
            # e.g. a crash and restart: docs/real_logs.md, "IMU logging gap across a
            # crash"). Re-level roll/pitch from the
            # samples after the gap when they are static (relevel[k+1] finite), keep the yaw
            # and the bias; otherwise hold the attitude. No velocity matching over any
            # interval that touches the gap.
            put(q[k + 1], _across_gap(q[k], relevel[k + 1]))
            psi[0] = 0.0
            psi[1] = 0.0
            t_gap_end = t[k + 1]
            cnt[6] += 1
        else:
            bg = bg + corr_i * dt
            w0 = gyro[k] - bg - corr_p
            w1 = gyro[k + 1] - bg - corr_p
            _, _, qn = strapdown_step(lla_i[k], vel_k, q[k], w0, w1, accel[k], accel[k + 1],
                                      dt)
            put(q[k + 1], qn)
        put(bg_out[k], bg)
        c1 = quat_to_dcm(q[k + 1])
        put(f_n[k + 1], c1 @ accel[k + 1])
        cum = cum + 0.5 * (f_n[k] + f_n[k + 1]) * dt
        put(cum_arr[k + 1], cum)
        put(gyr_arr[k + 1], gyr_arr[k] + 0.5 * (gyro[k] + gyro[k + 1]) * dt)
        put(acc_arr[k + 1], acc_arr[k] + 0.5 * (accel[k] + accel[k + 1]) * dt)
        if dt <= imu_gap:
            vp[0] += 0.5 * (f_n[k, 0] + f_n[k + 1, 0]) * dt
            vp[1] += 0.5 * (f_n[k, 1] + f_n[k + 1, 1]) * dt
        # heading (``_heading_feedback``): the course of the propagated velocity (the last
        # usable fix's carried to t[k+1]: a held fix lags in turns) once the yaw is reset and
        # the last fix renewed it, else the last fix's (unknown yaw before the reset)
        fresh = yaw_done and vp_fresh
        yaw_done, reset = _heading_feedback(
            q[k + 1], c1, psi, vp[0] if fresh else vel_i[k + 1, 0],
            vp[1] if fresh else vel_i[k + 1, 1], max(v_min, 5.0 * sdv_i[k + 1]),
            t[k + 1] - t_vel_ok <= fb_after, yaw_done, max_corr)
        if reset:
            t_yaw = t[k]  # the fix interval across t[k] mixes two headings
        # tilt: velocity matching at each GNSS fix passed in (t[k], t[k+1]]
        while j < m and t_av[j] <= t[k + 1]:
            # ∫ f_n dt up to the fix time, from the stored prefix integral
            ia = np.searchsorted(t, t_g[j], side="right") - 1
            if ia >= k + 1:
                f_here = cum.copy()
            else:
                a = (t_g[j] - t[ia]) / (t[ia + 1] - t[ia])
                f_here = cum_arr[ia] + a * (cum_arr[ia + 1] - cum_arr[ia])
            skip = j > 0 and t_g[j - 1] <= t_yaw < t_g[j]
            usable = use_g[j] and use_g[j - 1] if j > 0 else False
            if not usable:
                cnt[3] += 1
            elif have_last and ok_g[j] and not skip and t_g[j - 1] >= t_gap_end:
                dtg = t_g[j] - t_g[j - 1]
                f_meas = (f_here - f_at_last) / dtg
                f_ref = (v_g[j] - v_g[j - 1]) / dtg + 0.5 * (cor_g[j] + cor_g[j - 1])
                f_ref[2] -= 0.5 * (g_g[j] + g_g[j - 1])
                if not vert_g[j]:
                    # R5: vertical GNSS component not trusted: nominal vertical specific
                    # force, residual from the horizontal components only
                    f_ref[2] = -0.5 * (g_g[j] + g_g[j - 1])
                    cnt[4] += 1
                d = f_meas - f_ref
                if not vert_g[j]:
                    d[2] = 0.0
                ah2 = f_ref[0] ** 2 + f_ref[1] ** 2
                # before the heading is known a horizontal acceleration would be read as tilt
                # (δf = ψ_z × a_h); then only quasi-static intervals level the platform
                if t_g[j] <= t_yaw and ah2 > a_static**2:
                    psi[0] = 0.0
                    psi[1] = 0.0
                else:
                    # R2: χ²₂ gate on the horizontal residual against its predicted spread
                    sd_t = sd0 + sd_bg * (t_g[j] - t_acc)
                    s_var = r_g[j] + (g_g[j] * sd_t) ** 2 + (sd_yaw**2) * ah2
                    accept, n_rej, t_rej0 = _gate(
                        (d[0] ** 2 + d[1] ** 2) / s_var, gate2, n_rej, t_rej0, t_g[j],
                        reinit_s, cnt)
                    if accept:
                        n_rej = 0
                        cnt[0] += 1
                        _tilt_update(psi, f_ref, d, r_g[j], r_nom, dtg, t_filt, max_corr,
                                     max_fb)
                        psi_until = t_av[j] + gap * dtg
                        t_acc = t_g[j]
                        t_gnss_acc = t_g[j]
                        t_vel_ok = t_g[j]
            if use_g[j] and n_rej == 0:
                # a usable velocity, not inside a run of gate rejections: trusted for the
                # course and as the start of the propagated velocity (Coriolis, ω_en)
                t_vel_ok = t_g[j]
                # propagated from the fix time to this epoch
                vp[0] = v_g[j, 0] + cum[0] - f_here[0]
                vp[1] = v_g[j, 1] + cum[1] - f_here[1]
                vp_valid = True
                vp_fresh = True
            else:
                # a fix came but did not renew the propagated velocity (unusable, or inside
                # a run of gate rejections): the course is that fix's until one does
                vp_fresh = False
            f_at_last = f_here
            have_last = True
            j += 1
        # fallback (step 6): slow accelerometer levelling when GNSS gave nothing usable
        tk = t[k + 1]
        while ks < k + 1 and tk - t[ks + 1] >= lvl_win:
            ks += 1
        if (tk - t_gnss_acc > fb_after and tk - t_lvl >= 0.2 * lvl_win
                and tk - t[ks] >= 0.8 * lvl_win and t[ks] >= t_gap_end):
            t_lvl = tk
            span = tk - t[ks]
            w_m = (gyr_arr[k + 1] - gyr_arr[ks]) / span - bg
            f_b = (acc_arr[k + 1] - acc_arr[ks]) / span
            fbn = np.sqrt(f_b[0] ** 2 + f_b[1] ** 2 + f_b[2] ** 2)
            wn = np.sqrt(w_m[0] ** 2 + w_m[1] ** 2 + w_m[2] ** 2)
            if wn < st_rate and abs(fbn - g_nom) < st_acc:
                _accel_level(psi, (cum_arr[k + 1] - cum_arr[ks]) / span, g_nom,
                             0.2 * lvl_win / lvl_tau, max_corr, max_fb)
                psi_until = tk + 0.4 * lvl_win
                t_acc = tk
                cnt[5] += 1
        put(vp_out[k + 1], vp)
    put(bg_out[n - 1], bg)
    if not vp_valid:
        vp_out[:] = 0.0
    return q, f_n, bg_out, vp_out, cnt


@njit(cache=True)
def poly_velocity(t, p, sd, half, seg):
    """Slope at each fix of a 1/σ²-weighted quadratic fit of p (M, 3) over the fixes of the
    same segment within ±half seconds; σ of the slope from (XᵀWX)⁻¹. NaN where < 3 fixes."""
    m = t.size
    v = np.full((m, 3), np.nan)
    sv = np.full((m, 3), np.inf)
    a = 0
    b = 0
    for j in range(m):
        while t[a] < t[j] - half or seg[a] != seg[j]:
            a += 1
        if b < j:
            b = j
        while b + 1 < m and t[b + 1] <= t[j] + half and seg[b + 1] == seg[j]:
            b += 1
        if b - a + 1 < 3:
            continue
        for ax in range(3):
            xtx = np.zeros((3, 3))
            xty = np.zeros(3)
            for i in range(a, b + 1):
                w = 1.0 / (sd[i, ax] * sd[i, ax])
                dtt = t[i] - t[j]
                x = np.array([1.0, dtt, dtt * dtt])
                xtx += w * outer(x, x)
                xty += w * x * p[i, ax]
            if abs(np.linalg.det(xtx)) < 1e-300:
                continue
            cov = np.linalg.inv(xtx)
            beta = cov @ xty
            v[j, ax] = beta[1]
            sv[j, ax] = np.sqrt(cov[1, 1])
    return v, sv


@njit(cache=True)
def trailing_slope(t_q, t_s, z, window, sd_floor):
    """Slope at each query time t_q of an unweighted quadratic fit of the samples (t_s, z)
    with t_q − window ≤ t_s ≤ t_q (causal: no sample after t_q), its σ
    σ̂·√[(XᵀX)⁻¹]₁₁ with σ̂ = max(√(RSS/(n − 3)), sd_floor) the fit's own residual σ. NaN /
    inf where the window holds fewer than 5 samples or spans less than half its length."""
    q = t_q.size
    rate = np.full(q, np.nan)
    unit_sd = np.full(q, np.inf)
    a = 0
    b = 0
    for j in range(q):
        while a < t_s.size and t_s[a] < t_q[j] - window:
            a += 1
        if b < a:
            b = a
        while b < t_s.size and t_s[b] <= t_q[j]:
            b += 1
        # samples a .. b-1
        if b - a < 5 or t_s[b - 1] - t_s[a] < 0.5 * window:
            continue
        xtx = np.zeros((3, 3))
        xty = np.zeros(3)
        for i in range(a, b):
            dtt = t_s[i] - t_q[j]
            x = np.array([1.0, dtt, dtt * dtt])
            xtx += outer(x, x)
            xty += x * z[i]
        if abs(np.linalg.det(xtx)) < 1e-300:
            continue
        cov = np.linalg.inv(xtx)
        beta = cov @ xty
        rss = 0.0
        for i in range(a, b):
            dtt = t_s[i] - t_q[j]
            r = z[i] - beta[0] - beta[1] * dtt - beta[2] * dtt * dtt
            rss += r * r
        sig = np.sqrt(rss / (b - a - 3))
        rate[j] = beta[1]
        unit_sd[j] = max(sig, sd_floor) * np.sqrt(cov[1, 1])
    return rate, unit_sd
