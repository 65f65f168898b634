"""Numba kernels of the INS/GNSS/baro error-state EKF and its RTS smoother.

Error state δx (27), every component "estimated minus true" (types.ERROR_STATE convention;
the first 18 are exactly the shared layout):

    0:3 δr (NED position [m]), 3:6 δv (NED [m/s]), 6:9 ψ (tilt in n [rad], C̃ = (I+[ψ×]) C),
    9:12 δb_g [rad/s], 12:15 δb_a [m/s²], 15 δs (baro scale), 16 δτ_d [s], 17 δb (baro bias
    [m]), 18:21 δk_a (accelerometer scale factors, f̃ = (1+k_a)∘f + b_a + n), 21:24 δb_m
    (magnetometer hard-iron bias in b [µT], a random walk; ``sensors.magnetometer``), 24:27 δe
    (time-correlated GNSS position error, NED [m], first-order Gauss-Markov per axis; zero
    variance on the axes ``EkfConfig.gnss_gm_sd_h`` / ``gnss_gm_sd_v`` leave at 0:
    ``sensors.gnss_model``).

The error dynamics, the propagation and update scheme, the heading before and at its
acquisition, GNSS gating, IMU gaps, the magnetometer row and the RTS smoother are specified in
docs/ekf.md.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numba import njit

from ...geo.earth import OMEGA_IE, gravity_scalar, radii_scalar
from ...nav.arrays import put, solve
from ...nav.error_state import BARO_COMPONENTS, mark_absent
from ...nav.rotations import quat_exp, quat_mul, skew3
from ...nav.strapdown import nav_rates
from ...types import ERROR_STATE_DIM

NX = 27  # internal error-state dimension
NPACK = NX * (NX + 1) // 2
NING = 23  # ingredients of F per grid interval (22: IMU-gap flag)
IPOS, IVEL, IATT, IBG, IBA, ISC, ITD, IBB, IKA, IMB, IGE = (0, 3, 6, 9, 12, 15, 16, 17, 18,
                                                            21, 24)
# indices of the nominal parameter vector ``par`` (NPAR,)
PBG, PBA, PKA, PSC, PTD, PBB, PMB, PGE = 0, 3, 6, 9, 10, 11, 12, 15
NPAR = 18


@njit(cache=True)
def pack(p, out):
    m = 0
    for i in range(NX):
        for j in range(i, NX):
            out[m] = p[i, j]
            m += 1


@njit(cache=True)
def unpack(v):
    p = np.empty((NX, NX))
    m = 0
    for i in range(NX):
        for j in range(i, NX):
            p[i, j] = v[m]
            p[j, i] = v[m]
            m += 1
    return p


@njit(cache=True)
def build_f(ing, tau_g, tau_a, tau_b, tau_h):
    """Continuous error-dynamics matrix F (NX, NX) of one grid interval (docs/ekf.md)."""
    f = np.zeros((NX, NX))
    c = ing[0:9].copy().reshape(3, 3)
    fn = ing[9:12]
    fb = ing[12:15]
    lat = ing[15]
    h = ing[16]
    v = ing[17:20].copy()
    rn, re = radii_scalar(lat)
    w_ie, w_en = nav_rates(lat, h, v)
    w_in = w_ie + w_en
    g = gravity_scalar(lat, h)
    for i in range(3):
        f[IPOS + i, IVEL + i] = 1.0
    put(f[IVEL:IVEL + 3, IVEL:IVEL + 3], -skew3(2.0 * w_ie + w_en))
    put(f[IVEL:IVEL + 3, IATT:IATT + 3], -skew3(fn))
    f[IVEL + 2, IPOS + 2] = 2.0 * g / (np.sqrt(rn * re) + h)
    for i in range(3):
        for j in range(3):
            f[IVEL + i, IBA + j] = -c[i, j]
            f[IVEL + i, IKA + j] = -c[i, j] * fb[j]
            f[IATT + i, IBG + j] = -c[i, j]
    put(f[IATT:IATT + 3, IATT:IATT + 3], -skew3(w_in))
    f[IATT + 0, IVEL + 1] = -1.0 / (re + h)
    f[IATT + 1, IVEL + 0] = 1.0 / (rn + h)
    f[IATT + 2, IVEL + 1] = np.tan(lat) / (re + h)
    f[IATT + 0, IPOS + 0] = OMEGA_IE * np.sin(lat) / (rn + h)
    f[IATT + 2, IPOS + 0] = OMEGA_IE * np.cos(lat) / (rn + h)
    for i in range(3):
        if np.isfinite(tau_g):
            f[IBG + i, IBG + i] = -1.0 / tau_g
        if np.isfinite(tau_a):
            f[IBA + i, IBA + i] = -1.0 / tau_a
    if np.isfinite(tau_b):
        f[IBB, IBB] = -1.0 / tau_b
    if np.isfinite(tau_h):
        for i in range(3):
            f[IGE + i, IGE + i] = -1.0 / tau_h
    if ing[22] > 0.5:
        # IMU gap (docs/ekf.md, "IMU gaps"): no inertial data, constant-velocity nominal; only
        # δṙ = δv and the Gauss-Markov decays remain
        g2 = np.zeros((NX, NX))
        for i in range(3):
            g2[IPOS + i, IVEL + i] = 1.0
            g2[IBG + i, IBG + i] = f[IBG + i, IBG + i]
            g2[IBA + i, IBA + i] = f[IBA + i, IBA + i]
        g2[IBB, IBB] = f[IBB, IBB]
        for i in range(3):
            g2[IGE + i, IGE + i] = f[IGE + i, IGE + i]
        f = g2
    if ing[20] > 0.5:  # heading unknown: decouple the yaw error
        for j in range(NX):
            f[IATT + 2, j] = 0.0
            f[j, IATT + 2] = 0.0
    return f


@njit(cache=True)
def transition(f, dt):
    a = f * dt
    return np.eye(NX) + a + 0.5 * (a @ a)


@njit(cache=True)
def step_phi(ing, tau_g, tau_a, tau_b, tau_h):
    """Φ of one grid interval: ``transition(build_f(ing), Δt)``; across an IMU gap the
    roll/pitch error rows are zero (the tilt is re-levelled after the gap, its new error is
    independent of the old one and enters through Q), and so is the yaw row when the heading
    is forgotten over the gap (ing[20] set: the yaw error restarts with the uniform variance
    in Q). The rows of the first-order Gauss-Markov states (IMU biases, baro bias, GNSS
    error) have F = −1/τ on the diagonal alone, so their row of e^{FΔt} is exactly e^{−Δt/τ}
    there: set so, and Φ² σ² + Q_d = σ² over any interval (``sensors.noise.gm_process_var``),
    an IMU gap of several τ included (the second-order series gives 1 − x + x²/2 ≥ 1/2)."""
    dt = ing[21]
    phi = transition(build_f(ing, tau_g, tau_a, tau_b, tau_h), dt)
    for i0, n, tau in ((IBG, 3, tau_g), (IBA, 3, tau_a), (IBB, 1, tau_b), (IGE, 3, tau_h)):
        if np.isfinite(tau):
            for i in range(i0, i0 + n):
                phi[i, i] = np.exp(-dt / tau)
    if ing[22] > 0.5:
        for j in range(NX):
            phi[IATT, j] = 0.0
            phi[IATT + 1, j] = 0.0
            if ing[20] > 0.5:  # heading forgotten over a long gap: yaw error restarts
                phi[IATT + 2, j] = 0.0
    return phi


@njit(cache=True)
def reset_jacobian(delta):
    """J of the heading reset: tilt rotated by R_z(Δ), yaw error replaced (row zeroed)."""
    j = np.eye(NX)
    cd, sd = np.cos(delta), np.sin(delta)
    j[IATT, IATT] = cd
    j[IATT, IATT + 1] = -sd
    j[IATT + 1, IATT] = sd
    j[IATT + 1, IATT + 1] = cd
    j[IATT + 2, IATT + 2] = 0.0
    return j


@njit(cache=True)
def scalar_update(p, dx, hrow, y, r):
    """Sequential scalar update, Joseph form expanded (docs/ekf.md). y = h(x̃) − z:
    ``consider_update`` with no consider states."""
    consider_update(p, dx, hrow, y, r, 0, 0)


@njit(cache=True)
def consider_update(p, dx, hrow, y, r, c0, c1):
    """``scalar_update`` with the states [c0, c1) held as Schmidt "consider" states: their
    gain is zero, so neither they nor their estimate change, while P keeps their
    correlations (the expanded Joseph form holds for any gain)."""
    a = p @ hrow
    s = hrow @ a + r
    k = a / s
    for i in range(c0, c1):
        k[i] = 0.0
    dx += k * (y - hrow @ dx)
    for i in range(NX):
        for j in range(NX):
            p[i, j] = p[i, j] - k[i] * a[j] - a[i] * k[j] + s * k[i] * k[j]
    for i in range(NX):
        for j in range(i + 1, NX):
            m = 0.5 * (p[i, j] + p[j, i])
            p[i, j] = m
            p[j, i] = m


@njit(cache=True)
def huber_weight(e, k):
    """Huber's IRLS weight of a Mahalanobis norm e with threshold k [σ]: 1 for e ≤ k, k/e
    above (``estimators.robust``); k ≤ 0: no loss, weight 1."""
    if k <= 0.0 or e <= k:
        return 1.0
    return k / e


@njit(cache=True)
def vector_update(p, dx, hm, y, rdiag, gate, force, huber_k, c0, c1):
    """Gate the m-vector y = h(x̃) − z on its NIS, then update sequentially.

    Huber re-weighting (``huber_k`` > 0): with e = √NIS the rows' variances are R/w,
    w = ``huber_weight``(e, k). States [c0, c1) are consider states (``consider_update``;
    c0 = c1: none). Returns (accepted, NIS, normalised innovations (m,), w); ``force`` skips
    the gate."""
    m = y.size
    nu = y - hm @ dx
    s = hm @ p @ hm.T
    for i in range(m):
        s[i, i] += rdiag[i]
    x = solve(s, nu.reshape((m, 1)))  # 2-D: the specialisation the RTS smoother compiles
    nis = 0.0
    for i in range(m):
        nis += nu[i] * x[i, 0]
    norm = np.empty(m)
    for i in range(m):
        norm[i] = -nu[i] / np.sqrt(s[i, i])  # sign of z − h(x̃)
    if nis > gate and not force:
        return False, nis, norm, 1.0
    w = huber_weight(np.sqrt(max(nis, 0.0)), huber_k)
    for i in range(m):
        if c1 > c0:
            consider_update(p, dx, hm[i].copy(), y[i], rdiag[i] / w, c0, c1)
        elif w < 1.0:
            scalar_update(p, dx, hm[i].copy(), y[i], rdiag[i] / w)
        else:
            scalar_update(p, dx, hm[i].copy(), y[i], rdiag[i])
    return True, nis, norm, w


@njit(cache=True)
def apply_correction(lla, v, q, par, dx):
    """Closed-loop feedback: remove the estimated error δx from the nominal state."""
    rn, re = radii_scalar(lla[0])
    lla[0] -= dx[IPOS] / (rn + lla[2])
    lla[1] -= dx[IPOS + 1] / ((re + lla[2]) * np.cos(lla[0]))
    lla[2] += dx[IPOS + 2]
    for i in range(3):
        v[i] -= dx[IVEL + i]
    qn = quat_mul(quat_exp(-dx[IATT:IATT + 3].copy()), q)
    qn /= np.sqrt(np.sum(qn * qn))
    put(q[:], qn)
    for i in range(3):
        par[PBG + i] -= dx[IBG + i]
        par[PBA + i] -= dx[IBA + i]
        par[PKA + i] -= dx[IKA + i]
        par[PMB + i] -= dx[IMB + i]
        par[PGE + i] -= dx[IGE + i]
    par[PSC] -= dx[ISC]
    par[PTD] -= dx[ITD]
    par[PBB] -= dx[IBB]


def unpack_cov(packed: Any, has_baro: bool) -> Any:
    """Packed (M, NPACK) NX-state covariances → (M, 18, 18) in the ERROR_STATE layout."""
    iu, ju = np.triu_indices(NX)
    keep = np.flatnonzero(ju < ERROR_STATE_DIM)  # upper triangle of the leading block
    iu, ju = iu[keep], ju[keep]
    # straight into the (M, 18, 18) result: an (M, NX, NX) temporary was the ekf's largest
    # allocation (90 MB on a 1-hour drive)
    cov = np.empty((packed.shape[0], ERROR_STATE_DIM, ERROR_STATE_DIM))
    for a in range(0, packed.shape[0], 4096):  # the gathered columns in blocks, not all at once
        blk = packed[a:a + 4096][:, keep]
        cov[a:a + 4096, iu, ju] = blk
        cov[a:a + 4096, ju, iu] = blk
    if not has_baro:
        mark_absent(cov, BARO_COMPONENTS)
    cov.setflags(write=False)  # read-only and owned: ``Estimate`` shares it instead of a copy
    return cov
