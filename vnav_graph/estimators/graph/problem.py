"""Problem set-up of the factor-graph smoothers: GNSS pre-gate, priors, the C++ factors (IMU
preintegration, Gauss-Markov baro-bias and GNSS-height chains) and the interval rows of the
custom baro/GNSS terms at a linearisation point (the settings: ``settings.GraphConfig``).
Used by ``batch``, ``solve``, ``isam2`` and ``terms``."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import gtsam
import numpy as np
from gtsam.symbol_shorthand import A, B, C, G, K, V, X

from ...config import REAL_LOG_BARO, BaroSpec, ImuSpec
from ...geo.earth import gravity
from ...nav.gaps import imu_gaps as nav_imu_gaps
from ...nav.levelling import coarse_level
from ...sensors.model import (
    BaroPrior,
    GnssHeightGM,
    accel_scale_sd,
    baro_prior,
    gnss_gm_split,
    sensor_model,
)
from ...sensors.noise import gm_process_var, gm_transition, imu_bias_step
from ...types import (
    Drive,
    FloatArray,
)
from . import factors as gf
from .general import information_factor
from .robust import reweight, robust_noise
from .settings import GraphConfig

# logging gaps (the shared rule of nav.gaps): an interval containing one gets random-walk
# factors instead of an IMU factor. Their velocity link bounds the change by a sustained
# acceleration GAP_ACCEL_LEVEL (σ_v = a·T): over a long gap the filters' white-acceleration
# model (nav.gaps, σ_v = √(qT), 12 m/s over 150 s) is too tight for a vehicle on a winding
# road: with it graph-isam2's altitude RMSE across a 150 s IMU gap rose from 0.77 to 0.94 m
# (graph-batch 0.69 m). The gap *rule* is the shared one.
GAP_ACCEL_LEVEL = gf.GAP_ACCEL_LEVEL  # m/s², white acceleration level over the gap
GAP_VEL_SD = 5.0  # m/s, unknown velocity change folded into the position random walk
GAP_TILT_SD = 0.2  # rad, roll/pitch of the re-levelling prior after a gap
GAP_YAW_SD = 0.5  # rad, yaw after a gap: kept from before it, loosely


def imu_gaps(t: np.ndarray, kf_idx: np.ndarray) -> np.ndarray:
    """Boolean (n_kf − 1,): interval k contains an IMU logging gap.

    A gap is a sample spacing the shared rule calls one (``nav.gaps.imu_gaps``).
    """
    big = nav_imu_gaps(t)  # sample j → j+1
    k = np.searchsorted(kf_idx, big, side="right") - 1
    out = np.zeros(max(kf_idx.size - 1, 0), bool)
    k = k[(k >= 0) & (k < out.size)]
    out[k] = True
    return out



# ----------------------------------------------------------------------------------------
# Problem set-up shared by both estimators


@dataclass(frozen=True)
class AccelScale:
    """The accelerometer scale-factor variable A(0) (3, random constant k_a, prior N(0, sd²)):
    ``f_mean`` (K, 3) is the mean measured specific force ā_k [m/s²] of interval k (body
    frame; the last keyframe's is its interval's, a gap interval's its predecessor's), so
    that B(k) is the effective accelerometer bias b_a + diag(ā_k)·k_a of interval k."""

    sd: float
    f_mean: FloatArray

    def true_bias(self, ba_eff: FloatArray, ka: FloatArray, k: np.ndarray) -> FloatArray:
        """b_a at intervals ``k`` from the effective biases ``ba_eff`` (len(k), 3)."""
        return ba_eff - self.f_mean[k] * ka


def interval_mean_force(t: FloatArray, accel: FloatArray, kf_idx: np.ndarray,
                        gap: np.ndarray) -> FloatArray:
    """ā_k (K, 3): the time average of the midpoint specific force the preintegration uses
    over each interval (``AccelScale``)."""
    dt = np.diff(t)
    fm = 0.5 * (accel[:-1] + accel[1:]) * dt[:, None]
    cs = np.vstack([np.zeros((1, 3)), np.cumsum(fm, axis=0)])
    ct = np.r_[0.0, np.cumsum(dt)]
    j0, j1 = kf_idx[:-1], kf_idx[1:]
    out = np.empty((kf_idx.size, 3))
    out[:-1] = (cs[j1] - cs[j0]) / np.maximum(ct[j1] - ct[j0], 1e-12)[:, None]
    for k in np.flatnonzero(gap):  # no inertial information across a logging gap
        out[k] = out[k - 1] if k > 0 else out[min(k + 1, out.shape[0] - 2)]
    out[-1] = out[-2] if kf_idx.size > 1 else 0.0
    return out


@dataclass
class Problem:
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
    baro_spec: BaroPrior | None  # the shared baro prior (sensors.model)
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
    g_incr: Any = None  # (fix indices, dense increments at them), see gnss_rows_of
    pri: dict[str, float] = field(default_factory=dict)  # baro priors (_baro_priors)
    gm: GnssHeightGM | None = None  # the GNSS height Gauss-Markov state G(k), if carried
    ka: AccelScale | None = None  # the accelerometer scale factors A(0), if carried

    @property
    def gnss_rejected(self) -> int:
        return int(np.sum(~self.g_use & (self.g_kf >= -1)))

    @property
    def n_kf(self) -> int:
        return int(self.t_kf.size)


def _floor(x: float, lo: float) -> float:
    return float(max(x, lo))


def setup(drive: Drive, cfg: GraphConfig) -> Problem:
    imu = drive.imu
    origin = np.asarray(drive.origin_lla, float)
    h0 = float(origin[2])
    g0 = float(gravity(origin[0], origin[2]))
    model = sensor_model(drive)  # the noise model every estimator shares (sensors.model)
    spec = model.imu
    bspec = model.baro
    kf_idx = gf.keyframe_indices(imu.t, cfg.keyframe_dt)
    dense = gf.dense_preintegration(imu.t, imu.gyro_b, imu.accel_b, kf_idx)
    gaps = imu_gaps(imu.t, kf_idx)
    if gaps.any():
        dense = replace(dense, gap=gaps)
    omega_t = gf.earth_rate_t(origin) if cfg.coriolis else np.zeros(3)
    p = gtsam.PreintegrationCombinedParams.MakeSharedD(g0)
    # continuous-time densities (STYLE.md pitfall 3); floors keep noiseless drives regular
    p.setAccelerometerCovariance(np.eye(3) * spec.accel_noise_density**2)
    p.setGyroscopeCovariance(np.eye(3) * spec.gyro_noise_density**2)
    p.setIntegrationCovariance(np.eye(3) * 1e-8)
    # the biases' random walk of PSD 2σ²/τ + rw² (only the bench's C++-only floor uses it:
    # the graph's own bias link is the Gauss-Markov step of ``bias_step``)
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
    # the nearer keyframe of the two around each fix (a keyframe stamp a hair before the fix's
    # own was missed when only the next one was looked at: on hill-drive seed 0, 236 of the
    # 540 fixes on keyframe epochs, which then entered graph-isam2 two keyframes late)
    j = np.clip(np.searchsorted(t_kf, gn.t), 0, t_kf.size - 1)
    jm = np.maximum(j - 1, 0)
    j = np.where(np.abs(t_kf[jm] - gn.t) < np.abs(t_kf[j] - gn.t), jm, j)
    on_kf = np.abs(t_kf[j] - gn.t) < 1e-6
    inside = (gn.t >= t_kf[0]) & (gn.t <= t_kf[-1])
    g_kf = np.where(on_kf, j, -1)
    g_kf[~inside] = -2
    use = _pregate_gnss(drive, gn.t, gn.lla[:, 2], model.gnss_pos_sd[:, 2], _baro_priors(bspec),
                        cfg.gnss_gate_prob,
                        None if gn.vel_n is None else gn.vel_n[:, 2],
                        None if gn.vel_sd is None else gn.vel_sd[:, 2])
    P = Problem(drive, cfg, origin, h0, g0, omega_t, kf_idx, t_kf, dense, p, spec, bspec,
                gn.t, pos, model.gnss_pos_sd, vel, model.gnss_vel_sd,
                np.asarray(gn.lever_arm_b, float),
                 g_kf, use)
    P.g_rej_pre = P.gnss_rejected
    P.pri = _baro_priors(bspec)
    gm = cfg.gnss_gm
    if gm is not None:
        # the pre-gate above used the receiver's whole σ (it models no GNSS error state)
        P.gm = gm  # g_pos_sd becomes the white rest of the receiver's σ
        P.g_pos_sd = P.g_pos_sd.copy()
        P.g_pos_sd[:, 2] = gnss_gm_split(P.g_pos_sd[:, 2], gm)
    ka_sd = accel_scale_sd(model, cfg.accel_scale)  # the rule every estimator shares
    if ka_sd > 0:
        P.ka = AccelScale(ka_sd, interval_mean_force(imu.t, imu.accel_b, kf_idx, gaps))
    if not np.any(use & inside):
        raise ValueError("graph: every GNSS fix inside the IMU span was rejected by the "
                         "baro-consistency gate")
    return P


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


def _baro_priors(bs: BaroSpec | BaroPrior | None) -> dict[str, float]:
    """Prior mean and sigma of s, τd and b_0 as a dict (``sensors.model.baro_prior``: the
    shared rule; a drive without a baro gets the real-log prior, which then goes unused)."""
    bp = bs if isinstance(bs, BaroPrior) else baro_prior(REAL_LOG_BARO if bs is None else bs)
    return {"s_sd": bp.scale_sd, "tau0": bp.latency_mean, "tau_sd": bp.latency_sd,
            "b_sd": bp.bias_sd, "b_tau": bp.bias_tau, "noise": bp.noise_sd}


def gravity_delta(P: Problem, pos: FloatArray) -> FloatArray:
    """δg_k = g_t(p_k) − [0, 0, γ0] (K, 3) [m/s²] (zero when the correction is disabled)."""
    if not P.cfg.gravity_correction:
        return np.zeros_like(pos)
    return gf.gravity_t(pos, P.origin) - np.array([0.0, 0.0, P.g0])


def preintegrate(P: Problem, k: int, r_k: FloatArray, dg_k: FloatArray,
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
    pim = gtsam.PreintegratedImuMeasurements(P.params, bias)
    integ = pim.integrateMeasurement
    for a, w, dt in zip(fm, wm, dts, strict=True):
        integ(a, w, dt)
    return pim


def noise(sd: FloatArray) -> Any:
    return gtsam.noiseModel.Diagonal.Sigmas(np.asarray(sd, dtype=float))


def prior_factors(P: Problem, r0: FloatArray, p0: FloatArray, v0: FloatArray,
                   pri: dict[str, float], calib_key: int) -> gtsam.NonlinearFactorGraph:
    g = gtsam.NonlinearFactorGraph()
    s = P.imu_spec
    g.add(gtsam.PriorFactorPose3(X(0), gtsam.Pose3(gtsam.Rot3(r0), p0),
                                 noise([0.05, 0.05, 0.5, 10.0, 10.0, 10.0])))
    g.add(gtsam.PriorFactorVector(V(0), v0, noise([2.0, 2.0, 2.0])))
    sd_b = noise([_floor(s.accel_bias_sd, 1e-4)] * 3 + [_floor(s.gyro_bias_sd, 1e-6)] * 3)
    if P.ka is None:
        g.add(gtsam.PriorFactorConstantBias(B(0), gtsam.imuBias.ConstantBias(), sd_b))
    else:  # the prior is on b_a = B_a(0) − diag(ā_0)·k_a, and k_a ~ N(0, σ_ka²)
        ja = np.zeros((6, 3))
        ja[0:3] = -np.diag(P.ka.f_mean[0])
        g.add(_linear(gtsam.JacobianFactor(B(0), np.eye(6), A(0), ja, np.zeros(6), sd_b),
                      [(B(0), 6), (A(0), 3)]))
        g.add(gtsam.PriorFactorVector(A(0), np.zeros(3), noise([P.ka.sd] * 3)))
    if P.drive.baro is not None:
        g.add(gtsam.PriorFactorVector(C(0), np.zeros(1), noise([pri["b_sd"]])))
        g.add(gtsam.PriorFactorVector(calib_key, np.array([0.0, pri["tau0"]]),
                                      noise([pri["s_sd"], pri["tau_sd"]])))
    if P.gm is not None:  # the stationary Gauss-Markov prior of the GNSS height error
        g.add(gtsam.PriorFactorVector(G(0), np.zeros(1), noise([P.gm.sd_m])))
    return g


def keyframe_fixes(P: Problem, k: int) -> list[tuple[int, Any]]:
    """The used fixes on keyframe k's epoch as C++ factors, each with its fix index:
    ``GPSFactorArm`` on X(k) and, with GNSS velocity and no lever arm, a prior on V(k)."""
    out = []
    cfg = P.cfg
    for i in np.flatnonzero((P.g_kf == k) & P.g_use):
        out.append((int(i), gtsam.GPSFactorArm(X(k), P.g_pos[i], P.lever, robust_noise(
            noise(P.g_pos_sd[i]), cfg.loss_gnss_pos, cfg.loss_threshold_sd[0]))))
        if P.g_vel is not None and P.g_vel_sd is not None and not np.any(P.lever):
            out.append((int(i), gtsam.PriorFactorVector(V(k), P.g_vel[i], robust_noise(
                noise(P.g_vel_sd[i]), cfg.loss_gnss_vel, cfg.loss_threshold_sd[1]))))
    return out


def _zeros(keys: list[tuple[int, int]]) -> Any:
    """Values of zero for vector-space variables (``keys``: key, dimension); B keys are
    ``ConstantBias``."""
    lin = gtsam.Values()
    for key, n in keys:
        if gtsam.Symbol(key).chr() == ord("b"):
            lin.insert(key, gtsam.imuBias.ConstantBias())
        else:
            lin.insert(key, np.zeros(n))
    return lin


def _linear(jf: Any, keys: list[tuple[int, int]]) -> Any:
    """A linear factor on vector-space variables as a nonlinear one, linearised at zero
    (exact at any point)."""
    return gtsam.LinearContainerFactor(jf, _zeros(keys))


def bias_walk_psd(params: Any) -> FloatArray:
    """PSD (6,) of the IMU biases' random walk (accel, gyro) in the preintegration
    parameters ``params`` (``Problem.params``): the bench's C++-only floor uses it."""
    return np.r_[np.diag(params.getBiasAccCovariance()),
                 np.diag(params.getBiasOmegaCovariance())]


