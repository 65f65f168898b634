"""The forward EKF's steps at a grid epoch (``kernel.run_filter`` strings them together):
covariance prediction, the heading reset, the delayed-measurement correction of the rows,
and one gated update per measurement kind."""

from __future__ import annotations

import numpy as np
from numba import njit

from ...nav.arrays import put
from ...nav.gnss_gate import REFUSE, USE_INFLATE, height_gate
from ...nav.rotations import quat_mul, quat_to_dcm
from .model import (
    IATT,
    IBB,
    IPOS,
    IVEL,
    NING,
    NX,
    PBA,
    PBB,
    PBG,
    PGE,
    build_f,
    consider_update,
    huber_weight,
    reset_jacobian,
    scalar_update,
    step_phi,
    vector_update,
)

# the gates' refusal counters (an int array carried by the loop)
C_POS, C_BARO, C_MAG = 0, 1, 2
# ``tilt_held``: the attitude is held as a consider state only while the heading is unknown
# and the tilt σ exceeds this (a levelling in motion leaves 15–20°, far outside the linear
# regime; a static levelling leaves < 1°, and holding that tilt for a whole drive whose
# heading never becomes known cost ekf-rts 0.33 → 0.72 m altitude RMSE on seed003)
TILT_HELD_VAR = np.radians(5.0) ** 2


@njit(cache=True)
def tilt_held(p, settings, heading_ok):
    """Whether the GNSS and baro updates hold the attitude as Schmidt consider states
    (``EkfConfig.tilt_consider``; ``model`` docstring, "Heading before it is known")."""
    if not settings.tilt_consider or heading_ok:
        return False
    return max(p[IATT, IATT], p[IATT + 1, IATT + 1]) > TILT_HELD_VAR


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
    inflation of tilt and horizontal velocity (``model``'s docstring); the nominal
    Gauss-Markov states decay alike. Returns (P, F's ingredients, F, Q_d)."""
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


@njit(cache=True)
def update_gnss(p, dx, heff, y, r, mm, idx, te, k, settings, sd_v, has_baro, b_prior_var,
                v_gate, counts, rts_q, inn_pos, inn_vel, rej_pos, rej_vel, rej_v, heading_ok,
                forced_pos):
    """A GNSS fix: the horizontal position pair (χ²₂ gate; after ``max_consec`` refusals a
    jump of the observed size is added to P and forced in, flagged in ``forced_pos``), the
    height through the fault
    detection of ``nav.gnss_gate.height_gate``, then the velocity (pair, then down, which
    follows the height's verdict). Huber re-weighting per ``settings.huber_*`` (pair, height
    and vertical velocity each on its own NIS). While the heading is unknown the horizontal
    pairs hold the attitude as consider states while its tilt σ is large (``tilt_held``)."""
    no_force = mm < 0  # False as a typed bool: a literal compiles vector_update again
    c0 = IATT if tilt_held(p, settings, heading_ok) else 0
    c1 = IATT + 3 if c0 > 0 else 0
    force_h = counts[C_POS] >= settings.max_consec
    forced_pos[idx] = force_h
    if force_h:
        for a in range(2):
            nu_a = y[a] - heff[a] @ dx
            p[IPOS + a, IPOS + a] += nu_a * nu_a
            if settings.store_rts:
                rts_q[k, IPOS + a] += nu_a * nu_a
    ok, nis, nrm, w = vector_update(p, dx, heff[:2].copy(), y[:2].copy(), r[:2].copy(),
                                    settings.gate_pos, force_h, settings.huber_pos, c0, c1)
    put(inn_pos[idx, :2], nrm)
    rej_pos[idx] = not ok
    counts[C_POS] = 0 if nis <= settings.gate_pos else counts[C_POS] + 1
    hv = heff[2].copy()
    rv = r[2]
    nu_v = y[2] - hv @ dx
    s_v = hv @ p @ hv + rv
    inn_pos[idx, 2] = -nu_v / np.sqrt(s_v)
    usable = sd_v <= settings.max_sd_v
    code = height_gate(v_gate, te, usable, nu_v * nu_v, s_v, settings.gate_v,
                       settings.probation_s, settings.max_consec, b_prior_var, not has_baro)
    use_v = code != REFUSE
    if use_v:
        if code == USE_INFLATE:
            p[IBB, IBB] += b_prior_var
        w = huber_weight(np.sqrt(nu_v * nu_v / s_v), settings.huber_pos)
        if c1 > c0:
            consider_update(p, dx, hv, y[2], rv if w >= 1.0 else rv / w, c0, c1)
        else:
            scalar_update(p, dx, hv, y[2], rv if w >= 1.0 else rv / w)
    else:
        rej_v[idx] = True
        rej_pos[idx] = True
    if mm == 6:
        ok, nis, nrm, w = vector_update(p, dx, heff[3:5].copy(), y[3:5].copy(),
                                        r[3:5].copy(), settings.gate_vel, no_force,
                                        settings.huber_vel, c0, c1)
        put(inn_vel[idx, :2], nrm)
        rej_vel[idx] = not ok
        if use_v:
            ok, nis, nrm, w = vector_update(p, dx, heff[5:6].copy(), y[5:6].copy(),
                                            r[5:6].copy(), settings.gate_v, no_force,
                                            settings.huber_vel, c0, c1)
            inn_vel[idx, 2] = nrm[0]
            rej_vel[idx] = rej_vel[idx] or not ok
        else:
            rej_vel[idx] = True


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


@njit(cache=True)
def update_zupt(p, dx, heff, y, r, gate, inn, rej, idx):
    """A zero-velocity pseudo-measurement (``rows.zupt_rows``) behind a χ²₃ gate, never
    forced: a standstill the filter's velocity contradicts is refused (``rej``)."""
    no_force = gate < 0.0  # False as a typed bool: a literal compiles vector_update again
    ok, nis, nrm, w = vector_update(p, dx, heff[:3].copy(), y[:3].copy(), r[:3].copy(), gate,
                                    no_force, 0.0, 0, 0)
    put(inn[idx], nrm)
    rej[idx] = not ok
