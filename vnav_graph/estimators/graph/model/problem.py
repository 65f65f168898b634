"""Problem set-up of the factor-graph smoothers: the ``Problem`` (keyframes, GNSS in the
tangent frame and its pre-gate, baro priors, IMU logging gaps, the accelerometer scale
factors), preintegration, and the interval rows of the custom baro/GNSS terms at a
linearisation point (the settings: ``settings.GraphConfig``). The C++ factors built from it
are in ``cpp_factors``. Used by ``batch.smoother``, ``solver.solve``, ``isam2.smoother``,
``isam2.relin`` and ``isam2.linear_factors``."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import gtsam
import numpy as np
from gtsam.symbol_shorthand import B, K, X

from ....config import REAL_LOG_BARO, BaroSpec, ImuSpec
from ....geo.earth import gravity
from ....nav.arrays import nearest_index
from ....nav.gaps import imu_gaps as nav_imu_gaps
from ....nav.gnss_glitch import causal_glitch_mask, glitch_mask
from ....nav.velocity_screen import velocity_screen
from ....sensors.gnss_model import GnssGM
from ....sensors.model import (
    BaroPrior,
    accel_scale_sd,
    baro_prior,
    sensor_model,
)
from ....types import Drive
from ....types.streams import FloatArray
from ...robust import post_gate_threshold
from ...zupt import drive_standstill
from ..settings import GraphConfig
from . import interval_factors as gf
from .accel_scale import AccelScale, interval_mean_force
from .dense_increments import DenseIncrements, dense_preintegration
from .gnss_pregate import pregate_gnss
from .robust import reweight

# σ [m] of a kept fix's refused position (``Problem.g_pos_drop``): its rows then carry no
# information (1e-12 of a 1 m fix's) and its velocity rows stay
POS_DROPPED_SD = 1e6


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
    dense: DenseIncrements
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
    g_rej_pre: int = 0  # rejected by the pre-gate (baro consistency, position glitches and
    # the velocity screen)
    g_rej_vel: int = 0  # of those, refused by the velocity screen (nav.velocity_screen)
    # used fixes whose position the pre-gate refused and whose velocity passed the velocity
    # screen: the velocity is kept, the position carries no information (``POS_DROPPED_SD``)
    g_pos_drop: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    g_rej_post: int = 0  # rejected by the post-solve residual gate
    g_incr: Any = None  # (fix indices, dense increments at them), see gnss_rows_of
    # body rate at each fix [rad/s] for the lever arm's velocity (None without a lever arm)
    g_omega: FloatArray | None = None
    pri: dict[str, float] = field(default_factory=dict)  # baro priors (_baro_priors)
    gm: GnssGM | None = None  # the GNSS Gauss-Markov error state G(k), if carried
    # interval k spans an IMU logging gap (``imu_gaps``; computed once in ``setup``)
    gap: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    ka: AccelScale | None = None  # the accelerometer scale factors A(0), if carried
    # where the initial keyframe attitudes came from (``initial_guess.initial_states``): "triad",
    # "compass" or "ekf"; and why not the ekf's where it was due but failed
    init_attitude: str = "triad"
    init_note: str = ""
    # graph-isam2's causal start (``initial_guess.CausalStart``), set by ``initial_states``
    start0: Any = None
    # the first keyframe whose initial heading is the forward ekf's own (``filter_attitude``)
    ekf_heading_kf: int = 0
    # keyframes inside a detected standstill (``nav.standstill``, ``GraphConfig.zupt``): a
    # zero-velocity prior of σ ``zupt_sd`` [m/s] on V(k) (``cpp_factors.zupt_factor``)
    zupt_kf: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    zupt_sd: float = 0.0
    zupt_intervals: list[list[float]] = field(default_factory=list)
    # the shared model's note when it raised the GNSS velocity σ (``sensors.gnss_consistency``)
    gnss_vel_note: str = ""

    def zupt_info(self) -> dict[str, Any]:
        """``info["zupt_intervals"]`` ([t_start, t_end] [s]) and ``zupt_keyframes`` (the
        keyframes given a zero-velocity prior) of both smoothers."""
        return {"zupt_intervals": self.zupt_intervals,
                "zupt_keyframes": int(np.count_nonzero(self.zupt_kf))}

    def sensor_info(self) -> dict[str, str]:
        """``info["gnss_vel_note"]`` of both smoothers when the shared sensor model raised
        the GNSS velocity σ (``SensorModel.gnss_vel_note``), else nothing."""
        return {"gnss_vel_note": self.gnss_vel_note} if self.gnss_vel_note else {}

    def init_info(self) -> dict[str, str]:
        """``info["init_attitude"]`` (and ``init_note`` when there is one) of both smoothers."""
        return {"init_attitude": self.init_attitude,
                **({"init_note": self.init_note} if self.init_note else {})}

    def __post_init__(self) -> None:
        if self.g_pos_drop.shape != self.g_use.shape:
            self.g_pos_drop = np.zeros(self.g_use.shape, dtype=bool)

    @property
    def gnss_rejected(self) -> int:
        """Fixes inside the keyframe span refused whole or in their position."""
        return int(np.sum((~self.g_use | self.g_pos_drop) & (self.g_kf >= -1)))

    @property
    def g_pos_use(self) -> np.ndarray:
        """The fixes whose position is used (``g_use`` less ``g_pos_drop``)."""
        return self.g_use & ~self.g_pos_drop

    @property
    def n_kf(self) -> int:
        return int(self.t_kf.size)


def gnss_gates(drive: Drive, model: Any, cfg: GraphConfig, t_g: FloatArray, pos: FloatArray,
               t_kf: FloatArray, g_kf: np.ndarray, pri: dict[str, float], g0: float,
               causal: bool) -> tuple[np.ndarray, np.ndarray, int]:
    """The pre-solve GNSS gates of ``setup``: the baro height pre-gate, the glitch mask and
    the velocity screen. Returns the used fixes, those of them whose position is refused
    (their velocity kept, ``Problem.g_pos_drop``) and the number the velocity screen
    refused."""
    gn, imu, spec = drive.gnss, drive.imu, model.imu
    # the keyframe at which each fix enters graph-isam2's online pass (its data up to then)
    t_enter = t_kf[np.minimum(np.searchsorted(t_kf, t_g - 1e-6), t_kf.size - 1)]
    use = pregate_gnss(drive, t_g, gn.lla[:, 2], model.gnss_pos_sd[:, 2], pri,
                        cfg.gnss_gate_prob,
                        None if gn.vel_n is None else gn.vel_n[:, 2],
                        None if gn.vel_sd is None else gn.vel_sd[:, 2],
                        t_enter if causal else None)
    if cfg.gnss_gate_prob > 0:
        # fixes that jump away faster than any vehicle and come back (nav.gnss_glitch): the
        # post-solve gate cannot take them, the initial guess already follows them (a 10 km
        # jump held for 5 s left both smoothers 700 m off and graph-isam2's information
        # blocks indefinite)
        # heights: the baro gate above
        use &= ~(causal_glitch_mask if causal else glitch_mask)(t_g, pos[:, :2])
    n_vel = 0
    pos_drop = np.zeros(t_g.size, dtype=bool)
    if cfg.velocity_screen and gn.vel_n is not None and cfg.gnss_gate_prob > 0:
        # GNSS velocity against the IMU's specific-force integral (attitude-free)
        ok_v = velocity_screen(t_g, gn.vel_n, model.gnss_vel_sd, imu.t, imu.gyro_b,
                               imu.accel_b, g0, spec.accel_bias_sd,
                               accel_scale_sd(model, cfg.accel_scale),
                               spec.accel_noise_density, cfg.gnss_gate_prob)
        n_vel = int(np.sum(~ok_v & (g_kf >= -1)))
        # a fix whose position the gates above refused keeps a velocity that passed this
        # screen, as the ekf gates position and velocity apart (a multipath burst biases
        # positions by tens of metres, its Doppler velocities hardly)
        pos_drop = ~use & ok_v & np.all(np.isfinite(gn.vel_n), axis=1)
        use = (use | pos_drop) & ok_v
    return use, pos_drop, n_vel


def setup(drive: Drive, cfg: GraphConfig, causal: bool = False) -> Problem:
    """The problem of ``drive`` under ``cfg``. ``causal``: the GNSS pre-gates decide each fix
    from the data up to the keyframe at which it enters (graph-isam2, whose online answer
    is real time): ``gnss_pregate.pregate_gnss``'s causal seed, climb rate and baro epoch, and
    ``nav.gnss_glitch.causal_glitch_mask``; without it (graph-batch) they may use the whole
    drive."""
    imu = drive.imu
    origin = np.asarray(drive.origin_lla, float)
    h0 = float(origin[2])
    g0 = float(gravity(origin[0], origin[2]))
    model = sensor_model(drive)  # the noise model every estimator shares (sensors.model)
    spec = model.imu
    bspec = model.baro
    kf_idx = gf.keyframe_indices(imu.t, cfg.keyframe_dt)
    dense = dense_preintegration(imu.t, imu.gyro_b, imu.accel_b, kf_idx)
    gaps = imu_gaps(imu.t, kf_idx)
    if gaps.any():
        dense = replace(dense, gap=gaps)
    omega_t = gf.earth_rate_t(origin) if cfg.coriolis else np.zeros(3)
    p = gtsam.PreintegrationCombinedParams.MakeSharedD(g0)
    # continuous-time densities, not discrete variances; floors keep noiseless drives regular
    p.setAccelerometerCovariance(np.eye(3) * spec.accel_noise_density**2)
    p.setGyroscopeCovariance(np.eye(3) * spec.gyro_noise_density**2)
    p.setIntegrationCovariance(np.eye(3) * 1e-8)
    # (no bias covariances: ImuFactor does not read them; the biases' Gauss-Markov step is
    # ``cpp_factors.bias_link``)
    p.setOmegaCoriolis(omega_t)
    gn = drive.gnss
    t_kf = imu.t[kf_idx]
    if gn is None or len(gn) == 0:
        raise ValueError("graph: the drive has no GNSS fixes (needed to anchor the graph)")
    # fix times of validity: the stamp minus the receiver's latency (GnssSpec.latency_s), as
    # the ekf takes them (ekf.alignment)
    t_g = gn.t - float(getattr(gn.spec, "latency_s", 0.0) or 0.0)
    pos = gf.to_tangent(gn.lla, origin)
    c_tn = gf.rot_t_n(gn.lla, origin)
    vel = None if gn.vel_n is None else np.einsum("nij,nj->ni", c_tn, gn.vel_n)
    # the nearer keyframe of the two around each fix (a keyframe stamp a hair before the fix's
    # own was missed when only the next one was looked at: on hill-drive seed 0, 236 of the
    # 540 fixes on keyframe epochs, which then entered graph-isam2 two keyframes late)
    j = nearest_index(t_kf, t_g)
    on_kf = np.abs(t_kf[j] - t_g) < 1e-6
    inside = (t_g >= t_kf[0]) & (t_g <= t_kf[-1])
    g_kf = np.where(on_kf, j, -1)
    g_kf[~inside] = -2
    pri = _baro_priors(bspec)
    if cfg.baro_scale_sd is not None:  # the post-solve scale check's (sensors.baro)
        pri["s_sd"] = float(cfg.baro_scale_sd)
    use, pos_drop, n_vel = gnss_gates(drive, model, cfg, t_g, pos, t_kf, g_kf, pri, g0,
                                      causal)
    P = Problem(drive, cfg, origin, h0, g0, omega_t, kf_idx, t_kf, dense, p, spec, bspec,
                t_g, pos, np.where(pos_drop[:, None], POS_DROPPED_SD, model.gnss_pos_sd), vel,
                model.gnss_vel_sd, np.asarray(gn.lever_arm_b, float), g_kf, use,
                g_pos_drop=pos_drop)
    P.gap = gaps
    P.gnss_vel_note = model.gnss_vel_note()
    if np.any(P.lever):
        P.g_omega = np.column_stack([np.interp(t_g, imu.t, imu.gyro_b[:, a]) for a in range(3)])
    P.g_rej_pre = P.gnss_rejected
    P.g_rej_vel = n_vel
    P.pri = pri
    gm = cfg.gnss_gm
    if gm is not None:
        # the pre-gate above used the receiver's whole σ (it models no GNSS error state)
        P.gm = gm  # g_pos_sd becomes the white rest of the receiver's σ
        P.g_pos_sd = gm.split(P.g_pos_sd)
    ka_sd = accel_scale_sd(model, cfg.accel_scale)  # the rule every estimator shares
    if ka_sd > 0:
        P.ka = AccelScale(ka_sd, interval_mean_force(imu.t, imu.accel_b, kf_idx, gaps))
    if not np.any(use & inside):
        raise ValueError("graph: every GNSS fix inside the IMU span was rejected by the "
                         "baro-consistency gate")
    P.zupt_kf = np.zeros(kf_idx.size, dtype=bool)
    if cfg.zupt:
        still = drive_standstill(drive, model)
        P.zupt_kf = still.still[kf_idx]
        P.zupt_sd = still.vel_sd
        P.zupt_intervals = still.interval_list()
    return P


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
    f' = f + (R_k ΔR_j)ᵀ δg_k. GTSAM's step rotates the specific force by the attitude at the
    step's start (first order in Δt); the body turns by ω·Δt during the step, so the
    velocity increment misses ½ (ω × f) Δt² per step (the sculling-like term the ekf's
    ``strapdown_step`` carries). It is added to the sample, f'' = f' + ½ (ω × f') Δt, which
    makes the increment exact to second order for constant ω and f over the step: without
    it the online estimate's 60 s outage error on a noiseless hill-drive was 0.2–0.6 m
    larger than the ekf's (``docs/graph.md``, "Variables, factors, keyframes")."""
    imu = P.drive.imu
    j0, j1 = int(P.kf_idx[k]), int(P.kf_idx[k + 1])
    fm = 0.5 * (imu.accel_b[j0:j1] + imu.accel_b[j0 + 1:j1 + 1])
    wm = 0.5 * (imu.gyro_b[j0:j1] + imu.gyro_b[j0 + 1:j1 + 1])
    if np.any(dg_k):
        fm = fm + np.einsum("nji,j->ni", P.dense.rot(j0, j1), r_k.T @ dg_k)
    dts = np.diff(imu.t[j0:j1 + 1])
    fm = fm + 0.5 * np.cross(wm, fm) * dts[:, None]
    pim = gtsam.PreintegratedImuMeasurements(P.params, bias)
    integ = pim.integrateMeasurement
    for a, w, dt in zip(fm, wm, dts, strict=True):
        integ(a, w, dt)
    return pim