def bias_step(spec: ImuSpec, dt: float) -> tuple[FloatArray, FloatArray]:
    """(φ, var w), each (6,) in ``ConstantBias`` order (accel, gyro), of the IMU biases over
    ``dt``: the ekf's discretisation (``sensors.noise.imu_bias_step``), with the floors of
    the preintegration parameters (a noiseless spec stays regular)."""
    dt = max(dt, 1e-9)
    pa, va = imu_bias_step(dt, spec.accel_bias_tau, spec.accel_bias_sd, spec.accel_bias_rw)
    pg, vg = imu_bias_step(dt, spec.gyro_bias_tau, spec.gyro_bias_sd, spec.gyro_bias_rw)
    return (np.r_[[float(pa)] * 3, [float(pg)] * 3],
            np.r_[[max(float(va), 1e-12 * dt)] * 3, [max(float(vg), 1e-16 * dt)] * 3])


def bias_link(P: Problem, k: int, dt: float, a_keys: tuple[int, int] | None = None) -> Any:
    """B(k) → B(k+1): the IMU biases' Gauss-Markov step b(k+1) = φ·b(k) + w (``bias_step``:
    φ = exp(−Δt/τ), var w = σ²(1 − φ²) + rw²·Δt per component, the ekf's model of the
    ``ImuSpec``), as a linear factor. With the accelerometer scale factors (``AccelScale``)
    B holds effective biases b_a + diag(ā)·k_a and the link is
    B_a(k+1) − diag(ā_k+1)·k_a' − φ_a·(B_a(k) − diag(ā_k)·k_a) = w, k_a and k_a' the scale
    variables of intervals k and k+1 (``a_keys``; default A(0) for both, the batch's; the
    incremental front end has one per segment). Until session 29 the graph carried the
    biases as random walks of PSD 2σ²/τ + rw² (no decay of the mean; docs/graph.md)."""
    phi, var = bias_step(P.imu_spec, dt)
    sd = noise(np.sqrt(var))
    minus_phi = -np.diag(phi)
    eye = np.eye(6)
    if P.ka is None:
        return _linear(gtsam.JacobianFactor(B(k), minus_phi, B(k + 1), eye, np.zeros(6), sd),
                       [(B(k), 6), (B(k + 1), 6)])
    a0, a1 = a_keys if a_keys is not None else (A(0), A(0))
    f0, f1 = phi[0:3] * P.ka.f_mean[k], P.ka.f_mean[k + 1]
    if a0 == a1:
        ja = np.zeros((6, 3))
        ja[0:3] = np.diag(f0 - f1)
        return _linear(gtsam.JacobianFactor(B(k), minus_phi, B(k + 1), eye, a0, ja,
                                            np.zeros(6), sd),
                       [(B(k), 6), (B(k + 1), 6), (a0, 3)])
    # four keys (a segment boundary): GTSAM's Python JacobianFactor takes ≤ 3, so the
    # information JᵀΣ⁻¹J goes in as ≤ 3-key Hessian pieces (``general.information_factor``)
    jac = np.zeros((6, 18))
    jac[:, 0:6], jac[:, 6:12] = minus_phi, eye
    jac[0:3, 12:15], jac[0:3, 15:18] = np.diag(f0), -np.diag(f1)
    jw = jac / np.sqrt(var)[:, None]
    keys = [(B(k), 6), (B(k + 1), 6), (a0, 3), (a1, 3)]
    return information_factor([key for key, _ in keys], jw.T @ jw, np.zeros(18),
                              ((0, 6), (6, 6), (12, 3), (15, 3)), _zeros(keys))


