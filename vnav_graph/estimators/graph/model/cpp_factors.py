"""The C++ factors of the factor-graph smoothers, built from a ``problem.Problem``: priors,
keyframe GNSS fixes, the IMU factor and the IMU biases' Gauss-Markov link (with the
accelerometer scale factors), the Gauss-Markov chains of the baro bias and the GNSS height
error, the random-walk factors across IMU logging gaps, and the batch's whole C++ graph.
Used by ``batch``, ``isam2`` and ``isam2_setup`` (and the bench's C++-only floor)."""

from __future__ import annotations

from typing import Any

import gtsam
import numpy as np
from gtsam.symbol_shorthand import A, B, C, G, K, V, X

from ....config import ImuSpec
from ....nav.levelling import coarse_level
from ....sensors.gnss_model import GnssGM
from ....sensors.noise import gm_process_var, gm_transition, imu_bias_step
from ....types.streams import FloatArray
from ..solver.general import information_factor
from . import interval_factors as gf
from .problem import Problem, gravity_delta, noise, preintegrate
from .robust import robust_noise

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


def _floor(x: float, lo: float) -> float:
    return float(max(x, lo))


# σ of keyframe 0's prior on roll, pitch and yaw (body axes) [rad]
PRIOR_ATT_SD = (0.05, 0.05, 0.5)


def prior_factors(P: Problem, r0: FloatArray, p0: FloatArray, v0: FloatArray,
                  pri: dict[str, float], calib_key: int,
                  yaw_sd: float = PRIOR_ATT_SD[2]) -> gtsam.NonlinearFactorGraph:
    """Keyframe 0's priors; ``yaw_sd``: its yaw σ (graph-isam2's causal start before the
    heading is known: ``initial_guess.UNKNOWN_YAW_SD``)."""
    g = gtsam.NonlinearFactorGraph()
    s = P.imu_spec
    g.add(gtsam.PriorFactorPose3(X(0), gtsam.Pose3(gtsam.Rot3(r0), p0),
                                 noise([*PRIOR_ATT_SD[:2], yaw_sd, 10.0, 10.0, 10.0])))
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
    if P.gm is not None:  # the stationary Gauss-Markov prior of the GNSS error state
        g.add(gtsam.PriorFactorVector(G(0), np.zeros(P.gm.dim), noise(list(P.gm.sd))))
    return g


def keyframe_fixes(P: Problem, k: int) -> list[tuple[int, Any]]:
    """The used fixes on keyframe k's epoch as C++ factors, each with its fix index:
    ``GPSFactorArm`` on X(k) and, with GNSS velocity and no lever arm, a prior on V(k)."""
    out = []
    cfg = P.cfg
    for i in np.flatnonzero((P.g_kf == k) & P.g_use):
        if not P.g_pos_drop[i]:
            out.append((int(i), gtsam.GPSFactorArm(X(k), P.g_pos[i], P.lever, robust_noise(
                noise(P.g_pos_sd[i]), cfg.loss_gnss_pos, cfg.loss_threshold_sd[0]))))
        if P.g_vel is not None and P.g_vel_sd is not None and not np.any(P.lever):
            out.append((int(i), gtsam.PriorFactorVector(V(k), P.g_vel[i], robust_noise(
                noise(P.g_vel_sd[i]), cfg.loss_gnss_vel, cfg.loss_threshold_sd[1]))))
    return out


def zupt_factor(P: Problem, k: int) -> Any:
    """Keyframe k's zero-velocity prior V(k) = 0, σ ``P.zupt_sd`` per axis (a keyframe inside
    a detected standstill, ``nav.standstill``)."""
    return gtsam.PriorFactorVector(V(k), np.zeros(3), noise([P.zupt_sd] * 3))


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


def _linear(jf: Any, keys: list[tuple[int, int]], zeros: Any = None) -> Any:
    """A linear factor on vector-space variables as a nonlinear one, linearised at zero
    (exact at any point). ``zeros``: a ``Values`` that holds zero for every key of the factor
    (it may hold others; the factor keeps only its own), else one is made for it."""
    return gtsam.LinearContainerFactor(jf, _zeros(keys) if zeros is None else zeros)


