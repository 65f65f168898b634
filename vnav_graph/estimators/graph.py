"""GTSAM factor-graph smoother: ``graph-batch`` (full batch) and ``graph-isam2`` (incremental).

The only modules that import gtsam are ``graph*.py``. Design (details and measurements in
``docs/graph.md``):

- Frame: one Earth-fixed tangent-plane NED frame ``t`` at ``Drive.origin_lla``;
  ``MakeSharedD(γ(origin))`` gravity, ``omegaCoriolis`` = Ω_ie resolved in t (exact for an
  Earth-fixed frame; centrifugal is inside normal gravity). The tilt and magnitude change of
  the true gravity over the drive, δg = C_tn(p)·[0, 0, γ(lat, h)] − [0, 0, γ0], is added to
  the specific force fed to the preintegration, rotated with the keyframe attitude estimate.
  Outputs are converted to geodetic lla (ellipsoidal heights) and local-level NED.
- Variables per keyframe k: X(k) Pose3, V(k) velocity, B(k) IMU bias, C(k) baro
  Gauss-Markov bias; K(j) = (s, τd) baro calibration (one for the batch, one per segment in
  the incremental front end).
- C++ factors: CombinedImuFactor (Forster et al. 2017), GPSFactorArm and velocity priors for
  fixes at keyframe epochs, priors, and the exact Gauss-Markov chain
  b_{k+1} = e^{−Δt/τ} b_k + w, var w = σ²(1 − e^{−2Δt/τ}) as linear factors.
- Baro samples and GNSS fixes between keyframes: linearised in numpy, vectorised over all
  samples (``graph_factors``), reduced to one information block per interval and added to the
  linearised C++ graph inside our own Gauss-Newton loop (batch), or wrapped once as
  ``LinearContainerFactor`` (incremental).

References: Forster et al., "On-Manifold Preintegration", IEEE T-RO 2017; Kaess et al.,
"iSAM2", IJRR 2012; Groves 2nd ed. §2.4, §5.4; seed 001 (baro error model).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import gtsam
import numpy as np
from gtsam.symbol_shorthand import B, C, K, V, X

from ..config import IMU_PRESETS, BaroSpec, ImuSpec
from ..geo.earth import gravity
from ..geo.frames import mat_to_quat, ned_to_lla
from ..sensors.noise import gm_process_var, gm_transition
from ..types import (
    ERROR_STATE,
    BaroEstimate,
    Drive,
    Estimate,
    FloatArray,
    ParamEstimate,
    Trajectory,
)
from . import graph_factors as gf
from . import graph_linalg as gla


@dataclass(frozen=True)
class GraphConfig:
    """Settings of the factor-graph smoothers (SI units).

    keyframe_dt: keyframe spacing [s]; max_iterations / rel_tol / abs_tol: Gauss-Newton
    stops when an iteration lowers the cost ½χ² by less than rel_tol·cost or abs_tol, or
    when the decrease predicted for the next step is below abs_tol (0.05: a χ² change of
    0.1, a tenth of the change that moves one parameter by 1σ; that step is not taken and
    its factorisation gives the covariance); bias_lag_tol [s]: the baro bias is read at
    t_s − λ, λ the latency at the start of the solve, re-set when τd moves further than this
    (``graph_factors.baro_rows``);
    output_rate_hz: rate of the output trajectory (interpolated between keyframes with the
    IMU-shaped interpolant); cov_epochs: maximum number of keyframes with an 18×18 covariance;
    gravity_correction / coriolis: tangent-frame corrections (off only for studies);
    segment_s: length of a baro-calibration segment in the incremental front end;
    calib_rw: random-walk root PSD of (s [1/√s], τd [s/√s]) between segments;
    relinearize_threshold: iSAM2 relinearisation threshold (one value for every component;
    used only when ``relinearize_typed`` is None; 0 switches relinearisation off);
    relinearize_typed: per-type thresholds (rotation [rad], translation [m], velocity [m/s],
    accel bias [m/s²], gyro bias [rad/s]) — the baro bias C and calibration K only appear in
    linear factors and are never relinearised; relinearize_skip: iSAM2 relinearizeSkip;
    partial_relinearization_check: iSAM2 option of that name; wildfire_threshold: iSAM2
    back-substitution threshold (None: GTSAM's 1e-3); see ``docs/graph.md`` for the measured
    per-update latencies; final_batch: run the batch solver after the incremental pass to
    produce the smoothed trajectory.
    gnss_gate_prob: probability of the χ² gates on GNSS fixes (0 switches gating off):
    a causal pre-gate of the GNSS height against the barometer and a post-solve gate of
    each fix's normalised position (+ velocity) residual, repeated ≤ ``gate_rounds`` times.
    """

    keyframe_dt: float = 1.0
    bias_lag_tol: float = 0.02
    max_iterations: int = 12
    rel_tol: float = 1e-7
    abs_tol: float = 0.05
    output_rate_hz: float = 20.0
    cov_epochs: int = 60
    gravity_correction: bool = True
    coriolis: bool = True
    segment_s: float = 60.0
    calib_rw: tuple[float, float] = (2e-5, 2e-4)
    relinearize_threshold: float = 0.05
    relinearize_skip: int = 10
    partial_relinearization_check: bool = False
    relinearize_typed: tuple[float, float, float, float, float] | None = (
        0.02, 1.0, 0.5, 0.1, 0.005)
    wildfire_threshold: float | None = 0.01
    final_batch: bool = True
    observable_ratio: float = 0.8
    gnss_gate_prob: float = 0.9999
    gate_rounds: int = 3
    verbose: bool = False


# ----------------------------------------------------------------------------------------
# Problem set-up shared by both estimators


@dataclass
class _Problem:
    drive: Drive
    cfg: GraphConfig
    origin: FloatArray
    h0: float
    g0: float
    omega_t: FloatArray
    kf_idx: np.ndarray
    t_kf: FloatArray
    dense: gf.DenseIncrements
    params: Any
    imu_spec: ImuSpec
    baro_spec: BaroSpec | None
    # GNSS in the tangent frame
    g_t: FloatArray
    g_pos: FloatArray
    g_pos_sd: FloatArray
    g_vel: FloatArray | None
    g_vel_sd: FloatArray | None
    lever: FloatArray
    g_kf: np.ndarray  # keyframe index of fixes on a keyframe epoch, −1 otherwise
    g_use: np.ndarray  # fixes not rejected by the gates (bool)
    g_rej_pre: int = 0  # rejected by the baro-consistency pre-gate
    g_rej_post: int = 0  # rejected by the post-solve residual gate
    g_incr: Any = None  # (fix indices, dense increments at them), see _gnss_rows_of

    @property
    def gnss_rejected(self) -> int:
        return int(np.sum(~self.g_use & (self.g_kf >= -1)))

    @property
    def n_kf(self) -> int:
        return int(self.t_kf.size)


def _floor(x: float, lo: float) -> float:
    return float(max(x, lo))


def _setup(drive: Drive, cfg: GraphConfig) -> _Problem:
    imu = drive.imu
    origin = np.asarray(drive.origin_lla, float)
    h0 = float(origin[2])
    g0 = float(gravity(origin[0], origin[2]))
    spec = imu.spec if isinstance(imu.spec, ImuSpec) else _spec_from_data(imu, origin)
    bspec = None
    if drive.baro is not None:
        bspec = drive.baro.spec if isinstance(drive.baro.spec, BaroSpec) else BaroSpec()
    kf_idx = gf.keyframe_indices(imu.t, cfg.keyframe_dt)
    dense = gf.dense_preintegration(imu.t, imu.gyro_b, imu.accel_b, kf_idx)
    omega_t = gf.earth_rate_t(origin) if cfg.coriolis else np.zeros(3)
    p = gtsam.PreintegrationCombinedParams.MakeSharedD(g0)
    # continuous-time densities (STYLE.md pitfall 3); floors keep noiseless drives regular
    p.setAccelerometerCovariance(np.eye(3) * _floor(spec.accel_noise_density, 1e-4) ** 2)
    p.setGyroscopeCovariance(np.eye(3) * _floor(spec.gyro_noise_density, 1e-6) ** 2)
    p.setIntegrationCovariance(np.eye(3) * 1e-8)
    # Gauss-Markov bias approximated by a random walk of PSD 2σ²/τ + rw²
    qa = 2 * spec.accel_bias_sd**2 / spec.accel_bias_tau + spec.accel_bias_rw**2
    qg = 2 * spec.gyro_bias_sd**2 / spec.gyro_bias_tau + spec.gyro_bias_rw**2
    p.setBiasAccCovariance(np.eye(3) * max(qa, 1e-12))
    p.setBiasOmegaCovariance(np.eye(3) * max(qg, 1e-16))
    p.setOmegaCoriolis(omega_t)
    gn = drive.gnss
    t_kf = imu.t[kf_idx]
    if gn is None or len(gn) == 0:
        raise ValueError("graph: the drive has no GNSS fixes (needed to anchor the graph)")
    pos = gf.to_tangent(gn.lla, origin)
    c_tn = gf.rot_t_n(gn.lla, origin)
    vel = None if gn.vel_n is None else np.einsum("nij,nj->ni", c_tn, gn.vel_n)
    j = np.clip(np.searchsorted(t_kf, gn.t), 0, t_kf.size - 1)
    on_kf = np.abs(t_kf[j] - gn.t) < 1e-6
    inside = (gn.t >= t_kf[0]) & (gn.t <= t_kf[-1])
    g_kf = np.where(on_kf, j, -1)
    g_kf[~inside] = -2
    use = _pregate_gnss(drive, gn.t, gn.lla[:, 2], gn.pos_sd[:, 2], _baro_priors(bspec),
                        cfg.gnss_gate_prob,
                        None if gn.vel_n is None else gn.vel_n[:, 2],
                        None if gn.vel_sd is None else gn.vel_sd[:, 2])
    P = _Problem(drive, cfg, origin, h0, g0, omega_t, kf_idx, t_kf, dense, p, spec, bspec,
                 gn.t, pos, gn.pos_sd, vel, gn.vel_sd, np.asarray(gn.lever_arm_b, float),
                 g_kf, use)
    P.g_rej_pre = P.gnss_rejected
    if not np.any(use & inside):
        raise ValueError("graph: every GNSS fix inside the IMU span was rejected by the "
                         "baro-consistency gate")
    return P


def _spec_from_data(imu: Any, origin: FloatArray) -> ImuSpec:
    """IMU noise model for a log without a spec: the consumer preset with data-driven floors.

    White-noise density from first differences, σ_w = std(Δf)/√2 per sample → density
    σ_w·√dt (vibration of a multirotor shows up here and must be treated as noise at the
    keyframe scale), and an accelerometer bias sigma of at least |median|f| − γ|, the
    specific-force magnitude error at rest-like epochs. The preset alone (3 mg/√Hz, 50 mg)
    made the IMU factors outweigh baro and GNSS by orders of magnitude on the Erle logs."""
    base = IMU_PRESETS["consumer"]
    dt = float(np.median(np.diff(imu.t))) if imu.t.size > 1 else 0.01
    if imu.t.size < 10:
        return base
    sa = float(np.median(np.std(np.diff(imu.accel_b, axis=0), axis=0))) / np.sqrt(2.0)
    sg = float(np.median(np.std(np.diff(imu.gyro_b, axis=0), axis=0))) / np.sqrt(2.0)
    fmag = float(np.median(np.linalg.norm(imu.accel_b, axis=1)))
    ba = abs(fmag - float(gravity(origin[0], origin[2])))
    from dataclasses import replace as _replace

    return _replace(base, accel_noise_density=max(base.accel_noise_density, sa * np.sqrt(dt)),
                    gyro_noise_density=max(base.gyro_noise_density, sg * np.sqrt(dt)),
                    accel_bias_sd=max(base.accel_bias_sd, 2.0 * ba))


def _pregate_gnss(drive: Drive, t: FloatArray, h: FloatArray, sd_h: FloatArray,
                  pri: dict[str, float], prob: float, vel_d: FloatArray | None = None,
                  vel_d_sd: FloatArray | None = None) -> np.ndarray:
    """Causal χ² gate of GNSS heights against the barometer; returns the mask of kept fixes.

    By the shared baro model, d = h_gnss(t) − h_baro(t + τ0) = −s·(h − h0) − b + noise: a
    2-state Kalman filter on x = [c, s] with d = c + s·(h_baro − h0) + v, c a random walk of
    PSD 2σ_b²/τ_b (the Gauss-Markov bias, Groves §14.2 / ``sensors.noise``), s ~ N(0, σ_s²),
    var v = σ_h,gnss² + σ_baro² + (v_up·σ_τ)². A fix whose innovation ν has ν²/S above the
    1-dof χ² quantile ``prob`` is rejected (not used to update), like the EKF's innovation
    gate; the prediction variance grows while fixes are refused, so the gate re-opens.
    When the log has GNSS velocity, a fix is also refused when −v_down disagrees with the
    baro climb rate (central difference over ±1 s): variance σ_vd² + (σ_baro/√2 /1 s)²
    + (σ_s·v)² + (0.5 m/s)² (vertical acceleration over the ±1 s difference window).
    """
    use = np.isfinite(h) & np.isfinite(sd_h)
    baro = drive.baro
    if baro is None or prob <= 0 or baro.t.size < 2:
        return use
    from scipy.stats import chi2

    thr = float(chi2.ppf(prob, 1))
    bt, bz = baro.t, baro.altitude
    inside = use & (t + pri["tau0"] >= bt[0]) & (t + pri["tau0"] <= bt[-1])
    idx = np.flatnonzero(inside)
    if idx.size == 0:
        return use
    tt = t[idx] + pri["tau0"]
    hb = np.interp(tt, bt, bz)
    v_up = (np.interp(tt + 1.0, bt, bz) - np.interp(tt - 1.0, bt, bz)) / 2.0
    d = h[idx] - hb
    r = sd_h[idx] ** 2 + pri["noise"] ** 2 + (v_up * pri["tau_sd"]) ** 2
    hrel = hb - drive.origin_lla[2]
    q_rate = 2.0 * pri["b_sd"] ** 2 / pri["b_tau"]
    n0 = min(10, idx.size)
    c0 = float(np.median(d[:n0]))
    mad = float(np.median(np.abs(d[:n0] - c0))) * 1.4826
    x = np.array([c0, 0.0])
    pm = np.diag([mad**2 + float(np.median(r[:n0])), pri["s_sd"] ** 2])
    keep = np.ones(idx.size, bool)
    if vel_d is not None and vel_d_sd is not None:
        var_v = (vel_d_sd[idx] ** 2 + 0.5 * pri["noise"] ** 2 + (pri["s_sd"] * v_up) ** 2
                 + 0.5**2)
        nu_v = -vel_d[idx] - v_up
        keep &= ~(nu_v**2 > thr * var_v) & np.isfinite(nu_v)
    t_prev = tt[0]
    for i in range(idx.size):
        pm[0, 0] += q_rate * max(tt[i] - t_prev, 0.0)
        t_prev = tt[i]
        if not keep[i]:
            continue
        hv = np.array([1.0, hrel[i]])
        nu = d[i] - hv @ x
        ph = pm @ hv
        s_inn = hv @ ph + r[i]
        if nu * nu > thr * s_inn:
            keep[i] = False
            continue
        kg = ph / s_inn
        x = x + kg * nu
        pm = pm - np.outer(kg, ph)
    use[idx[~keep]] = False
    return use


def _baro_priors(bs: BaroSpec | None) -> dict[str, float]:
    """Prior mean and sigma of s, τd and b_0 from the baro spec (uniform latency range →
    its mean and width/√12)."""
    if bs is None:
        return {"s_sd": 0.01, "tau0": 0.1, "tau_sd": 0.1, "b_sd": 3.0, "b_tau": 1800.0,
                "noise": 0.3}
    if bs.latency_range_s is not None:
        lo, hi = bs.latency_range_s
        tau0, tau_sd = 0.5 * (lo + hi), max((hi - lo) / np.sqrt(12.0), 0.01)
    else:
        tau0, tau_sd = bs.latency_s, 0.05
    s_sd = bs.scale_sd if bs.scale is None else max(bs.scale_sd, 1e-4)
    return {"s_sd": max(s_sd, 1e-4), "tau0": tau0, "tau_sd": tau_sd,
            "b_sd": max(bs.bias_sd, 1e-3), "b_tau": bs.bias_tau, "noise": max(bs.noise_sd, 1e-3)}


def _so3_exp(phi: FloatArray) -> FloatArray:
    return gtsam.Rot3.Expmap(phi).matrix()


def _initial_states(P: _Problem) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Initial R_tb, p_t, v_t at keyframes from GNSS and the IMU (no filter involved).

    Position/velocity: GNSS at keyframes (lever arm removed), else propagated with the
    preintegrated increments. Attitude: TRIAD of (specific force, velocity direction) —
    f_t = a_t − g_t (a_t from differenced GNSS velocity) against the mean measured f_b, and the
    body x axis along the GNSS velocity when moving faster than 3 m/s; otherwise propagated
    with the gyro increments (backwards before the first valid alignment)."""
    imu = P.drive.imu
    nk = P.n_kf
    dr_t, dv_t, dp_t = P.dense.end()
    u = P.g_use
    gt, pos = P.g_t[u], P.g_pos[u]
    vel = None if P.g_vel is None else P.g_vel[u]
    near = np.min(np.abs(gt[None, :] - P.t_kf[:, None]), axis=1) if nk * gt.size < 5e7 else \
        np.abs(gt[np.clip(np.searchsorted(gt, P.t_kf), 0, gt.size - 1)] - P.t_kf)
    rate = 1.0 / max(float(np.median(np.diff(gt))), 1e-3) if gt.size > 1 else 1.0
    has = near <= max(0.6 / rate, 0.02)
    pos_kf = np.column_stack([np.interp(P.t_kf, gt, pos[:, i]) for i in range(3)])
    if vel is None:
        dtw = 0.5
        vel_src = (np.column_stack([np.interp(P.t_kf + dtw, gt, pos[:, i]) for i in range(3)])
                   - np.column_stack([np.interp(P.t_kf - dtw, gt, pos[:, i])
                                      for i in range(3)])) / (2 * dtw)
        vel_kf = vel_src
        acc_kf = np.zeros((nk, 3))
        acc_ok = np.zeros(nk, bool)
    else:
        vel_kf = np.column_stack([np.interp(P.t_kf, gt, vel[:, i]) for i in range(3)])
        w = 0.5
        vp = np.column_stack([np.interp(P.t_kf + w, gt, vel[:, i]) for i in range(3)])
        vm = np.column_stack([np.interp(P.t_kf - w, gt, vel[:, i]) for i in range(3)])
        acc_kf = (vp - vm) / (2 * w)
        acc_ok = has & (np.abs(P.t_kf + w - P.t_kf.clip(gt[0], gt[-1])) >= 0)
    # inside gaps > 5 s between kept fixes: linear bridge horizontally, baro height
    # (plus the median GNSS − baro offset) vertically when a barometer is present
    gap_len = np.zeros(nk)
    if gt.size > 1:
        j = np.clip(np.searchsorted(gt, P.t_kf), 1, gt.size - 1)
        gap_len = gt[j] - gt[j - 1]
    in_gap = ~has & (gap_len > 5.0) & (P.t_kf > gt[0]) & (P.t_kf < gt[-1])
    baro = P.drive.baro
    if baro is not None and np.any(in_gap) and baro.t.size > 1:
        hg = ned_to_lla(pos, P.origin)[:, 2]
        off = float(np.median(hg - np.interp(gt, baro.t, baro.altitude)))
        hb = np.interp(P.t_kf[in_gap], baro.t, baro.altitude) + off
        pos_kf[in_gap, 2] = -(hb - P.h0)
        vz = -np.gradient(np.interp(P.t_kf, baro.t, baro.altitude), P.t_kf)
        vel_kf[in_gap, 2] = vz[in_gap]
    g_kf = gf.gravity_t(pos_kf, P.origin)
    # mean measured specific force over ±0.25 s
    cs = np.vstack([np.zeros((1, 3)), np.cumsum(imu.accel_b, axis=0)])
    lo = np.searchsorted(imu.t, P.t_kf - 0.25)
    hi = np.searchsorted(imu.t, P.t_kf + 0.25, side="right")
    f_b = (cs[hi] - cs[lo]) / np.maximum(hi - lo, 1)[:, None]
    f_t = acc_kf - g_kf + 2 * np.cross(P.omega_t, vel_kf)
    speed = np.linalg.norm(vel_kf[:, :2], axis=1)
    triad_ok = has & acc_ok & (speed > 3.0) & (vel is not None)
    rot_triad = np.zeros((nk, 3, 3))
    for k in np.flatnonzero(triad_ok):
        rot_triad[k] = _triad(f_b[k], np.array([1.0, 0.0, 0.0]), f_t[k], vel_kf[k])
    k0 = int(np.flatnonzero(triad_ok)[0]) if triad_ok.any() else -1
    if k0 < 0:
        r = _level(f_b[0])
    else:
        r = rot_triad[k0]
        for k in range(k0 - 1, -1, -1):
            r = _so3_exp(P.omega_t * (P.t_kf[k + 1] - P.t_kf[k])) @ r @ dr_t[k].T
    rot = np.zeros((nk, 3, 3))
    p_out = np.zeros((nk, 3))
    v_out = np.zeros((nk, 3))
    rot[0] = r
    p_out[0] = pos_kf[0] - r @ P.lever if has[0] else pos_kf[0]
    v_out[0] = vel_kf[0]
    for k in range(nk - 1):
        T = P.t_kf[k + 1] - P.t_kf[k]
        a = g_kf[k] - 2 * np.cross(P.omega_t, v_out[k])
        rr = rot[k]
        p1 = p_out[k] + v_out[k] * T + 0.5 * a * T * T + rr @ dp_t[k]
        v1 = v_out[k] + a * T + rr @ dv_t[k]
        r1 = _so3_exp(-P.omega_t * T) @ rr @ dr_t[k]
        if triad_ok[k + 1]:
            r1 = rot_triad[k + 1]
        if has[k + 1]:
            p1 = pos_kf[k + 1] - r1 @ P.lever
            v1 = vel_kf[k + 1]
        elif in_gap[k + 1]:
            # long gap between kept fixes (outage or rejected fixes): IMU propagation from
            # unknown biases drifts far outside Gauss-Newton's basin; bridge it instead
            p1, v1 = pos_kf[k + 1], vel_kf[k + 1]
        rot[k + 1], p_out[k + 1], v_out[k + 1] = r1, p1, v1
    return rot, p_out, v_out


def _unit(x: FloatArray) -> FloatArray:
    return x / np.linalg.norm(x)


def _triad(f_b: FloatArray, x_b: FloatArray, f_t: FloatArray, v_t: FloatArray) -> FloatArray:
    b1, n1 = _unit(f_b), _unit(f_t)
    b2, n2 = _unit(np.cross(f_b, x_b)), _unit(np.cross(f_t, v_t))
    mb = np.column_stack([b1, b2, np.cross(b1, b2)])
    mn = np.column_stack([n1, n2, np.cross(n1, n2)])
    return mn @ mb.T


def _level(f_b: FloatArray) -> FloatArray:
    """Roll/pitch from a static specific force, yaw 0."""
    roll = np.arctan2(-f_b[1], -f_b[2])
    pitch = np.arctan2(f_b[0], np.hypot(f_b[1], f_b[2]))
    return gtsam.Rot3.Ypr(0.0, pitch, roll).matrix()


def _gravity_delta(P: _Problem, pos: FloatArray) -> FloatArray:
    """δg_k = g_t(p_k) − [0, 0, γ0] (K, 3) [m/s²] (zero when the correction is disabled)."""
    if not P.cfg.gravity_correction:
        return np.zeros_like(pos)
    return gf.gravity_t(pos, P.origin) - np.array([0.0, 0.0, P.g0])


def _preintegrate(P: _Problem, k: int, r_k: FloatArray, dg_k: FloatArray,
                  bias: Any) -> Any:
    """Preintegrate interval k with midpoint samples; δg folded into the specific force:
    f' = f + (R_k ΔR_j)ᵀ δg_k."""
    imu = P.drive.imu
    j0, j1 = int(P.kf_idx[k]), int(P.kf_idx[k + 1])
    fm = 0.5 * (imu.accel_b[j0:j1] + imu.accel_b[j0 + 1:j1 + 1])
    wm = 0.5 * (imu.gyro_b[j0:j1] + imu.gyro_b[j0 + 1:j1 + 1])
    if np.any(dg_k):
        fm = fm + np.einsum("nji,j->ni", P.dense.dr[j0:j1], r_k.T @ dg_k)
    dts = np.diff(imu.t[j0:j1 + 1])
    pim = gtsam.PreintegratedCombinedMeasurements(P.params, bias)
    integ = pim.integrateMeasurement
    for a, w, dt in zip(fm, wm, dts, strict=True):
        integ(a, w, dt)
    return pim


def _noise(sd: FloatArray) -> Any:
    return gtsam.noiseModel.Diagonal.Sigmas(np.asarray(sd, dtype=float))


def _prior_factors(P: _Problem, r0: FloatArray, p0: FloatArray, v0: FloatArray,
                   pri: dict[str, float], calib_key: int) -> gtsam.NonlinearFactorGraph:
    g = gtsam.NonlinearFactorGraph()
    s = P.imu_spec
    g.add(gtsam.PriorFactorPose3(X(0), gtsam.Pose3(gtsam.Rot3(r0), p0),
                                 _noise([0.05, 0.05, 0.5, 10.0, 10.0, 10.0])))
    g.add(gtsam.PriorFactorVector(V(0), v0, _noise([2.0, 2.0, 2.0])))
    g.add(gtsam.PriorFactorConstantBias(
        B(0), gtsam.imuBias.ConstantBias(),
        _noise([_floor(s.accel_bias_sd, 1e-4)] * 3 + [_floor(s.gyro_bias_sd, 1e-6)] * 3)))
    if P.drive.baro is not None:
        g.add(gtsam.PriorFactorVector(C(0), np.zeros(1), _noise([pri["b_sd"]])))
        g.add(gtsam.PriorFactorVector(calib_key, np.array([0.0, pri["tau0"]]),
                                      _noise([pri["s_sd"], pri["tau_sd"]])))
    return g


def _keyframe_fix_factors(P: _Problem, k: int) -> list[Any]:
    out = []
    for i in np.flatnonzero((P.g_kf == k) & P.g_use):
        out.append(gtsam.GPSFactorArm(X(k), P.g_pos[i], P.lever, _noise(P.g_pos_sd[i])))
        if P.g_vel is not None and P.g_vel_sd is not None and not np.any(P.lever):
            out.append(gtsam.PriorFactorVector(V(k), P.g_vel[i], _noise(P.g_vel_sd[i])))
    return out


def _gm_factor(k: int, dt: float, pri: dict[str, float]) -> Any:
    """Exact discrete Gauss-Markov link b_{k+1} − φ b_k = w as a (linear) C++ factor."""
    phi = float(gm_transition(dt, pri["b_tau"]))
    sd = float(np.sqrt(max(gm_process_var(dt, pri["b_tau"], pri["b_sd"]), 1e-12)))
    jf = gtsam.JacobianFactor(C(k), np.array([[-phi]]), C(k + 1), np.array([[1.0]]),
                              np.zeros(1), _noise([sd]))
    lin = gtsam.Values()
    lin.insert(C(k), np.zeros(1))
    lin.insert(C(k + 1), np.zeros(1))
    return gtsam.LinearContainerFactor(jf, lin)


# ----------------------------------------------------------------------------------------
# Interval terms → GTSAM Hessian blocks


def _states_from_values(P: _Problem, vals: Any, calib_of_kf: np.ndarray) -> gf.KeyframeStates:
    nk = P.n_kf
    poses = gtsam.utilities.extractPose3(vals)
    rot = poses[:, :9].reshape(nk, 3, 3)
    pos = poses[:, 9:12]
    vel = gtsam.utilities.extractVectors(vals, "v")
    at_bias = vals.atConstantBias
    ba = np.array([at_bias(B(k)).accelerometer() for k in range(nk)])
    if P.drive.baro is not None:
        cb = gtsam.utilities.extractVectors(vals, "c")[:, 0]
        cal = {int(j): vals.atVector(K(int(j))) for j in np.unique(calib_of_kf)}
        s = np.array([cal[int(j)][0] for j in calib_of_kf])
        tau = np.array([cal[int(j)][1] for j in calib_of_kf])
    else:
        cb = np.zeros(nk)
        s = np.zeros(nk)
        tau = np.zeros(nk)
    dg = _gravity_delta(P, pos)
    acc = np.array([0.0, 0.0, P.g0]) + dg - 2 * np.cross(P.omega_t, vel)
    return gf.KeyframeStates(rot, pos, vel, ba, cb, s, tau, acc)


def _gnss_batch_idx(P: _Problem) -> np.ndarray:
    """Fixes used by the batch: every kept fix inside the keyframe span (on keyframe epochs
    too — at τ = 0 the interpolant is exactly X_k, so the row equals GPSFactorArm's)."""
    return np.flatnonzero(P.g_use & (P.g_kf >= -1))


def _gnss_rows_of(P: _Problem, st: gf.KeyframeStates, idx: np.ndarray) -> gf.IntervalRows:
    t_g = P.g_t[idx]
    # the IMU increments at the fixes depend on the fix times only: cached per fix set
    if P.g_incr is None or not np.array_equal(P.g_incr[0], idx):
        k = np.clip(np.searchsorted(P.t_kf, t_g, side="right") - 1, 0, P.n_kf - 2)
        P.g_incr = (idx, P.dense.at(t_g, k))
    return gf.gnss_rows(
        P.dense, st, t_g, P.g_pos[idx], P.g_pos_sd[idx],
        None if P.g_vel is None else P.g_vel[idx],
        None if P.g_vel_sd is None else P.g_vel_sd[idx], P.lever, incr=P.g_incr[1])


def _interval_rows(P: _Problem, st: gf.KeyframeStates, pri: dict[str, float],
                   bias_lag: float | None) -> gf.IntervalRows:
    """Baro and GNSS interval rows; ``bias_lag``: see ``graph_factors.baro_rows``."""
    parts = []
    if P.drive.baro is not None:
        bt = P.drive.baro.t
        m = (bt >= P.t_kf[0]) & (bt <= P.t_kf[-1])
        parts.append(gf.baro_rows(P.dense, st, bt[m], P.drive.baro.altitude[m], pri["noise"],
                                  P.h0, P.origin, bias_lag=bias_lag))
    idx = _gnss_batch_idx(P)
    if idx.size:
        parts.append(_gnss_rows_of(P, st, idx))
    return gf.concat_rows(*parts)


def _gnss_chi2(P: _Problem, st: gf.KeyframeStates, idx: np.ndarray) -> tuple[FloatArray, int]:
    """χ² of each fix's whitened residual at the solution (position, + velocity when the log
    has it) and its degrees of freedom."""
    rows = _gnss_rows_of(P, st, idx)
    m = idx.size
    r = rows.r.reshape(-1, m, 3)  # (1 or 2, m, 3): position rows, then velocity rows
    return np.sum(r**2, axis=(0, 2)), 3 * r.shape[0]


def _group_keys(P: _Problem, k: int, calib_key: int) -> list[int]:
    return [X(k), X(k + 1), C(k), C(k + 1), calib_key]


def _hessian_pieces(keys: list[int], lam: FloatArray, eta: FloatArray,
                    active: tuple[int, ...]) -> list[Any]:
    """Split one group's information (16×16, η) into ≤3-key HessianFactors (pair cover)."""
    blocks = gf.BLOCKS
    sl = [slice(a, a + n) for a, n in blocks]
    if len(active) <= 3:
        trip = [tuple(active)]
    else:
        trip = [tr for tr in gf.PAIR_COVER]
    owned_pair: set[tuple[int, int]] = set()
    owned_diag: set[int] = set()
    out = []
    for tr in trip:
        tr = tuple(b for b in tr if b in active)
        gmat = {}
        gvec = {}
        for a_i, a in enumerate(tr):
            gvec[a] = (eta[sl[a]] if a not in owned_diag else np.zeros(blocks[a][1]))
            for b in tr[a_i:]:
                if a == b:
                    gmat[a, a] = lam[sl[a], sl[a]] if a not in owned_diag else \
                        np.zeros((blocks[a][1],) * 2)
                elif (a, b) in owned_pair:
                    gmat[a, b] = np.zeros((blocks[a][1], blocks[b][1]))
                else:
                    gmat[a, b] = lam[sl[a], sl[b]]
                    owned_pair.add((a, b))
        owned_diag.update(tr)
        kk = [keys[a] for a in tr]
        if len(tr) == 3:
            a, b, c = tr
            out.append(gtsam.HessianFactor(kk[0], kk[1], kk[2], gmat[a, a], gmat[a, b],
                                           gmat[a, c], gvec[a], gmat[b, b], gmat[b, c], gvec[b],
                                           gmat[c, c], gvec[c], 0.0))
        elif len(tr) == 2:
            a, b = tr
            out.append(gtsam.HessianFactor(kk[0], kk[1], gmat[a, a], gmat[a, b], gvec[a],
                                           gmat[b, b], gvec[b], 0.0))
        else:
            (a,) = tr
            out.append(gtsam.HessianFactor(kk[0], gmat[a, a], gvec[a], 0.0))
    return out


# ----------------------------------------------------------------------------------------
# Batch Gauss-Newton on our own banded-arrow normal equations (graph_linalg)


@dataclass
class _Layout:
    """Column layout of the batch normal equations: keyframe k owns columns
    k·bs + [X (6, Pose3 tangent: rotation, translation), V (3), B (6, accel then gyro), C (1)]
    (bs = 16, or 15 without baro), then the global (s, τd) of K(0). ``g2m`` maps GTSAM's
    sparse-Jacobian columns (keys in sorted order) to ours."""

    nk: int
    bs: int
    has_baro: bool
    n_band: int
    n_cols: int
    g2m: np.ndarray
    keys: list[Any]
    pattern: Any = None  # _SparsePattern of the graph last linearised with this layout

    @property
    def bandwidth(self) -> int:
        return 2 * self.bs - 1

    @property
    def term_cols(self) -> np.ndarray:
        """Interval-term columns (graph_factors order) present in this layout."""
        core = np.arange(gf.N_CORE if self.has_baro else 12)
        return np.r_[core, np.arange(gf.N_CORE, gf.N_COLS)]

    def block_cols(self, k: np.ndarray) -> np.ndarray:
        """Our columns of the interval-term blocks (X_k, X_k+1, [C_k, C_k+1, K,] accel bias
        of B_k), in the order of ``term_cols`` (G, 19|15)."""
        k = np.asarray(k)[:, None]
        six = np.arange(6)[None, :]
        parts = [k * self.bs + six, (k + 1) * self.bs + six]
        if self.has_baro:
            parts += [k * self.bs + 15, (k + 1) * self.bs + 15,
                      np.full_like(k, self.n_band), np.full_like(k, self.n_band + 1)]
        parts.append(k * self.bs + 9 + np.arange(3)[None, :])
        return np.concatenate(parts, axis=1)

    def vector_values(self, delta: FloatArray) -> Any:
        vv = gtsam.VectorValues()
        ins = vv.insert
        bs = self.bs
        d = delta[:self.n_band].reshape(self.nk, bs)
        for k in range(self.nk):
            row = d[k]
            ins(X(k), row[0:6])
            ins(V(k), row[6:9])
            ins(B(k), row[9:15])
            if self.has_baro:
                ins(C(k), row[15:16])
        if self.has_baro:
            ins(K(0), delta[self.n_band:])
        return vv


def _layout(P: _Problem) -> _Layout:
    nk = P.n_kf
    has_baro = P.drive.baro is not None
    bs = 16 if has_baro else 15
    n_band = nk * bs
    items = []
    for k in range(nk):
        o = k * bs
        items += [(X(k), 6, o), (V(k), 3, o + 6), (B(k), 6, o + 9)]
        if has_baro:
            items.append((C(k), 1, o + 15))
    if has_baro:
        items.append((K(0), 2, n_band))
    items.sort(key=lambda it: it[0])
    g2m = np.concatenate([off + np.arange(dim) for _, dim, off in items])
    n_cols = n_band + (2 if has_baro else 0)
    return _Layout(nk, bs, has_baro, n_band, n_cols, g2m, [it[0] for it in items])


@dataclass
class _BatchResult:
    values: Any
    graph: Any  # C++ NonlinearFactorGraph
    cost: float
    iterations: int
    calib_of_kf: np.ndarray
    layout: _Layout
    rows: gf.IntervalRows  # interval terms linearised at ``values``
    fac: gla.ArrowFactor | None = None  # factorised normal equations at ``values``, if kept
    bias_lag: float = 0.0  # baro-bias read time offset of the last solve (baro_rows)


@dataclass
class _SparsePattern:
    """Row/column bookkeeping of GTSAM's sparse Jacobian of one graph: the pattern (entry
    order included) is the same at every linearisation point, so it is computed once."""

    i: np.ndarray
    j: np.ndarray
    rhs_entries: np.ndarray  # entries of the right-hand-side column
    rhs_rows: np.ndarray
    a_sorted: np.ndarray  # matrix entries, ordered by row
    cols_sorted: np.ndarray  # their columns in our layout
    indptr: np.ndarray
    n_rows: int


def _sparse_pattern(lay: _Layout, i: np.ndarray, j: np.ndarray) -> _SparsePattern:
    pat = lay.pattern
    if pat is not None and np.array_equal(pat.i, i) and np.array_equal(pat.j, j):
        return pat
    if int(j.max()) != lay.n_cols:
        raise RuntimeError("graph: linearised C++ graph does not cover the expected variables")
    is_b = j == lay.n_cols
    nrow = int(i.max()) + 1
    a = np.flatnonzero(~is_b)
    order = np.argsort(i[a], kind="stable")
    pat = _SparsePattern(i, j, np.flatnonzero(is_b), i[is_b], a[order],
                         lay.g2m[j[a[order]]],
                         np.r_[0, np.cumsum(np.bincount(i[a], minlength=nrow))], nrow)
    lay.pattern = pat
    return pat


def _normal_equations(P: _Problem, lay: _Layout, graph: Any, vals: Any,
                      rows: gf.IntervalRows) -> tuple[Any, ...]:
    """Arrow-form normal equations of the C++ factors (GTSAM linearisation, sparse Jacobian)
    plus the interval terms (per-interval information blocks)."""
    gfg = graph.linearize(vals)
    sj = gfg.sparseJacobian_()
    pat = _sparse_pattern(lay, sj[0].astype(np.int64) - 1, sj[1].astype(np.int64) - 1)
    v = sj[2]
    b = np.zeros(pat.n_rows)
    b[pat.rhs_rows] = v[pat.rhs_entries]
    # interval terms: reduced per interval to (Λ_k, η_k) (batched BLAS), added as blocks
    groups, lam, eta, _ = gf.group_information(rows, P.n_kf - 1)
    tc = lay.term_cols
    return gla.assemble(lay.n_cols, lay.n_band, lay.bandwidth, pat.indptr, pat.cols_sorted,
                        v[pat.a_sorted], b,
                        lay.block_cols(groups), lam[:, tc[:, None], tc[None, :]], eta[:, tc])


def _factorize(ab: FloatArray, bm: FloatArray, dm: FloatArray) -> gla.ArrowFactor:
    """Cholesky of the normal equations; if H is numerically singular (e.g. 1 Hz averaged
    IMU with an unobservable direction), retry with growing Marquardt damping μ·diag(H)."""
    mu = 0.0
    for _ in range(6):
        try:
            if mu == 0.0:
                return gla.factorize(ab, bm, dm)
            ab2 = ab.copy()
            ab2[0] += mu * ab[0] + 1e-12
            return gla.factorize(ab2, bm, dm + np.diag(mu * np.diag(dm) + 1e-12))
        except gla.LinAlgError:
            mu = 1e-9 if mu == 0.0 else mu * 100.0
    raise RuntimeError(
        "graph: the Gauss-Newton system stays singular even with Marquardt damping 1e-1·diag(H) "
        "— the drive does not determine the states (check IMU rate/units and GNSS coverage)")


def _damped(ab: FloatArray, bm: FloatArray, dm: FloatArray, mu: float) -> gla.ArrowFactor:
    """Factorisation of H + μ·diag(H) (Levenberg-Marquardt damping)."""
    ab2 = ab.copy()
    ab2[0] *= 1.0 + mu
    return _factorize(ab2, bm, dm + mu * np.diag(np.diag(dm)))


def _gn_core(P: _Problem, lay: _Layout, graph: Any, vals: Any, calib_of_kf: np.ndarray,
             pri: dict[str, float]) -> _BatchResult:
    """Gauss-Newton on the total cost (C++ factors + interval terms); a step that raises the
    cost is retried with Levenberg-Marquardt damping μ·diag(H) (μ from 1e-5, ×10 per
    retry, ÷10 after a success, back to plain Gauss-Newton below 1e-6). On the simulated
    drives every full step is accepted; on hovering-multirotor logs the weakly determined
    heading makes the full step overshoot (docs/graph.md). The interval rows evaluated at an
    accepted candidate are reused as its linearisation."""
    st = _states_from_values(P, vals, calib_of_kf)
    # the baro bias is read at t_s − λ with λ fixed while τd moves, so that the cost is smooth
    # along τd (graph_factors.baro_rows); λ follows τd when they drift > bias_lag_tol apart
    lag = float(np.median(st.latency))
    rows = _interval_rows(P, st, pri, lag)
    cost = graph.error(vals) + 0.5 * float(rows.r @ rows.r)
    it = 0
    fac = None
    mu = 0.0
    for it in range(1, P.cfg.max_iterations + 1):
        ab, bm, dm, g = _normal_equations(P, lay, graph, vals, rows)
        fac = _factorize(ab, bm, dm)
        delta = fac.solve(g)
        dec = 0.5 * float(delta @ g)  # decrease predicted by the quadratic model
        if P.cfg.verbose:
            print(f"GN it {it}: predicted decrease {dec:.3g}")
        if dec < P.cfg.abs_tol:
            # converged at ``vals``: the step is not taken, and this factorisation — of the
            # normal equations at the solution — is kept for the covariance
            break
        fac = None
        if mu > 0.0:
            delta = _damped(ab, bm, dm, mu).solve(g)
        failed = False
        while True:
            cand = vals.retract(lay.vector_values(delta))
            st_c = _states_from_values(P, cand, calib_of_kf)
            lat = float(np.median(st_c.latency))
            lag_c = lat if abs(lat - lag) > P.cfg.bias_lag_tol else lag
            rows_c = _interval_rows(P, st_c, pri, lag_c)
            new_cost = graph.error(cand) + 0.5 * float(rows_c.r @ rows_c.r)
            ref = cost
            if lag_c != lag and new_cost > cost:
                # λ moved with τd: a slightly different cost function — compare the
                # candidate with the current point under the new λ (rare: early iterations
                # gain far more than the ≈ 10 that moving λ by tens of ms changes)
                r_ref = _interval_rows(P, st, pri, lag_c).r
                ref = graph.error(vals) + 0.5 * float(r_ref @ r_ref)
            if new_cost <= ref * (1 + 1e-12):
                mu = 0.0 if mu <= 1e-6 else mu / 10.0
                break
            if mu == 0.0 and abs(new_cost - ref) < P.cfg.rel_tol * ref:
                break  # converged: the change is at round-off level
            mu = 1e-5 if mu == 0.0 else mu * 10.0
            if mu > 1e3:
                failed = True  # no descent even as a tiny gradient step: stop here
                break
            delta = _damped(ab, bm, dm, mu).solve(g)
        if failed:
            if P.cfg.verbose:
                print(f"GN it {it}: no step lowers the cost (μ > 1e3); stopping")
            break
        rel = (cost - new_cost) / max(cost, 1e-12)
        if P.cfg.verbose:
            print(f"GN it {it}: cost {cost:.10g} -> {new_cost:.10g} μ {mu:.0e}"
                  + (f" (bias lag {lag:.4f} -> {lag_c:.4f} s)" if lag_c != lag else ""))
        cost_prev = cost
        vals, st, rows, cost = cand, st_c, rows_c, new_cost
        if lag_c != lag:
            lag = lag_c  # a new cost function: no convergence test on this step
            continue
        if mu == 0.0 and (abs(rel) < P.cfg.rel_tol or abs(cost_prev - cost) < P.cfg.abs_tol):
            break
    return _BatchResult(vals, graph, cost, it, calib_of_kf, lay, rows, fac, lag)


def _gauss_newton(P: _Problem, graph: Any, vals: Any, calib_of_kf: np.ndarray,
                  pri: dict[str, float]) -> _BatchResult:
    """Gauss-Newton solve, then the post-solve GNSS gate: fixes whose whitened residual χ²
    (3 dof position, 6 with velocity) exceeds the ``gnss_gate_prob`` quantile are rejected
    and the problem re-solved from the current solution (≤ ``gate_rounds`` rounds).
    The residual of a fix that took part in the fit is smaller than its innovation, so the
    gate is conservative (Groves §17.3)."""
    lay = _layout(P)
    res = _gn_core(P, lay, graph, vals, calib_of_kf, pri)
    if P.cfg.gnss_gate_prob <= 0:
        return res
    from scipy.stats import chi2

    iters = res.iterations
    for _ in range(P.cfg.gate_rounds):
        idx = _gnss_batch_idx(P)
        if idx.size == 0:
            break
        st = _states_from_values(P, res.values, calib_of_kf)
        c2, dof = _gnss_chi2(P, st, idx)
        # post-solve gate at the squared tail probability: a false rejection costs a whole
        # re-solve, a glitch has χ² in the thousands either way
        bad = c2 > chi2.ppf(1.0 - (1.0 - P.cfg.gnss_gate_prob) ** 2, dof)
        if not np.any(bad) or np.all(bad):
            break
        P.g_use[idx[bad]] = False
        P.g_rej_post += int(bad.sum())
        res = _gn_core(P, lay, graph, res.values, calib_of_kf, pri)
        iters += res.iterations
    res.iterations = iters
    return res



# ----------------------------------------------------------------------------------------
# Outputs


def _output_times(P: _Problem) -> FloatArray:
    t = P.drive.imu.t
    n = max(int(round(P.cfg.output_rate_hz and (1.0 / P.cfg.output_rate_hz) / np.median(
        np.diff(t)))), 1)
    idx = np.unique(np.r_[np.arange(0, t.size, n), P.kf_idx])
    idx = idx[(idx >= P.kf_idx[0]) & (idx <= P.kf_idx[-1])]
    return t[idx]


def _trajectory(P: _Problem, st: gf.KeyframeStates, vals: Any, t_q: FloatArray) -> Trajectory:
    k = np.clip(np.searchsorted(P.t_kf, t_q, side="right") - 1, 0, P.n_kf - 2)
    ip = gf.interpolate(P.dense, st, t_q, k)
    lla = ned_to_lla(ip["p"], P.origin)
    c_tn = gf.rot_t_n(lla, P.origin)
    vel_n = np.einsum("nji,nj->ni", c_tn, ip["v"])
    # exact keyframe velocities at keyframe epochs
    on = np.isin(t_q, P.t_kf)
    kk = np.searchsorted(P.t_kf, t_q[on])
    vel_n[on] = np.einsum("nji,nj->ni", c_tn[on], st.vel[kk])
    q = mat_to_quat(np.swapaxes(c_tn, 1, 2) @ ip["rot"])
    nk = P.n_kf
    bias = np.array([vals.atConstantBias(B(j)).vector() for j in range(nk)])
    alpha = ip["alpha"]
    bg = bias[k, 3:6]
    ba = bias[k, 0:3]
    bb = (1 - alpha) * st.baro_bias[k] + alpha * st.baro_bias[k + 1]
    return Trajectory(t_q, lla, vel_n, q, bg, ba, bb if P.drive.baro is not None else None)


def _cov_18(P: _Problem, fac: gla.ArrowFactor, sb: FloatArray, lay: _Layout, vals: Any,
            k: int) -> FloatArray:
    """18×18 ERROR_STATE covariance at keyframe k from the selected inverse of the final
    normal equations (joint marginal of X_k, V_k, B_k, C_k and the global (s, τd)).

    Pose3 tangent (ω_b, v_b): att_t = R ω_b, δp_t = R v_b; then t → local NED with C_nt.
    ConstantBias (accel, gyro) → bias_gyro 9:12, bias_accel 12:15 (body frame)."""
    full = fac.cov_block(sb, k * lay.bs + np.arange(lay.bs))
    n = full.shape[0]
    r = vals.atPose3(X(k)).rotation().matrix()
    lla = ned_to_lla(vals.atPose3(X(k)).translation()[None, :], P.origin)
    c_nt = gf.rot_t_n(lla, P.origin)[0].T
    tmat = np.zeros((18, n))
    tmat[6:9, 0:3] = c_nt @ r
    tmat[0:3, 3:6] = c_nt @ r
    tmat[3:6, 6:9] = c_nt
    tmat[12:15, 9:12] = np.eye(3)
    tmat[9:12, 12:15] = np.eye(3)
    if P.drive.baro is not None:
        tmat[17, 15] = 1.0
        tmat[15, 16] = 1.0
        tmat[16, 17] = 1.0
    cov = tmat @ full @ tmat.T
    if P.drive.baro is None:
        cov[15:18, :] = np.nan
        cov[:, 15:18] = np.nan
    return cov


def _gm_mean_prior_sd(sd: float, tau: float, dur: float) -> float:
    """Prior sigma of the time average of a stationary GM process over ``dur`` seconds:
    var = σ²·(2τ/D)(1 − (τ/D)(1 − e^{−D/τ}))."""
    if dur <= 0 or not np.isfinite(tau):
        return sd
    x = tau / dur
    return float(sd * np.sqrt(max(2 * x * (1 - x * (1 - np.exp(-1 / x))), 0.0)))


def _outputs(P: _Problem, res: _BatchResult, pri: dict[str, float],
             calib_key: int | None) -> dict[str, Any]:
    vals = res.values
    lay = res.layout
    st = _states_from_values(P, vals, res.calib_of_kf)
    traj = _trajectory(P, st, vals, _output_times(P))
    # covariance of the final linear system: one banded factorisation + selected inversion
    fac = res.fac
    if fac is None:
        ab, bm, dm, _ = _normal_equations(P, lay, res.graph, vals, res.rows)
        fac = _factorize(ab, bm, dm)
    sb = fac.band_inverse()
    nk = P.n_kf
    sel = np.unique(np.linspace(0, nk - 1, min(P.cfg.cov_epochs, nk)).astype(int))
    cov = np.array([_cov_18(P, fac, sb, lay, vals, int(k)) for k in sel])
    out: dict[str, Any] = {"trajectory": traj, "cov": cov, "t_cov": P.t_kf[sel]}
    if P.drive.baro is None or calib_key is None:
        out["baro"] = None
        out["observability"] = {}
        return out
    kc = vals.atVector(calib_key)
    pk = fac.s_inv
    # sigma of the time-averaged bias b̄ = (1/K) Σ b_k: uᵀ H⁻¹ u with u = 1/K on every C(k)
    u = np.zeros(lay.n_cols)
    u[np.arange(nk) * lay.bs + 15] = 1.0 / nk
    b_mean = float(np.mean(st.baro_bias))
    hu = fac.solve(u)
    b_var = max(float(u @ hu), 0.0)
    b_sd = float(np.sqrt(b_var))
    # b is referenced to h0 (DESIGN.md): at a height Δh above h0 an error δs moves it by
    # −δs·Δh, so a flight far above h0 ties b̄ to s (sortie: corr −0.995)
    cov_sb = float(hu[lay.n_band])
    corr_sb = cov_sb / np.sqrt(b_var * pk[0, 0]) if b_var > 0 and pk[0, 0] > 0 else 0.0
    b_sd_given_s = float(np.sqrt(max(b_var - cov_sb**2 / pk[0, 0], 0.0))) if pk[0, 0] > 0 \
        else b_sd
    dur = float(P.t_kf[-1] - P.t_kf[0])
    b_prior = _gm_mean_prior_sd(pri["b_sd"], pri["b_tau"], dur)
    baro = BaroEstimate(
        scale=ParamEstimate(float(kc[0]), float(np.sqrt(pk[0, 0])), pri["s_sd"]),
        latency_s=ParamEstimate(float(kc[1]), float(np.sqrt(pk[1, 1])), pri["tau_sd"]),
        bias_m=ParamEstimate(b_mean, b_sd, b_prior),
    )
    obs = {}
    for name, pe, why in (
        ("scale", baro.scale, "needs altitude change"),
        ("latency_s", baro.latency_s, "needs vertical speed"),
        ("bias_m", baro.bias_m, "needs GNSS height"),
    ):
        assert pe is not None and pe.sd is not None and pe.prior_sd is not None
        ratio = pe.sd / pe.prior_sd
        obs[name] = {"prior_sd": pe.prior_sd, "posterior_sd": pe.sd, "ratio": ratio,
                     "observable": bool(ratio < P.cfg.observable_ratio),
                     "note": "" if ratio < P.cfg.observable_ratio else
                     f"barely informed by the data ({why})"}
    obs["bias_m"]["corr_with_scale"] = float(corr_sb)
    obs["bias_m"]["sd_given_scale"] = b_sd_given_s
    out["baro"] = baro
    out["observability"] = obs
    return out


# ----------------------------------------------------------------------------------------
# Estimators


def _build_batch_graph(P: _Problem, rot: FloatArray, pos: FloatArray, vel: FloatArray,
                       pims: list[Any], pri: dict[str, float],
                       calib_of_kf: np.ndarray) -> tuple[Any, Any]:
    """C++ part of the batch graph: priors, CombinedImuFactors and the Gauss-Markov links.
    Every GNSS fix (on keyframe epochs too) enters as an interval term so that the gates can
    drop it without rebuilding the graph."""
    graph = _prior_factors(P, rot[0], pos[0], vel[0], pri, K(0))
    vals = gtsam.Values()
    nk = P.n_kf
    for k in range(nk):
        vals.insert(X(k), gtsam.Pose3(gtsam.Rot3(rot[k]), pos[k]))
        vals.insert(V(k), vel[k])
        vals.insert(B(k), gtsam.imuBias.ConstantBias())
        if P.drive.baro is not None:
            vals.insert(C(k), np.zeros(1))
        if k + 1 < nk:
            graph.add(gtsam.CombinedImuFactor(X(k), V(k), X(k + 1), V(k + 1), B(k), B(k + 1),
                                              pims[k]))
            if P.drive.baro is not None:
                graph.add(_gm_factor(k, float(P.t_kf[k + 1] - P.t_kf[k]), pri))
    if P.drive.baro is not None:
        for j in np.unique(calib_of_kf):
            vals.insert(K(int(j)), np.array([0.0, pri["tau0"]]))
    return graph, vals


def _pims_for(P: _Problem, rot: FloatArray, pos: FloatArray) -> list[Any]:
    dg = _gravity_delta(P, pos)
    bias0 = gtsam.imuBias.ConstantBias()
    return [_preintegrate(P, k, rot[k], dg[k], bias0) for k in range(P.n_kf - 1)]


def _provides(drive: Drive) -> frozenset[str]:
    q = {"alt", "vel_d", "pos_h", "vel_h", "att", "cov"}
    if drive.baro is not None:
        q.add("baro")
    return frozenset(q)


class GraphBatch:
    """``graph-batch``: full-batch smoothing of the whole drive (offline)."""

    name = "graph-batch"

    def __init__(self, config: GraphConfig | None = None) -> None:
        self.config = config or GraphConfig()

    def run(self, drive: Drive) -> Estimate:
        t0 = time.perf_counter()
        P = _setup(drive, self.config)
        pri = _baro_priors(P.baro_spec)
        rot, pos, vel = _initial_states(P)
        t1 = time.perf_counter()
        pims = _pims_for(P, rot, pos)
        t2 = time.perf_counter()
        calib = np.zeros(P.n_kf, dtype=int)
        graph, vals = _build_batch_graph(P, rot, pos, vel, pims, pri, calib)
        res = _gauss_newton(P, graph, vals, calib, pri)
        t3 = time.perf_counter()
        out = _outputs(P, res, pri, K(0) if drive.baro is not None else None)
        t4 = time.perf_counter()
        info = {"keyframes": P.n_kf, "iterations": res.iterations, "final_cost": res.cost,
                "baro_bias_lag_s": res.bias_lag,
                "gnss_rejected": P.gnss_rejected, "gnss_rejected_pregate": P.g_rej_pre,
                "gnss_rejected_postsolve": P.g_rej_post,
                "observability": out["observability"],
                "timing_s": {"init": t1 - t0, "preintegration": t2 - t1, "solve": t3 - t2,
                             "outputs": t4 - t3},
                "frame": "tangent-plane NED at origin; gravity-difference and Coriolis "
                         "corrections" if self.config.gravity_correction else "tangent-plane"}
        return Estimate(self.name, out["trajectory"], _provides(drive), out["cov"],
                        out["t_cov"], out["baro"], time.perf_counter() - t0, info=info,
                        config=self.config)


ERROR_STATE_KEYS = tuple(ERROR_STATE)

# The incremental estimator lives in graph_isam2.py (size); the registry names graph:GraphISAM2.
from .graph_isam2 import GraphISAM2  # noqa: E402

__all__ = ["ERROR_STATE_KEYS", "GraphBatch", "GraphConfig", "GraphISAM2"]