def noise(sd: FloatArray) -> Any:
    return gtsam.noiseModel.Diagonal.Sigmas(np.asarray(sd, dtype=float))


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
    g_gm = None
    if P.gm is not None:  # (K,) for the height alone, else (K, d)
        g_gm = gtsam.utilities.extractVectors(vals, "g")
        g_gm = g_gm[:, 0] if P.gm.dim == 1 else g_gm
    return gf.KeyframeStates(rot, pos, vel, ba, cb, s, tau, nav_accel(P, pos, vel), g_gm)


def nav_accel(P: Problem, pos: FloatArray, vel: FloatArray,
              dg: FloatArray | None = None) -> FloatArray:
    """The kinematic acceleration the interval terms expect at rest in the tangent frame:
    gravity (γ(origin) plus the anomaly ``dg`` at ``pos``, computed when not given) minus
    the Coriolis term 2Ω×v, per keyframe."""
    g = gravity_delta(P, pos) if dg is None else dg
    return np.array([0.0, 0.0, P.g0]) + g - 2 * np.cross(P.omega_t, vel)


CHI2_BLOCK = 2048  # fixes per block of ``gnss_chi2``


def post_solve_rejections(P: Problem, st: gf.KeyframeStates) -> np.ndarray:
    """The post-solve GNSS gate at the states ``st`` over every used fix (``gate_failures``).
    The failing fixes are marked unused (``P.g_use``) and counted (``P.g_rej_post``); returns
    them, empty when none or every one fails (or gating is off)."""
    idx = gate_failures(P, st, gnss_batch_idx(P))
    P.g_use[idx] = False
    P.g_rej_post += int(idx.size)
    return idx