def bias_step(spec: ImuSpec, dt: float | FloatArray) -> tuple[FloatArray, FloatArray]:
    """(φ, var w), each (6,) in ``ConstantBias`` order (accel, gyro), of the IMU biases over
    ``dt``: the ekf's discretisation (``sensors.noise.imu_bias_step``), with the floors of
    the preintegration parameters (a noiseless spec stays regular). ``dt`` (n,): each (n, 6)
    (one call for every interval of a graph)."""
    dt = np.maximum(np.asarray(dt, dtype=float), 1e-9)
    pa, va = imu_bias_step(dt, spec.accel_bias_tau, spec.accel_bias_sd, spec.accel_bias_rw)
    pg, vg = imu_bias_step(dt, spec.gyro_bias_tau, spec.gyro_bias_sd, spec.gyro_bias_rw)
    va, vg = np.maximum(va, 1e-12 * dt), np.maximum(vg, 1e-16 * dt)
    return (np.stack([pa] * 3 + [pg] * 3, axis=-1), np.stack([va] * 3 + [vg] * 3, axis=-1))


def bias_link(P: Problem, k: int, dt: float, a_keys: tuple[int, int] | None = None,
              step: tuple[FloatArray, FloatArray] | None = None, zeros: Any = None) -> Any:
    """B(k) → B(k+1): the IMU biases' Gauss-Markov step b(k+1) = φ·b(k) + w (``bias_step``:
    φ = exp(−Δt/τ), var w = σ²(1 − φ²) + rw²·Δt per component, the ekf's model of the
    ``ImuSpec``), as a linear factor. With the accelerometer scale factors (``AccelScale``)
    B holds effective biases b_a + diag(ā)·k_a and the link is
    B_a(k+1) − diag(ā_k+1)·k_a' − φ_a·(B_a(k) − diag(ā_k)·k_a) = w, k_a and k_a' the scale
    variables of intervals k and k+1 (``a_keys``; default A(0) for both, the batch's; the
    incremental front end has one per segment). The step is the Gauss-Markov one the ekf
    uses too (``sensors.noise.imu_bias_step``; docs/graph.md).
    ``step``: ``bias_step(P.imu_spec, dt)`` when already computed; ``zeros``: as in
    ``_linear``."""
    phi, var = bias_step(P.imu_spec, dt) if step is None else step
    sd = noise(np.sqrt(var))
    minus_phi = -np.diag(phi)
    eye = np.eye(6)
    if P.ka is None:
        return _linear(gtsam.JacobianFactor(B(k), minus_phi, B(k + 1), eye, np.zeros(6), sd),
                       [(B(k), 6), (B(k + 1), 6)], zeros)
    a0, a1 = a_keys if a_keys is not None else (A(0), A(0))
    f0, f1 = phi[0:3] * P.ka.f_mean[k], P.ka.f_mean[k + 1]
    if a0 == a1:
        ja = np.zeros((6, 3))
        ja[0:3] = np.diag(f0 - f1)
        return _linear(gtsam.JacobianFactor(B(k), minus_phi, B(k + 1), eye, a0, ja,
                                            np.zeros(6), sd),
                       [(B(k), 6), (B(k + 1), 6), (a0, 3)], zeros)
    # four keys (a segment boundary): GTSAM's Python JacobianFactor takes ≤ 3, so the
    # information JᵀΣ⁻¹J goes in as ≤ 3-key Hessian pieces (``general.information_factor``)
    jac = np.zeros((6, 18))
    jac[:, 0:6], jac[:, 6:12] = minus_phi, eye
    jac[0:3, 12:15], jac[0:3, 15:18] = np.diag(f0), -np.diag(f1)
    jw = jac / np.sqrt(var)[:, None]
    keys = [(B(k), 6), (B(k + 1), 6), (a0, 3), (a1, 3)]
    return information_factor([key for key, _ in keys], jw.T @ jw, np.zeros(18),
                              ((0, 6), (6, 6), (12, 3), (15, 3)),
                              _zeros(keys) if zeros is None else zeros)


