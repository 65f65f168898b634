"""The forward EKF kernel: one compiled pass over the whole drive (``run_filter``).

The error-state model, its measurement rows and the update steps it calls are in
``ekf.model`` (whose docstring describes the filter); this module holds only the loop that
strings them together, a documented numba kernel kept whole so that it compiles once.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ...geo.earth import radii_scalar
from ...nav.gnss_gate import REFUSE, USE_INFLATE, height_gate
from ...nav.rotations import quat_mul, quat_to_dcm, rpy_quat, skew3
from ...nav.rotations import yaw_of as _yaw
from .model import (
    IATT,
    IBB,
    IBG,
    IPOS,
    ISC,
    ITD,
    IVEL,
    NING,
    NPACK,
    NX,
    PBA,
    PBB,
    PBG,
    PKA,
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
from .strapdown import nav_rates, strapdown_step


@njit(cache=True)
def run_filter(
    t, gyro, accel, grid_of, out_of, n_grid, n_out, cov_out_of, n_cov_out,
    lla0, v0, q0, par0, p0, q_diag,
    tau_g, tau_a, tau_b,
    ev_t, ev_type, ev_idx,
    g_lla, g_pos_sd, g_vel, g_vel_sd, has_vel, lever, tr_yaw, tr_speed, tr_sd,
    b_alt, b_sd, h0,
    gate_pos, gate_vel, gate_baro, max_consec,
    heading_known, heading_v_min, yaw_unknown_var, tilt_rate_sd,
    max_pending, store_rts,
    gate_v, max_sd_v, probation_s, has_baro, b_prior_var, gap_step, gap_rp, max_consec_baro,
    heading_accel, align_chunk_s, align_forget_s, align_sd_max, align_acc_sd,
    gap_forget_s,
):
    """Forward error-state EKF over the whole drive (see module docstring).

    ``grid_of[i]`` / ``out_of[i]`` / ``cov_out_of[k]``: slot of IMU sample i in the grid / the
    output trajectory (−1 if none), of grid epoch k in the covariance output. ``ev_*``: merged
    measurement events sorted by time (type 0 GNSS fix, 1 baro sample). ``gate_pos`` /
    ``gate_vel``: χ²₂ gates of the horizontal pairs, ``gate_v`` / ``gate_baro``: χ²₁ gates;
    ``gap_step[i]``: IMU interval i → i+1 is a gap (a grid interval of its own). Returns the output
    trajectory, packed covariances and, when ``store_rts``, what the RTS smoother needs.
    """
    n = t.size
    out_lla = np.empty((n_out, 3))
    out_v = np.empty((n_out, 3))
    out_q = np.empty((n_out, 4))
    out_par = np.empty((n_out, 12))
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
        out_lla[o], out_v[o], out_q[o], out_par[o] = lla, v, q, par
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
                y[2] = (g_lla[idx, 2] - lm[2]) + d[2]
                sk = skew3(d)
                lev2 = 0.0 if heading_ok else lever @ lever
                for a in range(3):
                    hm[a, IPOS + a] = 1.0
                    for b in range(3):
                        hm[a, IATT + b] = -sk[a, b]
                    r[a] = g_pos_sd[idx, a] ** 2 + lev2
                mm = 3
                if has_vel:
                    w_ie, w_en = nav_rates(lm[0], lm[2], vm)
                    wnb = 0.5 * (w0 + w1) - cm.T @ (w_ie + w_en)
                    u = cm @ np.cross(wnb, lever)
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
                    if tr_speed[idx] > heading_v_min and np.isnan(reset_delta):
                        dlt = tr_yaw[idx] - _yaw(qm)
                        reset_delta = np.arctan2(np.sin(dlt), np.cos(dlt))
                        reset_sd = tr_sd[idx]
            else:
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
            if n_pend < max_pending:
                pend_type[n_pend] = ev_type[je]
                pend_idx[n_pend] = idx
                pend_t[n_pend] = tm
                pend_y[n_pend] = y
                pend_h[n_pend] = hm
                pend_r[n_pend] = r
                pend_m[n_pend] = mm
                n_pend += 1
            je += 1

        k = grid_of[i + 1]
        if k >= 0:
            dtg = t[i + 1] - t_prev_grid
            ing = np.zeros(NING)
            ing[0:9] = quat_to_dcm(q).copy().reshape(9)
            ing[9:12] = acc_fn / max(acc_n, 1)
            ing[12:15] = acc_fb / max(acc_n, 1)
            ing[15] = lla[0]
            ing[16] = lla[2]
            ing[17:20] = v
            ing[20] = 0.0 if heading_ok else 1.0
            ing[21] = dtg
            ing[22] = 1.0 if gap_step[i] else 0.0
            fmat = build_f(ing, tau_g, tau_a, tau_b)
            phi = step_phi(ing, tau_g, tau_a, tau_b)
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
                rts_ing[k] = ing
                rts_q[k] = qd
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
                    inn_pos[idx, :2] = nrm
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
                            pend_r[e, 3:5].copy(), gate_vel, False)
                        inn_vel[idx, :2] = nrm
                        rej_vel[idx] = not ok
                        if use_v:
                            ok, nis, nrm = vector_update(
                                p, dx, heff[5:6].copy(), pend_y[e, 5:6].copy(),
                                pend_r[e, 5:6].copy(), gate_v, False)
                            inn_vel[idx, 2] = nrm[0]
                            rej_vel[idx] = rej_vel[idx] or not ok
                        else:
                            rej_vel[idx] = True
                else:
                    ok, nis, nrm = vector_update(
                        p, dx, heff[:1].copy(), pend_y[e, :1].copy(), pend_r[e, :1].copy(),
                        gate_baro, consec_baro >= max_consec_baro)
                    inn_baro[idx] = nrm[0]
                    rej_baro[idx] = not ok
                    consec_baro = 0 if nis <= gate_baro else consec_baro + 1
            n_pend = 0
            apply_correction(lla, v, q, par, dx)
            if store_rts:
                corr[k] = dx
                pack(p, rts_p[k])
            if cov_out_of[k] >= 0:
                pack(p, cov_out[cov_out_of[k]])
            acc_fn[:] = 0.0
            acc_fb[:] = 0.0
            acc_n = 0
            t_prev_grid = t[i + 1]

        o = out_of[i + 1]
        if o >= 0:
            out_lla[o], out_v[o], out_q[o], out_par[o] = lla, v, q, par

    return (out_lla, out_v, out_q, out_par, cov_out, rts_p, rts_ing, rts_q, corr, reset_at,
            inn_pos, inn_vel, inn_baro, rej_pos, rej_vel, rej_baro, t_heading, rej_v)