def imu_factor(k: int, pim: Any) -> Any:
    """Interval k's IMU factor on X(k), V(k), X(k+1), V(k+1) and its bias B(k) (the biases'
    random walk is ``bias_link``)."""
    return gtsam.ImuFactor(X(k), V(k), X(k + 1), V(k + 1), B(k), pim)


def gm_link(key0: int, key1: int, dt: float, tau: float, sd: float) -> Any:
    """Exact discrete Gauss-Markov link x_1 − φ x_0 = w, φ = e^{−Δt/τ}, var w = σ²(1 − φ²),
    between two scalar variables, as a (linear) C++ factor."""
    phi = float(gm_transition(dt, tau))
    sd_w = float(np.sqrt(max(gm_process_var(dt, tau, sd), 1e-12)))
    return _linear(gtsam.JacobianFactor(key0, np.array([[-phi]]), key1, np.array([[1.0]]),
                                        np.zeros(1), noise([sd_w])), [(key0, 1), (key1, 1)])


def gm_factor(k: int, dt: float, pri: dict[str, float]) -> Any:
    """The baro bias's Gauss-Markov link C(k) → C(k+1)."""
    return gm_link(C(k), C(k + 1), dt, pri["b_tau"], pri["b_sd"])


def gnss_gm_factor(k: int, dt: float, gm: GnssHeightGM) -> Any:
    """The GNSS height error's Gauss-Markov link G(k) → G(k+1)."""
    return gm_link(G(k), G(k + 1), dt, gm.tau_s, gm.sd_m)