def imu_factor(k: int, pim: Any) -> Any:
    """Interval k's IMU factor on X(k), V(k), X(k+1), V(k+1) and its bias B(k) (the biases'
    Gauss-Markov step is ``bias_link``)."""
    return gtsam.ImuFactor(X(k), V(k), X(k + 1), V(k + 1), B(k), pim)


def gm_link(key0: int, key1: int, dt: float, tau: float, sd: float, zeros: Any = None) -> Any:
    """Exact discrete Gauss-Markov link x_1 − φ x_0 = w, φ = e^{−Δt/τ}, var w = σ²(1 − φ²),
    between two scalar variables, as a (linear) C++ factor (``zeros``: as in ``_linear``)."""
    phi = float(gm_transition(dt, tau))
    sd_w = float(np.sqrt(max(gm_process_var(dt, tau, sd), 1e-12)))
    return _linear(gtsam.JacobianFactor(key0, np.array([[-phi]]), key1, np.array([[1.0]]),
                                        np.zeros(1), noise([sd_w])), [(key0, 1), (key1, 1)],
                   zeros)


def gm_factor(k: int, dt: float, pri: dict[str, float], zeros: Any = None) -> Any:
    """The baro bias's Gauss-Markov link C(k) → C(k+1)."""
    return gm_link(C(k), C(k + 1), dt, pri["b_tau"], pri["b_sd"], zeros)


def gnss_gm_factor(k: int, dt: float, gm: GnssGM, zeros: Any = None) -> Any:
    """The GNSS error state's Gauss-Markov link G(k) → G(k+1), one exact discrete step per
    carried axis (``gm_link``; a diagonal vector link when more than one axis is carried)."""
    if gm.dim == 1:
        return gm_link(G(k), G(k + 1), dt, gm.tau_s, gm.sd_m, zeros)
    phi = float(gm_transition(dt, gm.tau_s))
    sd_w = [float(np.sqrt(max(gm_process_var(dt, gm.tau_s, float(s)), 1e-12))) for s in gm.sd]
    eye = np.eye(gm.dim)
    return _linear(gtsam.JacobianFactor(G(k), -phi * eye, G(k + 1), eye, np.zeros(gm.dim),
                                        noise(sd_w)), [(G(k), gm.dim), (G(k + 1), gm.dim)],
                   zeros)



def level(f_b: FloatArray) -> FloatArray:
    """Rotation matrix of the roll/pitch from a static specific force (coarse_level), yaw 0."""
    roll, pitch = coarse_level(f_b)
    return gtsam.Rot3.Ypr(0.0, pitch, roll).matrix()


