"""The forward EKF's steps at a grid epoch (``kernel.run_filter`` strings them together):
covariance prediction, the heading reset, the delayed-measurement correction of the rows,
and the gating that several measurements share (``tilt_held``, the one-row gated update
``update_gated``; each measurement's rows and update are ``ekf.updates``)."""

from __future__ import annotations

import numpy as np
from numba import njit

from ...nav.arrays import put
from ...nav.rotations import quat_mul, quat_to_dcm
from .model import (
    IATT,
    IVEL,
    NING,
    NX,
    PBA,
    PBB,
    PBG,
    PGE,
    build_f,
    reset_jacobian,
    step_phi,
    vector_update,
)


@njit(cache=True)
def decay_gm(par, dt, tau_g, tau_a, tau_b, tau_h):
    """The nominal Gauss-Markov states over ``dt``: gyro and accelerometer biases, baro bias
    and the GNSS error state each times exp(−dt/τ) (τ = inf: unchanged)."""
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
        f = np.exp(-dt / tau_h)
        for a in range(3):
            par[PGE + a] *= f


@njit(cache=True)
def grid_predict(p, q, lla, v, par, acc_fn, acc_fb, acc_n, heading_ok, gap, dtg, elapsed,
                 qd_k, noise):
    """Covariance over one grid interval: P ← Φ P Φᵀ + Q_d, with the unknown-heading
    inflation of tilt and horizontal velocity (docs/ekf.md, "Heading before it is known");
    the nominal Gauss-Markov states decay alike. Returns (P, F's ingredients, F, Q_d)."""
    ing = np.zeros(NING)
    put(ing[0:9], quat_to_dcm(q).copy().reshape(9))
    put(ing[9:12], acc_fn / max(acc_n, 1))
    put(ing[12:15], acc_fb / max(acc_n, 1))
    ing[15] = lla[0]
    ing[16] = lla[2]
    put(ing[17:20], v)
    ing[20] = 0.0 if heading_ok else 1.0
    ing[21] = dtg
    ing[22] = 1.0 if gap else 0.0
    tau_g, tau_a, tau_b, tau_h = noise.tau_g, noise.tau_a, noise.tau_b, noise.tau_h
    fmat = build_f(ing, tau_g, tau_a, tau_b, tau_h)
    phi = step_phi(ing, tau_g, tau_a, tau_b, tau_h)
    qd = qd_k.copy()
    if gap and not heading_ok:
        qd[IATT + 2] = noise.yaw_unknown_var
    if not heading_ok:
        tilt = 2.0 * noise.tilt_rate_sd**2 * elapsed * dtg
        qd[IATT] += tilt
        qd[IATT + 1] += tilt
        fh2 = ing[9] ** 2 + ing[10] ** 2
        qd[IVEL] += 8.0 * fh2 * dtg * dtg
        qd[IVEL + 1] += 8.0 * fh2 * dtg * dtg
    p = phi @ p @ phi.T
    for a in range(NX):
        p[a, a] += qd[a]
    # the nominal Gauss-Markov states follow the same model as their errors (Φ's −1/τ):
    # b ← exp(−Δt/τ)·b. Held constant, the mean of a Gauss-Markov bias would not follow the
    # model the covariance assumes; the graph's bias link decays it alike
    # (sensors.noise.imu_bias_step)
    decay_gm(par, dtg, tau_g, tau_a, tau_b, tau_h)
    return p, ing, fmat, qd


@njit(cache=True)
def heading_reset(p, q, qd, delta, sd):
    """Apply an acquired heading: yaw rotated by ``delta``, tilt covariance rotated with it,
    the yaw variance replaced by sd² (also in Q_d for the smoother). Returns (P, q)."""
    jr = reset_jacobian(delta)
    p = jr @ p @ jr.T
    p[IATT + 2, IATT + 2] = sd**2
    qz = np.array([np.cos(0.5 * delta), 0.0, 0.0, np.sin(0.5 * delta)])
    q = quat_mul(qz, q)
    q /= np.sqrt(np.sum(q * q))
    qd[IATT + 2] = sd**2
    return p, q


@njit(cache=True)
def delayed_rows(h, r, mm, fmat, qd, lag, dtg):
    """Rows of a measurement taken ``lag`` before the grid epoch, mapped to the epoch:
    H_eff = H (I − F lag); the process noise between the two enters the measurement,
    R_eff = R + diag(H Q(t_m→t_k) Hᵀ) with Q(t_m→t_k) ≈ Q_k · lag/Δt_k (``r`` in place)."""
    back = np.eye(NX) - fmat * lag
    heff = h[:mm] @ back
    if lag > 0.0:
        for a in range(mm):
            extra = 0.0
            for b in range(NX):
                extra += heff[a, b] ** 2 * qd[b]
            r[a] += extra * lag / dtg
    return heff


# ``tilt_held``: the attitude is held as a consider state only while the heading is unknown
# and the tilt σ exceeds this (a levelling in motion leaves 15–20°, far outside the linear
# regime; a static levelling leaves < 1°, and holding that tilt for a whole drive whose
# heading never becomes known cost ekf-rts 0.33 → 0.72 m altitude RMSE on seed003)
TILT_HELD_VAR = np.radians(5.0) ** 2


@njit(cache=True)
def tilt_held(p, settings, heading_ok):
    """Whether the GNSS and baro updates hold the attitude as Schmidt consider states
    (``EkfConfig.tilt_consider``; docs/ekf.md, "Heading before it is known")."""
    if not settings.tilt_consider or heading_ok:
        return False
    return max(p[IATT, IATT], p[IATT + 1, IATT + 1]) > TILT_HELD_VAR


@njit(cache=True)
def update_gated(p, dx, heff, y, r, gate, max_consec, counts, c, inn, rej, idx, huber_k,
                 hold_tilt):
    """A one-row measurement (baro, magnetometer heading) behind a χ²₁ gate, forced in after
    ``max_consec`` refusals in a row (counter ``counts[c]``); Huber re-weighting with
    threshold ``huber_k`` (0: none); ``hold_tilt``: the attitude as consider states."""
    c0 = IATT if hold_tilt else 0
    c1 = IATT + 3 if hold_tilt else 0
    ok, nis, nrm, w = vector_update(p, dx, heff[:1].copy(), y[:1].copy(), r[:1].copy(), gate,
                                    counts[c] >= max_consec, huber_k, c0, c1)
    inn[idx] = nrm[0]
    rej[idx] = not ok
    counts[c] = 0 if nis <= gate else counts[c] + 1