def level(f_b: FloatArray) -> FloatArray:
    """Rotation matrix of the roll/pitch from a static specific force (coarse_level), yaw 0."""
    roll, pitch = coarse_level(f_b)
    return gtsam.Rot3.Ypr(0.0, pitch, roll).matrix()


def gap_factors(P: Problem, k: int, rot: FloatArray, pos: FloatArray, vel: FloatArray,
                a_keys: tuple[int, int] | None = None) -> tuple[Any, FloatArray, list[Any]]:
    """Weak factors replacing the IMU factor over a logging gap in interval k (both smoothers).

    A gap of T seconds with no IMU samples carries no inertial information (one "sample"
    spanning it is usually a transient — on the Erle log the crash spike — and a
    CombinedImuFactor built from it asserts a 200 m/s velocity change with a σ of 0.6 m/s; in
    the batch graph, Loiter_RTL's 24 s gap then pulled the baro scale to −28 %). Instead, with a
    = ``GAP_ACCEL_LEVEL``: v_{k+1} − v_k ~ N(0, (a T)²), b_{k+1} − b_k ~ N(0, q_b T)
    with the bias PSD q_b of the preintegration (Forster et al. 2017, Eq. 48), and a re-
    alignment prior on X(k+1): roll and pitch levelled from the mean specific force of the first
    0.5 s after the gap (σ ``GAP_TILT_SD``; the vehicle may have been flipped — Erle crash log:
    f_z +9.8 before, −9.8 after — and the weak factors cannot pull a 180° error back inside
    Gauss-Newton's basin), yaw kept from before the gap (σ ``GAP_YAW_SD``), position at the last
    GNSS fix at or before t_{k+1} (within 1.5 s; else constant velocity) with σ_p = v_sd T + ½ a
    T². Every new variable stays constrained.

    ``rot, pos, vel``: current keyframe states (only index k is read). Returns (Pose3 value of
    X(k+1), velocity value (3,), factors).
    """
    T = float(P.t_kf[k + 1] - P.t_kf[k])
    p1 = pos[k] + vel[k] * T
    v1 = np.array(vel[k], dtype=float)
    sel = np.flatnonzero(P.g_use & (P.g_t <= P.t_kf[k + 1] + 1e-9)
                         & (P.g_t > P.t_kf[k + 1] - 1.5))
    if sel.size:
        i = sel[-1]
        p1 = P.g_pos[i] - rot[k] @ P.lever
        if P.g_vel is not None:
            v1 = P.g_vel[i].copy()
    imu_t = P.drive.imu.t
    j0 = int(P.kf_idx[k + 1])
    j1 = max(int(np.searchsorted(imu_t, imu_t[j0] + 0.5)), j0 + 1)
    lev = gtsam.Rot3(level(P.drive.imu.accel_b[j0:j1].mean(axis=0))).ypr()
    yaw = gtsam.Rot3(rot[k]).ypr()[0]
    x1 = gtsam.Pose3(gtsam.Rot3.Ypr(yaw, lev[1], lev[2]), p1)
    sd_p = GAP_VEL_SD * T + 0.5 * GAP_ACCEL_LEVEL * T * T
    fs = [
        gtsam.PriorFactorPose3(X(k + 1), x1,
                               noise([GAP_TILT_SD, GAP_TILT_SD, GAP_YAW_SD] + [sd_p] * 3)),
        gtsam.BetweenFactorVector(V(k), V(k + 1), np.zeros(3), noise([GAP_ACCEL_LEVEL * T] * 3)),
        bias_link(P, k, T, a_keys),
    ]
    return x1, v1, fs