def gap_factors(P: Problem, k: int, rot: FloatArray, pos: FloatArray, vel: FloatArray,
                a_keys: tuple[int, int] | None = None) -> tuple[Any, FloatArray, list[Any]]:
    """Weak factors replacing the IMU factor over a logging gap in interval k (both smoothers).

    A gap of T seconds with no IMU samples carries no inertial information (one "sample"
    spanning it is usually a transient, e.g. a crash's spike, and a CombinedImuFactor built
    from it asserts a velocity change of hundreds of m/s with a σ under 1 m/s, which the baro
    scale then absorbs; docs/real_logs.md, "IMU logging gap across a crash"). Instead, with a
    = ``GAP_ACCEL_LEVEL``: v_{k+1} − v_k ~ N(0, (a T)²), b_{k+1} − b_k ~ N(0, q_b T)
    with the bias PSD q_b of the preintegration (Forster et al. 2017, Eq. 48), and a re-
    alignment prior on X(k+1): roll and pitch levelled from the mean specific force of the first
    0.5 s after the gap (σ ``GAP_TILT_SD``; the vehicle may have been flipped, f_z +g before
    and −g after, and the weak factors cannot pull a 180° error back inside Gauss-Newton's
    basin), yaw kept from before the gap (σ ``GAP_YAW_SD``), position at the last
    GNSS fix at or before t_{k+1} (within 1.5 s; else constant velocity) with σ_p = v_sd T + ½ a
    T². Every new variable stays constrained.

    ``rot, pos, vel``: current keyframe states (only index k is read). Returns (Pose3 value of
    X(k+1), velocity value (3,), factors).
    """
    T = float(P.t_kf[k + 1] - P.t_kf[k])
    p1 = pos[k] + vel[k] * T
    v1 = np.array(vel[k], dtype=float)
    sel = np.flatnonzero(P.g_pos_use & (P.g_t <= P.t_kf[k + 1] + 1e-9)
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


def gap_start_states(P: Problem, rot: FloatArray, pos: FloatArray, vel: FloatArray
                     ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Copies of ``rot, pos, vel`` with the keyframe after each IMU logging gap set to its
    gap prior's centre (``gap_factors``, gaps in time order), as ``build_batch_graph``
    builds them: the states whose ``gap_factors`` are the batch problem's. graph-isam2 takes
    its gap priors from these (from the initial states), so that its problem is
    graph-batch's."""
    rot, pos, vel = rot.copy(), pos.copy(), vel.copy()
    for k in np.flatnonzero(P.gap):
        x1, v1, _ = gap_factors(P, int(k), rot, pos, vel)
        rot[k + 1], pos[k + 1], vel[k + 1] = x1.rotation().matrix(), x1.translation(), v1
    return rot, pos, vel


def build_batch_graph(P: Problem, rot: FloatArray, pos: FloatArray, vel: FloatArray,
                       pims: list[Any] | None, pri: dict[str, float],
                       calib_of_kf: np.ndarray) -> tuple[Any, Any]:
    """C++ part of the batch graph: priors, IMU factors and the biases' links (``gap_factors``
    over IMU logging gaps), the Gauss-Markov links and the zero-velocity priors
    (``zupt_factor``). Every GNSS fix (on keyframe epochs
    too) enters as an interval term so that the gates can drop it without rebuilding the graph.
    ``pims`` None: no IMU factors (only the initial values are wanted)."""
    graph = prior_factors(P, rot[0], pos[0], vel[0], pri, K(0))
    vals = gtsam.Values()
    nk = P.n_kf
    gap = P.gap
    if gap.any():  # the keyframe after each gap starts at its gap prior's centre
        rot, pos, vel = gap_start_states(P, rot, pos, vel)
    # the variables that start at zero (B, C, G, A) first: the linear links below take their
    # linearisation point (zero) from ``vals`` instead of a Values made for each link
    has_baro = P.drive.baro is not None
    for k in range(nk):
        vals.insert(B(k), gtsam.imuBias.ConstantBias())
        if has_baro:
            vals.insert(C(k), np.zeros(1))
        if P.gm is not None:
            vals.insert(G(k), np.zeros(P.gm.dim))
    if P.ka is not None:
        vals.insert(A(0), np.zeros(3))
    dts = np.diff(P.t_kf)
    phis, bvars = bias_step(P.imu_spec, dts)  # every interval's bias step at once
    for k in range(nk):
        vals.insert(X(k), gtsam.Pose3(gtsam.Rot3(rot[k]), pos[k]))
        vals.insert(V(k), vel[k])
        if k + 1 < nk:
            dt = float(dts[k])
            if gap[k]:
                for f in gap_factors(P, k, rot, pos, vel)[2]:
                    graph.add(f)
            elif pims is not None:
                graph.add(imu_factor(k, pims[k]))
                graph.add(bias_link(P, k, dt, step=(phis[k], bvars[k]), zeros=vals))
            if has_baro:
                graph.add(gm_factor(k, dt, pri, vals))
            if P.gm is not None:
                graph.add(gnss_gm_factor(k, dt, P.gm, vals))
    for k in np.flatnonzero(P.zupt_kf):
        graph.add(zupt_factor(P, int(k)))
    if has_baro:
        for j in np.unique(calib_of_kf):
            vals.insert(K(int(j)), np.array([0.0, pri["tau0"]]))
    return graph, vals


def pims_for(P: Problem, rot: FloatArray, pos: FloatArray) -> list[Any]:
    dg = gravity_delta(P, pos)
    bias0 = gtsam.imuBias.ConstantBias()
    return [preintegrate(P, k, rot[k], dg[k], bias0) for k in range(P.n_kf - 1)]
