"""Numba kernels of the IMU-shaped interpolant between keyframes
(``interval_factors.DenseIncrements.at`` and ``interval_factors.interpolate``): one pass over
the query times instead of ~40 numpy temporaries of the queries' length. They are evaluated at
every baro sample and GNSS fix in every Gauss-Newton iteration (~0.3 s per iteration-hour of
drive in numpy; the formulas and their order of operations are those of the numpy form they
replace)."""

from __future__ import annotations

import numpy as np
from numba import njit

from ....nav.rotations import quat_to_dcm_into


@njit(cache=True)
def increments_at(t, kf_idx, qr, dv, dp, dv_end, dp_end, t_q, k):  # pragma: no cover - jit
    """ΔR (nearest earlier sample), Δv and Δp (cubic Hermite through the neighbouring
    samples' (Δp, Δv)) of interval ``k[i]`` at ``t_q[i]``; arrays as in ``DenseIncrements``
    (ΔR as unit quaternions ``qr``). Returns (M, 3, 3), (M, 3), (M, 3)."""
    m = t_q.size
    dr_q = np.empty((m, 3, 3))
    dv_q = np.empty((m, 3))
    dp_q = np.empty((m, 3))
    j_all = np.searchsorted(t, t_q, side="right") - 1
    for i in range(m):
        ki = k[i]
        j = min(max(j_all[i], kf_idx[ki]), kf_idx[ki + 1] - 1)
        h = t[j + 1] - t[j]
        w = min(max((t_q[i] - t[j]) / h, 0.0), 1.0)
        w2 = w * w
        w3 = w * w * w
        at_end = j + 1 == kf_idx[ki + 1]
        c0 = 2 * w3 - 3 * w2 + 1
        c1 = w3 - 2 * w2 + w
        c2 = 3 * w2 - 2 * w3
        c3 = w3 - w2
        e0 = 6 * w2 - 6 * w
        e1 = 3 * w2 - 4 * w + 1
        e2 = 6 * w - 6 * w2
        e3 = 3 * w2 - 2 * w
        for a in range(3):
            v_next = dv_end[ki, a] if at_end else dv[j + 1, a]
            p_next = dp_end[ki, a] if at_end else dp[j + 1, a]
            p0 = dp[j, a]
            v0 = dv[j, a] * h
            v1 = v_next * h
            dp_q[i, a] = c0 * p0 + c1 * v0 + c2 * p_next + c3 * v1
            dv_q[i, a] = (e0 * p0 + e1 * v0 + e2 * p_next + e3 * v1) / h
        quat_to_dcm_into(qr[j], dr_q[i])
    return dr_q, dv_q, dp_q


@njit(cache=True)
def interpolant(t_kf, dv_end, dp_end, gap, dr_q, dv_q, dp_q, t_q, k, pos, rot, bias_accel,
                accel_t, with_rot):  # pragma: no cover - jit
    """Position p(t), velocity v(t) and (``with_rot``) attitude R(t) between keyframes k[i]
    and k[i]+1 at ``t_q[i]`` from the increments (``increments_at``), first-order corrected
    for the keyframe's accelerometer bias, plus α, d, δv, T, τ and the IMU flag the
    Jacobians need; ``gap`` (K−1,) bool: intervals holding an IMU logging gap (the straight
    line between the keyframes, attitude R_k, no bias dependence)."""
    m = t_q.size
    p = np.empty((m, 3))
    v = np.empty((m, 3))
    rot_q = np.empty((m if with_rot else 0, 3, 3))
    alpha = np.empty(m)
    d = np.empty((m, 3))
    dvel = np.empty((m, 3))
    big_t = np.empty(m)
    tau = np.empty(m)
    imu = np.ones(m)
    dd = np.empty(3)
    dve = np.empty(3)
    for i in range(m):
        ki = k[i]
        T = t_kf[ki + 1] - t_kf[ki]
        ta = t_q[i] - t_kf[ki]
        al = ta / T
        g = gap[ki]
        for a in range(3):
            ba = bias_accel[ki, a]
            dp_c = dp_q[i, a] - 0.5 * ta**2 * ba
            dv_c = dv_q[i, a] - ta * ba
            dp_end_c = dp_end[ki, a] - 0.5 * T**2 * ba
            dd[a] = 0.0 if g else dp_c - al * dp_end_c
            dve[a] = 0.0 if g else dv_c - dp_end_c / T
        for a in range(3):
            acc = 0.0 if g else accel_t[ki, a]
            rd = rot[ki, a, 0] * dd[0] + rot[ki, a, 1] * dd[1] + rot[ki, a, 2] * dd[2]
            rv = rot[ki, a, 0] * dve[0] + rot[ki, a, 1] * dve[1] + rot[ki, a, 2] * dve[2]
            p[i, a] = ((1 - al) * pos[ki, a] + al * pos[ki + 1, a]
                       + 0.5 * acc * (ta**2 - ta * T) + rd)
            v[i, a] = (pos[ki + 1, a] - pos[ki, a]) / T + acc * (ta - 0.5 * T) + rv
            d[i, a] = dd[a]
            dvel[i, a] = dve[a]
            if with_rot:
                for b in range(3):
                    if g:
                        rot_q[i, a, b] = rot[ki, a, b]
                    else:
                        rot_q[i, a, b] = (rot[ki, a, 0] * dr_q[i, 0, b]
                                          + rot[ki, a, 1] * dr_q[i, 1, b]
                                          + rot[ki, a, 2] * dr_q[i, 2, b])
        alpha[i] = al
        big_t[i] = T
        tau[i] = ta
        if g:
            imu[i] = 0.0
    return p, v, rot_q, alpha, d, dvel, big_t, tau, imu