def gate_failures(P: Problem, st: gf.KeyframeStates, idx: np.ndarray,
                  k: np.ndarray | None = None) -> np.ndarray:
    """The fixes among ``idx`` whose whitened residual χ² at the states ``st`` exceeds the
    post-solve threshold of ``gnss_gate_prob`` (``estimators.robust.post_gate_threshold``);
    empty when none or every one fails (a solution that fits none of them is not one to judge
    them by), or when gating is off. ``k``: each fix's interval (``gnss_chi2``)."""
    if idx.size == 0 or P.cfg.gnss_gate_prob <= 0:
        return idx[:0]
    c2, dof = gnss_chi2(P, st, idx, k)
    bad = c2 > post_gate_threshold(float(P.cfg.gnss_gate_prob), dof)
    if not np.any(bad) or np.all(bad):
        return idx[:0]
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
    return _gnss_rows(P, st, idx, P.g_incr[1], out)


def _gnss_rows(P: Problem, st: gf.KeyframeStates, idx: np.ndarray, incr: Any,
               out: FloatArray | None = None, k: np.ndarray | None = None
               ) -> gf.IntervalRows:
    """``gf.gnss_rows`` of fixes ``idx`` with the IMU increments ``incr`` at them (None:
    computed for these fixes); ``k``: each fix's interval (default: the one holding it)."""
    return gf.gnss_rows(
        P.dense, st, P.g_t[idx], P.g_pos[idx], P.g_pos_sd[idx],
        None if P.g_vel is None else P.g_vel[idx],
        None if P.g_vel_sd is None else P.g_vel_sd[idx], P.lever, incr=incr, out=out, k=k,
        omega_b=None if P.g_omega is None else P.g_omega[idx])