# ----------------------------------------------------------------------------------------
# Interval terms → GTSAM Hessian blocks


def keyframe_poses(vals: Any, nk: int) -> tuple[FloatArray, FloatArray]:
    """Rotations (K, 3, 3) and positions (K, 3) of X(0 … K−1) in ``vals``. Fast path: every
    Pose3 in ``vals`` is a keyframe pose; with Pose3 variables added by an extension
    (``extend``) the keyframe poses are read one by one."""
    poses = gtsam.utilities.extractPose3(vals)
    if poses.shape[0] != nk:
        poses = np.array([np.r_[p.rotation().matrix().ravel(), p.translation()]
                          for p in (vals.atPose3(X(k)) for k in range(nk))])
    return poses[:, :9].reshape(nk, 3, 3), poses[:, 9:12]


def states_from_values(P: Problem, vals: Any, calib_of_kf: np.ndarray) -> gf.KeyframeStates:
    nk = P.n_kf
    rot, pos = keyframe_poses(vals, nk)
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
    g_gm = gtsam.utilities.extractVectors(vals, "g")[:, 0] if P.gm is not None else None
    return gf.KeyframeStates(rot, pos, vel, ba, cb, s, tau, nav_accel(P, pos, vel), g_gm)


def nav_accel(P: Problem, pos: FloatArray, vel: FloatArray,
              dg: FloatArray | None = None) -> FloatArray:
    """The kinematic acceleration the interval terms expect at rest in the tangent frame:
    gravity (γ(origin) plus the anomaly ``dg`` at ``pos``, computed when not given) minus
    the Coriolis term 2Ω×v, per keyframe."""
    g = gravity_delta(P, pos) if dg is None else dg
    return np.array([0.0, 0.0, P.g0]) + g - 2 * np.cross(P.omega_t, vel)


