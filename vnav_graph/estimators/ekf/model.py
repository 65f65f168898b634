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

Error dynamics (Groves, 2nd ed., eqs. 14.64-14.65 reduced to local-level NED; Titterton &
Weston §12.3), with f_n the specific force in n and ω_in = ω_ie + ω_en:

    δṙ = δv
    δv̇ = −[f_n×] ψ − C δb_a − C diag(f_b) δk_a − [(2ω_ie + ω_en)×] δv + (2g/R) δr_D e_D
    ψ̇  = −[ω_in×] ψ − C δb_g − (∂ω_en/∂v) δv − (∂ω_ie/∂L) δr_N/(R_N+h)
    δḃ_g = −δb_g/τ_g + w,  δḃ_a = −δb_a/τ_a + w,  δḃ = −δb/τ_b + w,  δṡ = δτ̇ = δk̇_a = 0,
    δḃ_m = w,  δė = −δe/τ_e + w.

GNSS with the Gauss-Markov error state: the antenna position is predicted as r + C l + ê
(``sensors.gnss_model``, shared with the graph), so each position row carries ∂/∂δe = 1 on
its axis; the fix's own σ is then split into that state's σ and the white rest
(``GnssGM.split``).

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
The GNSS and baro updates hold the attitude as Schmidt consider states until the heading is
known while its tilt σ exceeds 5° (``consider_update``; ``steps.tilt_held``;
``EkfConfig.tilt_consider``): the horizontal rows cannot tell
tilt from heading then, and a levelling in motion can leave a tilt σ of 15–20° (position-only
start, ``alignment.moving_start``), far outside the linear regime — on cold-start-phone a
single baro sample moved the pitch by 16° (true error 3.8°) and a heading 10° off at its
acquisition was taken up as 12° of roll, each sending the forward filter hundreds of metres
off.
The first GNSS fix with track speed above the threshold resets the nominal yaw to the track
(q ← q_z(Δ) ⊗ q), rotates the tilt covariance with it (ψ' = R_z(Δ) ψ) and sets the yaw
variance to the track's σ²; the RTS smoother sees this step as Φ_eff = J Φ with Q_eff[8] = σ².

Heading by acceleration matching (``heading_accel``: the default when GNSS gives velocity).
Course over ground is the heading only without sideslip; a multicopter moves in any direction
(a hovering multicopter's track can point anywhere, so a track reset can leave the heading
far off, up to opposite, and the z-gyro bias then absorbs the error as a rate;
docs/real_logs.md, "Initial heading and tilt of a hovering multirotor"). Instead the
horizontal specific-force integral in the nominal frame, U = ∫ (C̃ f̃)_h dt (yaw still
arbitrary), is compared with the GNSS velocity increment W = Δv_h over the same interval:
W = R_z(δ) U + n (gravity and Coriolis have no horizontal part at this accuracy),
δ = true − nominal yaw. Per chunk of ≥ ``align_chunk_s`` between velocity fixes,
with σ² = Σ_both fixes (σ²_vN + σ²_vE)/2 + (σ_a T)² (σ_a = √2 × the accelerometer-bias prior:
tilt and bias per axis), the weighted sums S_c = Σ (U×W)/σ², S_d = Σ U·W/σ², S_uu = Σ |U|²/σ²
are kept with forgetting exp(−T/``align_forget_s``) (the nominal yaw drifts with the unknown
z-gyro bias); δ̂ = atan2(S_c, S_d) is the maximum-likelihood rotation, its Fisher information
is S_uu, σ_δ = 1/√S_uu. After ≥ 3 chunks and σ_δ ≤ ``align_sd_max`` the heading is reset by δ̂
with σ 2σ_δ (factor 2: bias drift and tilt in U). A chunk whose |W| and |U| differ by > 4σ
(rotation keeps the norm) is a GNSS velocity fault and is skipped. With "auto" the GNSS course
(σ by ``nav.course``) is taken before that once the matching's running estimate (≥ 1 chunk,
σ_δ ≤ ``course_confirm_sd``) agrees with it within 3 σ of both, with the course's σ
(``heading.confirmed_course``; the σ grown by their difference let the yaw wander 18° on
the simulated walk of ``test_ekf_walking_start``, against 4.9°). A gentle start gives a
course long before the matching's 15° (that walk at 0.1 m/s²: 5.9 s after moving instead of
12 s; a car drive likewise, docs/real_logs.md, "Standstills and course on the RTK drives"),
and a body that does not move along its x axis keeps the matching's heading (the sideways IMU
of ``test_ekf_heading``). A hand-held device is the limit: it need not point along its path
and swings with each step, so a course confirmed against the matching's early estimate can
leave the yaw more than ten degrees off for seconds (same section). Without GNSS velocity
the track heading (previous paragraph) is used.
An IMU gap longer than ``gap_forget_s`` makes the heading unknown again (the vehicle may have
turned: a crash that flips it over); the gap's Φ has a zero yaw row and Q gives the uniform
variance, and the heading is re-acquired after it.