def interval_rows(P: Problem, st: gf.KeyframeStates, pri: dict[str, float],
                  bias_lag: float) -> gf.IntervalRows:
    """Baro and GNSS interval rows; ``bias_lag``: see ``interval_factors.baro_rows``. Under robust
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
    n_cols = gf.n_cols_of(0 if P.gm is None else P.gm.dim)
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


def gnss_chi2(P: Problem, st: gf.KeyframeStates, idx: np.ndarray,
              k: np.ndarray | None = None) -> tuple[FloatArray, int]:
    """χ² of each fix's whitened residual at the solution (position, + velocity when the log
    has it) and its degrees of freedom. ``k``: each fix's interval (default: the one holding
    it; a fix on keyframe k+1 can be given interval k, ``gf.gnss_rows``)."""
    m = idx.size
    cached = k is None and P.g_incr is not None and np.array_equal(P.g_incr[0], idx)
    c2 = np.empty(m)
    n_kind = 1
    # in blocks of fixes: only the residuals are needed, and the Jacobian of every fix at
    # once (35 000 fixes on a 1-hour drive: 32 MB) was graph-isam2's memory peak, on top of
    # its Bayes tree
    for a in range(0, m, CHI2_BLOCK):
        sl = slice(a, a + CHI2_BLOCK)
        ii = idx[sl]
        rows = _gnss_rows(P, st, ii, tuple(x[sl] for x in P.g_incr[1]) if cached else None,
                          k=None if k is None else k[sl])
        r = rows.r.reshape(-1, ii.size, 3)  # (1 or 2, n, 3): position rows, then velocity
        c2[sl] = np.sum(r**2, axis=(0, 2))
        n_kind = r.shape[0]
    return c2, 3 * n_kind