def post_solve_rejections(P: Problem, st: gf.KeyframeStates) -> np.ndarray:
    """The post-solve GNSS gate at the states ``st``: the used fixes whose whitened residual
    χ² exceeds the squared tail probability of ``gnss_gate_prob`` (a false rejection costs a
    whole re-solve, a glitch has χ² in the thousands either way). They are marked unused
    (``P.g_use``) and counted (``P.g_rej_post``); returns them, empty when none or every one
    fails (or gating is off)."""
    from scipy.stats import chi2

    idx = gnss_batch_idx(P)
    if idx.size == 0 or P.cfg.gnss_gate_prob <= 0:
        return idx[:0]
    c2, dof = gnss_chi2(P, st, idx)
    bad = c2 > chi2.ppf(1.0 - (1.0 - P.cfg.gnss_gate_prob) ** 2, dof)
    if not np.any(bad) or np.all(bad):
        return idx[:0]
    P.g_use[idx[bad]] = False
    P.g_rej_post += int(bad.sum())
    return idx[bad]


def gnss_batch_idx(P: Problem) -> np.ndarray:
    """Fixes used by the batch: every kept fix inside the keyframe span (on keyframe epochs
    too — at τ = 0 the interpolant is exactly X_k, so the row equals GPSFactorArm's)."""
    return np.flatnonzero(P.g_use & (P.g_kf >= -1))