The RTS smoother (Rauch, Tung & Striebel 1965) runs on the same grid. With closed-loop
feedback, e_k = x⁺_k − x_true has filtered mean 0, and with c_k the correction applied at k:
ê^s_k = G_k (ê^s_{k+1} + c_{k+1}),  P^s_k = P⁺_k + G_k (P^s_{k+1} − P⁻_{k+1}) G_kᵀ,
G_k = P⁺_k Φ_kᵀ (P⁻_{k+1})⁻¹, ê^s_N = 0. P⁻_{k+1} is recomputed from the stored packed P⁺_k,
Φ_k (from its stored ingredients) and Q_k, so only ≈ 300 numbers per grid epoch are kept.

GNSS position gating (fault detection and exclusion). The horizontal pair and the height of a
fix are gated separately: NIS_h = ν_hᵀ S_h⁻¹ ν_h against χ²₂, NIS_v = ν_v²/S_v against χ²₁.
With a barometer the vertical is well determined without GNSS (baro + bias model), so a
GNSS height inconsistent with it is a receiver fault, and such faults persist (multipath,
a receiver glitch that moves the heights by hundreds of metres for tens of seconds while
the fix claims 3-D; docs/real_logs.md, "GNSS screens"):
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
vertical anchor: after ``updates.BaroData.max_consec`` consecutive refusals (≈ 1 s) it is
accepted (an inertial vertical that disagrees with the baro for that long has diverged — an
accelerometer that loses specific force under vibration — or the baro stepped, and then the
new level is the one to follow).

IMU gaps (logging dropouts, ``gap_step``): an IMU interval longer than the gap threshold is
not integrated as if the end samples held over it. The step is its own grid interval; the
nominal state moves at constant velocity, F keeps only δṙ = δv and the Gauss-Markov decays,
and Q adds the unknown motion: σ_a²Δt to velocity, σ_a²Δt³/3 to position (cross term
omitted), σ_ψ²Δt to yaw. The attitude is not carried over a gap (a logging gap can follow
a crash, the vehicle upside down before it and upright after it; docs/real_logs.md, "IMU
logging gap across a crash"): roll and pitch are re-levelled from the mean specific force
of the first samples after the gap (``gap_rp``, coarse levelling as at the start) with the
yaw kept; Φ's roll/pitch rows are zero there (``step_phi``) and Q gives them the levelling
variance, so the RTS smoother sees the reset exactly. The next GNSS/baro updates then
re-anchor position and velocity with the inflated covariance.

Magnetometer heading (``sensors.magnetometer``, shared with the graph): at most one sample per
``mag_interval_s`` (its errors are correlated over seconds), y = wrap(azimuth of C̃ (z − b̂_m)
in n − declination), row ∂y/∂ψ (yaw component 1, tilt components through the dip) and
∂y/∂δb_m, χ²₁-gated and forced in after ``mag_reaccept_s`` of refusals. While the heading is
unknown the first sample acquires it (a heading reset like the track's, σ² = the heading noise
plus the hard-iron prior and tilt variances projected on it).

The baro prediction and its Jacobian are the shared model's (``sensors.baro.baro_predict`` /
``baro_row``), placed into these columns by ``rows.baro_rows``.
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
    """Continuous error-dynamics matrix F (NX, NX) of one grid interval (module docstring)."""
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
        # IMU gap (module docstring): no inertial data, constant-velocity nominal; only
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
    """Sequential scalar update, Joseph form expanded (module docstring). y = h(x̃) − z:
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
