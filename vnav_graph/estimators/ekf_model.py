"""Numba kernels of the INS/GNSS/baro error-state EKF and its RTS smoother.

Error state δx (21), every component "estimated minus true" (types.ERROR_STATE convention;
the first 18 are exactly the shared layout):

    0:3 δr (NED position [m]), 3:6 δv (NED [m/s]), 6:9 ψ (tilt in n [rad], C̃ = (I+[ψ×]) C),
    9:12 δb_g [rad/s], 12:15 δb_a [m/s²], 15 δs (baro scale), 16 δτ_d [s], 17 δb (baro bias
    [m]), 18:21 δk_a (accelerometer scale factors, f̃ = (1+k_a)∘f + b_a + n).

Error dynamics (Groves, 2nd ed., eqs. 14.64-14.65 reduced to local-level NED; Titterton &
Weston §12.3), with f_n the specific force in n and ω_in = ω_ie + ω_en:

    δṙ = δv
    δv̇ = −[f_n×] ψ − C δb_a − C diag(f_b) δk_a − [(2ω_ie + ω_en)×] δv + (2g/R) δr_D e_D
    ψ̇  = −[ω_in×] ψ − C δb_g − (∂ω_en/∂v) δv − (∂ω_ie/∂L) δr_N/(R_N+h)
    δḃ_g = −δb_g/τ_g + w,  δḃ_a = −δb_a/τ_a + w,  δḃ = −δb/τ_b + w,  δṡ = δτ̇ = δk̇_a = 0.

The nominal state runs at the IMU rate through the shared ``strapdown.strapdown_step``. The
covariance is propagated on a coarser grid (every M IMU samples, ≈ 10 Hz): Φ = I + FΔt +
½(FΔt)² with F built from interval means of f_n, f_b and the end-of-interval nominal state.
Justification: the error dynamics are slow (Schuler 84 min, vertical 570 s, bias τ ≥ minutes);
over 0.1 s the neglected terms are O((‖F‖Δt)³) ≈ 1e-9.

Measurements inside a grid interval are predicted from the nominal state interpolated to
their own time t_m; they are applied at the next grid epoch t_k with H_eff = H(I − F(t_k −
t_m)), the first-order back-propagation δx(t_m) = Φ(t_m, t_k) δx(t_k). Updates are sequential
scalar updates (R is diagonal) in Joseph form, expanded to O(n²):
P⁺ = (I − K h) P (I − K h)ᵀ + K r Kᵀ = P − K aᵀ − a Kᵀ + (h a + r) K Kᵀ, a = P hᵀ (valid for
any gain K). Each GNSS position / velocity vector is chi-square gated first on its joint
NIS = νᵀ S⁻¹ ν. After the updates the estimate is fed back into the nominal state (closed
loop) and δx is reset to zero.

Heading before it is known (no given heading, not yet acquired): the yaw error ψ_D is
decoupled — its row and column of Φ and of H are zero and its variance stays at
``yaw_unknown_var`` (uniform heading, π²/3) — so the linear filter is never fed a large
heading error. Two effects of the unknown heading are added as process noise: the horizontal
Earth-rate compensation (tilt, rate ≤ 2Ω cos L, rms √2 Ω cos L, treated as a constant rate
of unknown sign) and the rotation of the horizontal specific force (velocity, rms √2 |f_h|).
The first GNSS fix with track speed above the threshold resets the nominal yaw to the track
(q ← q_z(Δ) ⊗ q), rotates the tilt covariance with it (ψ' = R_z(Δ) ψ) and sets the yaw
variance to the track's σ²; the RTS smoother sees this step as Φ_eff = J Φ with Q_eff[8] = σ².

Heading by acceleration matching (``heading_accel``: the default when GNSS gives velocity).
Course over ground is the heading only without sideslip; a multicopter moves in any direction
(218.BIN: the track reset left the heading 166° off the compass attitude and the z-gyro bias
absorbed ±1.3 °/s). Instead the horizontal specific-force integral in the nominal frame, U = ∫
(C̃ f̃)_h dt (yaw still arbitrary), is compared with the GNSS velocity increment W = Δv_h over
the same interval: W = R_z(δ) U + n (gravity and Coriolis have no horizontal part at this
accuracy), δ = true − nominal yaw. Per chunk of ≥ ``align_chunk_s`` between velocity fixes,
with σ² = Σ_both fixes (σ²_vN + σ²_vE)/2 + (σ_a T)² (σ_a = √2 × the accelerometer-bias prior:
tilt and bias per axis), the weighted sums S_c = Σ (U×W)/σ², S_d = Σ U·W/σ², S_uu = Σ |U|²/σ²
are kept with forgetting exp(−T/``align_forget_s``) (the nominal yaw drifts with the unknown
z-gyro bias); δ̂ = atan2(S_c, S_d) is the maximum-likelihood rotation, its Fisher information
is S_uu, σ_δ = 1/√S_uu. After ≥ 3 chunks and σ_δ ≤ ``align_sd_max`` the heading is reset by δ̂
with σ 2σ_δ (factor 2: bias drift and tilt in U). A chunk whose |W| and |U| differ by > 4σ
(rotation keeps the norm) is a GNSS velocity fault and is skipped. Without GNSS velocity the
track heading (previous paragraph) is used. An IMU gap longer than ``gap_forget_s`` makes the
heading unknown again (the vehicle may have turned: Loiter_RTL's crash); the gap's Φ has a
zero yaw row and Q gives the uniform variance, and the heading is re-acquired after it.

The RTS smoother (Rauch, Tung & Striebel 1965) runs on the same grid. With closed-loop
feedback, e_k = x⁺_k − x_true has filtered mean 0, and with c_k the correction applied at k:
ê^s_k = G_k (ê^s_{k+1} + c_{k+1}),  P^s_k = P⁺_k + G_k (P^s_{k+1} − P⁻_{k+1}) G_kᵀ,
G_k = P⁺_k Φ_kᵀ (P⁻_{k+1})⁻¹, ê^s_N = 0. P⁻_{k+1} is recomputed from the stored packed P⁺_k,
Φ_k (from its stored ingredients) and Q_k, so only ≈ 300 numbers per grid epoch are kept.

GNSS position gating (fault detection and exclusion). The horizontal pair and the height of a
fix are gated separately: NIS_h = ν_hᵀ S_h⁻¹ ν_h against χ²₂, NIS_v = ν_v²/S_v against χ²₁.
With a barometer the vertical is well determined without GNSS (baro + bias model), so a
GNSS height inconsistent with it is a receiver fault, and such faults persist (multipath,
the 181.BIN glitch: 300 m for a minute while the fix claims 3-D):
- a height whose own σ_v exceeds ``max_sd_v`` is not used (the receiver says it is degraded;
  relative to a baro-aided vertical it carries almost no information);
- an isolated rejected height (a spike) is just refused; after two consecutive refusals the
  GNSS height is on probation (a persistent fault): it is used again only once it has passed
  the gate (and been usable) for ``probation_s`` without a break;
- after ``max_consec`` consecutive vertical refusals the probation gate is widened by the
  baro-bias prior variance (S_v + σ²_b,prior: "consistent with the baro if we forget what we
  learned about its bias"), and the fix that completes probation is applied with σ²_b,prior
  added to the baro-bias variance, so a genuinely moved baro datum is re-learned;
- without a barometer the old rule applies: after ``max_consec`` refusals the height is
  accepted (GNSS is the only height reference; a diverged filter must recover).
The horizontal pair is accepted after ``max_consec`` refusals (nothing else observes it), as
a re-initialisation: a position jump with the variance of the observed innovation is added
to P (and to the stored Q, so the RTS smoother models the same jump) before the update.
The GNSS vertical velocity is used only with an accepted GNSS height (same receiver
solution); the horizontal velocity pair is gated on its own (χ²₂). The baro is the
vertical anchor: after ``max_consec_baro`` consecutive refusals (≈ 1 s) it is accepted (an
inertial vertical that disagrees with the baro for that long has diverged — 181.BIN's
vibrating accelerometer — or the baro stepped, and then the new level is the one to follow).

IMU gaps (logging dropouts, ``gap_step``): an IMU interval longer than the gap threshold is
not integrated as if the end samples held over it. The step is its own grid interval; the
nominal state moves at constant velocity, F keeps only δṙ = δv and the Gauss-Markov decays,
and Q adds the unknown motion: σ_a²Δt to velocity, σ_a²Δt³/3 to position (cross term
omitted), σ_ψ²Δt to yaw. The attitude is not carried over a gap (the 22 s gap of
Loiter_RTL.bin follows a crash: the vehicle lies upside down before it and stands upright
after it): roll and pitch are re-levelled from the mean specific force of the first samples
after the gap (``gap_rp``, coarse levelling as at the start) with the yaw kept; Φ's roll/pitch
rows are zero there (``step_phi``) and Q gives them the levelling variance, so the RTS smoother
sees the reset exactly. The next GNSS/baro updates then re-anchor position and velocity with
the inflated covariance.

The baro prediction/Jacobian ``baro_predict`` / ``baro_row`` are scalar njit twins of
``vnav_graph.sensors.baro.measure_baro`` / ``baro_jacobian`` (the shared model; tested equal in
tests/unit/test_ekf_model.py).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..geo.earth import OMEGA_IE, gravity_scalar, radii_scalar
from ..nav.gnss_gate import REFUSE, USE_INFLATE, height_gate
from ..nav.rotations import quat_exp, quat_mul, quat_to_dcm, rpy_quat, skew3
from ..nav.rotations import yaw_of as _yaw
from .strapdown import nav_rates, strapdown_step

NX = 21  # internal error-state dimension
NPACK = NX * (NX + 1) // 2
NING = 23  # ingredients of F per grid interval (22: IMU-gap flag)
IPOS, IVEL, IATT, IBG, IBA, ISC, ITD, IBB, IKA = 0, 3, 6, 9, 12, 15, 16, 17, 18
# indices of the nominal parameter vector ``par`` (12,)
PBG, PBA, PKA, PSC, PTD, PBB = 0, 3, 6, 9, 10, 11


@njit(cache=True)
def baro_predict(h, v_up, scale, latency, bias, h0):
    """Scalar twin of ``sensors.baro.measure_baro``: h0 + (1+s)(h − h0 − v_up τ) + b [m]."""
    return h0 + (1.0 + scale) * (h - h0 - v_up * latency) + bias


@njit(cache=True)
def baro_row(h, v_up, scale, latency, h0):
    """Scalar twin of ``sensors.baro.baro_jacobian``: ∂h_b/∂(h, v_up, s, τ, b), shape (5,)."""
    return np.array([1.0 + scale, -(1.0 + scale) * latency, h - h0 - v_up * latency,
                     -(1.0 + scale) * v_up, 1.0])


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
def build_f(ing, tau_g, tau_a, tau_b):
    """Continuous error-dynamics matrix F (21, 21) of one grid interval (module docstring)."""
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
    f[IVEL:IVEL + 3, IVEL:IVEL + 3] = -skew3(2.0 * w_ie + w_en)
    f[IVEL:IVEL + 3, IATT:IATT + 3] = -skew3(fn)
    f[IVEL + 2, IPOS + 2] = 2.0 * g / (np.sqrt(rn * re) + h)
    for i in range(3):
        for j in range(3):
            f[IVEL + i, IBA + j] = -c[i, j]
            f[IVEL + i, IKA + j] = -c[i, j] * fb[j]
            f[IATT + i, IBG + j] = -c[i, j]
    f[IATT:IATT + 3, IATT:IATT + 3] = -skew3(w_in)
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
    if ing[22] > 0.5:
        # IMU gap (module docstring): no inertial data, constant-velocity nominal; only
        # δṙ = δv and the Gauss-Markov decays remain
        g2 = np.zeros((NX, NX))
        for i in range(3):
            g2[IPOS + i, IVEL + i] = 1.0
            g2[IBG + i, IBG + i] = f[IBG + i, IBG + i]
            g2[IBA + i, IBA + i] = f[IBA + i, IBA + i]
        g2[IBB, IBB] = f[IBB, IBB]
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
def step_phi(ing, tau_g, tau_a, tau_b):
    """Φ of one grid interval: ``transition(build_f(ing), Δt)``; across an IMU gap the
    roll/pitch error rows are zero (the tilt is re-levelled after the gap, its new error is
    independent of the old one and enters through Q), and so is the yaw row when the heading
    is forgotten over the gap (ing[20] set: the yaw error restarts with the uniform variance
    in Q)."""
    phi = transition(build_f(ing, tau_g, tau_a, tau_b), ing[21])
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
def _scalar_update(p, dx, hrow, y, r):
    """Sequential scalar update, Joseph form expanded (module docstring). y = h(x̃) − z."""
    a = p @ hrow
    s = hrow @ a + r
    k = a / s
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
def _vector_update(p, dx, hm, y, rdiag, gate, force):
    """Gate the m-vector y = h(x̃) − z on its NIS, then update sequentially.

    Returns (accepted, NIS, normalised innovations (m,)); ``force`` skips the gate."""
    m = y.size
    nu = y - hm @ dx
    s = hm @ p @ hm.T
    for i in range(m):
        s[i, i] += rdiag[i]
    nis = nu @ np.linalg.solve(s, nu)
    norm = np.empty(m)
    for i in range(m):
        norm[i] = -nu[i] / np.sqrt(s[i, i])  # sign of z − h(x̃)
    if nis > gate and not force:
        return False, nis, norm
    for i in range(m):
        _scalar_update(p, dx, hm[i].copy(), y[i], rdiag[i])
    return True, nis, norm


@njit(cache=True)
def _apply_correction(lla, v, q, par, dx):
    """Closed-loop feedback: remove the estimated error δx from the nominal state."""
    rn, re = radii_scalar(lla[0])
    lla[0] -= dx[IPOS] / (rn + lla[2])
    lla[1] -= dx[IPOS + 1] / ((re + lla[2]) * np.cos(lla[0]))
    lla[2] += dx[IPOS + 2]
    for i in range(3):
        v[i] -= dx[IVEL + i]
    qn = quat_mul(quat_exp(-dx[IATT:IATT + 3].copy()), q)
    qn /= np.sqrt(np.sum(qn * qn))
    q[:] = qn
    for i in range(3):
        par[PBG + i] -= dx[IBG + i]
        par[PBA + i] -= dx[IBA + i]
        par[PKA + i] -= dx[IKA + i]
    par[PSC] -= dx[ISC]
    par[PTD] -= dx[ITD]
    par[PBB] -= dx[IBB]


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
                    ok, nis, nrm = _vector_update(
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
                        _scalar_update(p, dx, hv, pend_y[e, 2], rv)
                    else:
                        rej_v[idx] = True
                        rej_pos[idx] = True
                    if mm == 6:
                        ok, nis, nrm = _vector_update(
                            p, dx, heff[3:5].copy(), pend_y[e, 3:5].copy(),
                            pend_r[e, 3:5].copy(), gate_vel, False)
                        inn_vel[idx, :2] = nrm
                        rej_vel[idx] = not ok
                        if use_v:
                            ok, nis, nrm = _vector_update(
                                p, dx, heff[5:6].copy(), pend_y[e, 5:6].copy(),
                                pend_r[e, 5:6].copy(), gate_v, False)
                            inn_vel[idx, 2] = nrm[0]
                            rej_vel[idx] = rej_vel[idx] or not ok
                        else:
                            rej_vel[idx] = True
                else:
                    ok, nis, nrm = _vector_update(
                        p, dx, heff[:1].copy(), pend_y[e, :1].copy(), pend_r[e, :1].copy(),
                        gate_baro, consec_baro >= max_consec_baro)
                    inn_baro[idx] = nrm[0]
                    rej_baro[idx] = not ok
                    consec_baro = 0 if nis <= gate_baro else consec_baro + 1
            n_pend = 0
            _apply_correction(lla, v, q, par, dx)
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


@njit(cache=True)
def rts_smooth(rts_p, rts_ing, rts_q, corr, reset_at, tau_g, tau_a, tau_b, cov_out_of,
               n_cov_out):
    """Backward RTS pass on the covariance grid (module docstring).

    Returns ê^s (K, 21) — the smoothed estimate of the error of the filtered (post-update)
    nominal state at each grid epoch, estimated minus true — and the packed smoothed
    covariances at the covariance-output epochs.
    """
    kk = rts_p.shape[0]
    es = np.zeros((kk, NX))
    cov_s = np.empty((n_cov_out, NPACK))
    ps = unpack(rts_p[kk - 1])
    if cov_out_of[kk - 1] >= 0:
        pack(ps, cov_s[cov_out_of[kk - 1]])
    for k in range(kk - 2, -1, -1):
        pk = unpack(rts_p[k])
        ing = rts_ing[k + 1]
        phi = step_phi(ing, tau_g, tau_a, tau_b)
        if not np.isnan(reset_at[k + 1]):
            phi = reset_jacobian(reset_at[k + 1]) @ phi
        pm = phi @ pk @ phi.T
        for a in range(NX):
            pm[a, a] += rts_q[k + 1, a]
        # G = P⁺ Φᵀ (P⁻)⁻¹ through the correlation matrix (scales differ by ~1e12)
        dinv = 1.0 / np.sqrt(np.diag(pm))
        corr_m = pm * np.outer(dinv, dinv)
        rhs = (phi @ pk) * dinv.reshape(NX, 1)
        gt = np.linalg.solve(corr_m, rhs) * dinv.reshape(NX, 1)
        g = gt.T
        es[k] = g @ (es[k + 1] + corr[k + 1])
        ps = pk + g @ (ps - pm) @ g.T
        ps = 0.5 * (ps + ps.T)
        if cov_out_of[k] >= 0:
            pack(ps, cov_s[cov_out_of[k]])
    return es, cov_s