def gnss_rows_of(P: Problem, st: gf.KeyframeStates, idx: np.ndarray,
                 out: FloatArray | None = None) -> gf.IntervalRows:
    t_g = P.g_t[idx]
    # the IMU increments at the fixes depend on the fix times only: cached per fix set
    if P.g_incr is None or not np.array_equal(P.g_incr[0], idx):
        k = gf.interval_of(P.t_kf, t_g)
        P.g_incr = (idx, P.dense.at(t_g, k))
    return gf.gnss_rows(
        P.dense, st, t_g, P.g_pos[idx], P.g_pos_sd[idx],
        None if P.g_vel is None else P.g_vel[idx],
        None if P.g_vel_sd is None else P.g_vel_sd[idx], P.lever, incr=P.g_incr[1], out=out)


def interval_rows(P: Problem, st: gf.KeyframeStates, pri: dict[str, float],
                  bias_lag: float) -> gf.IntervalRows:
    """Baro and GNSS interval rows; ``bias_lag``: see ``factors.baro_rows``. Under robust
    losses (``GraphConfig.loss_*``) the rows are reweighted (IRLS, ``robust.reweight``),
    ``loss`` holds Σρ and ``weights`` the weight of every sample and fix. The Jacobians of
    all rows are written into one array (no per-type pieces concatenated: that held the
    rows twice, ~46 MB each on a 1-hour drive)."""
    cfg = P.cfg
    k_baro, k_pos, k_vel = (cfg.loss_threshold_sd[2], cfg.loss_threshold_sd[0],
                            cfg.loss_threshold_sd[1])
    ks, rs = [], []
    loss = 0.0
    weights: dict[str, Any] = {}
    has_baro = P.drive.baro is not None
    if has_baro:
        bt = P.drive.baro.t
        m = (bt >= P.t_kf[0]) & (bt <= P.t_kf[-1])
    n_baro = int(np.count_nonzero(m)) if has_baro else 0
    idx = gnss_batch_idx(P)
    n = 3 * idx.size  # position rows (fix-major, 3 per fix), then velocity rows
    with_vel = P.g_vel is not None and P.g_vel_sd is not None
    n_cols = gf.N_COLS_GM if P.gm is not None else gf.N_COLS
    jac = np.empty((n_baro + (2 * n if with_vel else n), n_cols))

    def put(part: FloatArray, j: FloatArray) -> None:
        if j is not part:  # reweighted (robust loss): a new array
            part[...] = j

    if has_baro:
        rows = gf.baro_rows(P.dense, st, bt[m], P.drive.baro.altitude[m], pri["noise"],
                            P.h0, P.origin, bias_lag=bias_lag, out=jac[:n_baro])
        r, j, w, rho = reweight(rows.r, rows.jac, 1, cfg.loss_baro, k_baro)
        put(rows.jac, j)
        ks.append(rows.k)
        rs.append(r)
        loss += rho
        weights.update(baro_t=bt[m], baro=w)
    if idx.size:
        rows = gnss_rows_of(P, st, idx, out=jac[n_baro:])
        jp = rows.jac[:n]
        r, j, w, rho = reweight(rows.r[:n], jp, 3, cfg.loss_gnss_pos, k_pos)
        put(jp, j)
        ks.append(rows.k[:n])
        rs.append(r)
        loss += rho
        weights.update(gnss_t=P.g_t[idx], gnss_pos=w, gnss_vel=None)
        if rows.r.size > n:
            jv = rows.jac[n:]
            r, j, w, rho = reweight(rows.r[n:], jv, 3, cfg.loss_gnss_vel, k_vel)
            put(jv, j)
            ks.append(rows.k[n:])
            rs.append(r)
            loss += rho
            weights["gnss_vel"] = w
    if not ks:
        return gf.IntervalRows(np.zeros(0, dtype=np.intp), np.zeros(0),
                               np.zeros((0, n_cols)), loss, weights)
    return gf.IntervalRows(np.concatenate(ks), np.concatenate(rs), jac, loss, weights)


def gnss_chi2(P: Problem, st: gf.KeyframeStates, idx: np.ndarray) -> tuple[FloatArray, int]:
    """χ² of each fix's whitened residual at the solution (position, + velocity when the log
    has it) and its degrees of freedom."""
    rows = gnss_rows_of(P, st, idx)
    m = idx.size
    r = rows.r.reshape(-1, m, 3)  # (1 or 2, m, 3): position rows, then velocity rows
    return np.sum(r**2, axis=(0, 2)), 3 * r.shape[0]


def build_batch_graph(P: Problem, rot: FloatArray, pos: FloatArray, vel: FloatArray,
                       pims: list[Any] | None, pri: dict[str, float],
                       calib_of_kf: np.ndarray) -> tuple[Any, Any]:
    """C++ part of the batch graph: priors, IMU factors and the biases' links (``gap_factors``
    over IMU logging gaps) and the Gauss-Markov links. Every GNSS fix (on keyframe epochs
    too) enters as an interval term so that the gates can drop it without rebuilding the graph.
    ``pims`` None: no IMU factors (only the initial values are wanted)."""
    graph = prior_factors(P, rot[0], pos[0], vel[0], pri, K(0))
    vals = gtsam.Values()
    nk = P.n_kf
    gap = imu_gaps(P.drive.imu.t, P.kf_idx)
    if gap.any():
        rot, pos, vel = rot.copy(), pos.copy(), vel.copy()
    for k in range(nk):
        vals.insert(X(k), gtsam.Pose3(gtsam.Rot3(rot[k]), pos[k]))
        vals.insert(V(k), vel[k])
        vals.insert(B(k), gtsam.imuBias.ConstantBias())
        if P.drive.baro is not None:
            vals.insert(C(k), np.zeros(1))
        if P.gm is not None:
            vals.insert(G(k), np.zeros(1))
        if k + 1 < nk:
            if gap[k]:
                x1, v1, fs = gap_factors(P, k, rot, pos, vel)
                for f in fs:
                    graph.add(f)
                rot[k + 1], pos[k + 1], vel[k + 1] = x1.rotation().matrix(), x1.translation(), v1
            elif pims is not None:
                graph.add(imu_factor(k, pims[k]))
                graph.add(bias_link(P, k, float(P.t_kf[k + 1] - P.t_kf[k])))
            if P.drive.baro is not None:
                graph.add(gm_factor(k, float(P.t_kf[k + 1] - P.t_kf[k]), pri))
            if P.gm is not None:
                graph.add(gnss_gm_factor(k, float(P.t_kf[k + 1] - P.t_kf[k]), P.gm))
    if P.drive.baro is not None:
        for j in np.unique(calib_of_kf):
            vals.insert(K(int(j)), np.array([0.0, pri["tau0"]]))
    if P.ka is not None:
        vals.insert(A(0), np.zeros(3))
    return graph, vals


def pims_for(P: Problem, rot: FloatArray, pos: FloatArray) -> list[Any]:
    dg = gravity_delta(P, pos)
    bias0 = gtsam.imuBias.ConstantBias()
    return [preintegrate(P, k, rot[k], dg[k], bias0) for k in range(P.n_kf - 1)]


