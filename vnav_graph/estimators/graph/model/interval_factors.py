"""Custom measurement terms of the factor-graph smoother, linearised in vectorised numpy.

Contents
--------
- Tangent-plane frame helpers: the graph runs in ONE Earth-fixed NED frame ``t`` (tangent plane
  at ``Drive.origin_lla``); ``rot_t_n`` rotates local-level NED at any (lat, lon) into ``t``,
  ``gravity_t`` gives the WGS-84 normal gravity vector resolved in ``t`` (its tilt and
  magnitude change over the drive are folded into the preintegration, see ``docs/graph.md``).
- ``dense_preintegration`` (module ``dense_increments``): body-frame increments ΔR, Δv, Δp
  from each keyframe to every IMU sample inside its interval (numba), used to interpolate the
  state at any sample time.
- ``interval_terms``: residuals and Jacobians of baro samples and GNSS fixes that fall between
  keyframes, through the interpolant

      p(t) = (1−α) p_k + α p_{k+1} + ½ a_k (τ² − τT) + R_k (Δp(τ) − α ΔP(T)),   α = τ/T,

  (τ = t − t_k, T = t_{k+1} − t_k, a_k = g + δg_k − 2Ω×v_k the nav-frame acceleration not
  measured by the IMU). It matches both keyframes exactly and follows the IMU-measured motion
  in between (Forster et al. 2017 preintegration, evaluated at intermediate samples).
- The baro row is the shared model (``vnav_graph.sensors.baro``) evaluated at the delayed
  time t_s − τd:  h_b = h0 + (1+s)(h(t_s−τd) − h0) + b(t_s−τd), with
  ∂/∂τd = −(1+s) v_up(t_s−τd) (docs/design.md; seed 001 eq. 2 is its first-order form).
- ``group_information``: per-interval information (Λ, η) of all those rows, reduced in one
  batched ``einsum`` (``general`` splits it into ≤3-key HessianFactor pieces: GTSAM's Python
  constructors take at most three keys).

Variables of one interval group, in column order: pose X_k (rotation 3, translation 3, GTSAM
Pose3 tangent: R ← R·Exp(ω), p ← p + R·v), pose X_{k+1}, baro bias b_k, b_{k+1}, the baro
calibration (s, τd) — the 16 "core" columns — and the accelerometer bias of keyframe k
(3 columns, last). The interpolant corrects the dense increments for that bias to first order
(Δp(τ) − ½τ²b_a), so ∂p(t)/∂b_a = ½τ(T − τ)·R_k and ∂v(t)/∂b_a = (½T − τ)·R_k; leaving these
columns out makes the Jacobian disagree with the cost and Gauss-Newton converge only linearly.
The gyro-bias dependence of the interpolant (second order over one interval) is not modelled.
The GNSS rows are the shared measurement model (``sensors.gnss_model``: antenna p + C l + e,
attitude Jacobian −[(C l)×] in t turned into the body rotation's by ``body_tilt``). With the
optional Gauss-Markov GNSS error state (``GraphConfig.gnss_gm_sd_h`` / ``gnss_gm_sd_v``,
G(k) of dimension d = 1 (down), 2 (north, east) or 3) the rows have 2d more columns, that
error at keyframes k and k+1 (``gm_cols``; linear in time between them, like the baro bias).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ....geo.earth import OMEGA_IE, gravity
from ....geo.frames import lla_to_ned, ned_to_lla, skew
from ....sensors.baro import baro_arrays
from ....sensors.gnss_model import (
    GM_AXES,
    antenna_arrays,
    body_tilt,
)
from ....types.streams import FloatArray
from .dense_increments import DenseIncrements
from .interp import interpolant

N_COLS = 19
N_CORE = 16  # columns of the five key blocks below (the baro-bias/calibration part)
COL_X0 = slice(0, 6)
COL_X1 = slice(6, 12)
COL_B0 = 12
COL_B1 = 13
COL_S = 14
COL_TAU = 15
COL_BA = slice(16, 19)
# key blocks of a group: (first column, width)
BLOCKS = ((0, 6), (6, 6), (12, 1), (13, 1), (14, 2))


def n_cols_of(gm_dim: int) -> int:
    """Columns of the rows with a GNSS error state of dimension ``gm_dim`` (0: none)."""
    return N_COLS + 2 * gm_dim


def gm_cols(gm_dim: int) -> tuple[slice, slice]:
    """Columns of the GNSS error state at keyframes k and k+1 (after ``N_COLS``)."""
    return slice(N_COLS, N_COLS + gm_dim), slice(N_COLS + gm_dim, N_COLS + 2 * gm_dim)


def gm_dim_of(st: KeyframeStates) -> int:
    """Dimension of the GNSS error state of ``st`` (0 when not carried)."""
    g = st.gnss_gm
    return 0 if g is None else (1 if g.ndim == 1 else int(g.shape[1]))


def rot_n_e(lat: FloatArray, lon: FloatArray) -> FloatArray:
    """C_ne (..., 3, 3): ECEF → local NED at (lat, lon) [rad] (Groves eq. 2.150)."""
    sl, cl = np.sin(lat), np.cos(lat)
    so, co = np.sin(lon), np.cos(lon)
    out = np.empty(np.shape(lat) + (3, 3))
    out[..., 0, 0], out[..., 0, 1], out[..., 0, 2] = -sl * co, -sl * so, cl
    out[..., 1, 0], out[..., 1, 1], out[..., 1, 2] = -so, co, 0.0
    out[..., 2, 0], out[..., 2, 1], out[..., 2, 2] = -cl * co, -cl * so, -sl
    return out


def rot_t_n(lla: FloatArray, origin_lla: FloatArray) -> FloatArray:
    """C_tn (N, 3, 3): local-level NED at ``lla`` (N, 3) → tangent NED at ``origin_lla``."""
    lla = np.atleast_2d(lla)
    c_te = rot_n_e(np.asarray(origin_lla[0]), np.asarray(origin_lla[1]))
    c_ne = rot_n_e(lla[:, 0], lla[:, 1])
    return np.einsum("ij,nkj->nik", c_te, c_ne)


def earth_rate_t(origin_lla: FloatArray) -> FloatArray:
    """Ω_ie resolved in the (Earth-fixed) tangent frame, (3,) [rad/s] — constant."""
    lat = float(origin_lla[0])
    return np.array([OMEGA_IE * np.cos(lat), 0.0, -OMEGA_IE * np.sin(lat)])


def gravity_t(pos_t: FloatArray, origin_lla: FloatArray) -> FloatArray:
    """Normal gravity vector at tangent positions ``pos_t`` (N, 3) [m], resolved in t [m/s²].

    g_t = C_tn(p)·[0, 0, γ(lat, h)]: the local vertical tilts by ≈ distance/R against the
    tangent-plane down axis and γ falls by ≈ 3.1e-6 /m with height."""
    lla = ned_to_lla(pos_t, origin_lla)
    c = rot_t_n(lla, origin_lla)
    return c[:, :, 2] * gravity(lla[:, 0], lla[:, 2])[:, None]


def height_and_up(pos_t: FloatArray, origin_lla: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Ellipsoidal height h (N,) [m] of tangent positions and ∂h/∂p_t = local up in t (N, 3)."""
    lla = ned_to_lla(pos_t, origin_lla)
    c = rot_t_n(lla, origin_lla)
    return lla[:, 2], -c[:, :, 2]


@dataclass(frozen=True)
class KeyframeStates:
    """Linearisation point of the interval terms at the K keyframes.

    rot (K, 3, 3) R_tb; pos (K, 3) tangent NED [m]; vel (K, 3) [m/s]; bias_accel (K, 3)
    [m/s²]; baro_bias (K,) [m]; scale, latency (K,) baro calibration per keyframe (constant
    for the batch graph, per segment for the incremental front end); accel_t (K, 3): the
    unmeasured nav-frame acceleration g + δg − 2Ω×v over each interval [m/s²]; gnss_gm (K, d)
    the GNSS Gauss-Markov error on its axes (``GM_AXES``; (K,) for the height alone) [m],
    None when the graph has no such state."""

    rot: FloatArray
    pos: FloatArray
    vel: FloatArray
    bias_accel: FloatArray
    baro_bias: FloatArray
    scale: FloatArray
    latency: FloatArray
    accel_t: FloatArray
    gnss_gm: FloatArray | None = None


@dataclass(frozen=True)
class IntervalRows:
    """Whitened rows ``r + J δ`` of the interval terms: interval index ``k`` (M,), residual
    ``r`` (M,) and Jacobian ``jac`` (M, 19, or 19 + 2d with a GNSS error state of dimension d)
    in the column order of this module."""

    k: np.ndarray
    r: FloatArray
    jac: FloatArray
    loss: float | None = None  # Σρ of the measurements when robust losses reweighted the rows
    weights: dict | None = None  # per-measurement IRLS weights (``robust``), by type

    @property
    def cost(self) -> float:
        """The terms' cost: Σρ under robust losses, else ½‖r‖²."""
        return self.loss if self.loss is not None else 0.5 * float(self.r @ self.r)

    def without_jac(self) -> IntervalRows:
        """The same rows with an empty (0, N_COLS) Jacobian: for rows whose linear system is
        already built (the Jacobian is ~46 MB on a 1-hour drive)."""
        return IntervalRows(self.k, self.r, np.zeros((0, self.jac.shape[1])), self.loss,
                            self.weights)


def interval_of(t_kf: FloatArray, t: FloatArray) -> np.ndarray:
    """Index k of the keyframe interval [t_k, t_{k+1}) holding each time (clipped to the first
    and last interval)."""
    return np.clip(np.searchsorted(t_kf, t, side="right") - 1, 0, t_kf.size - 2)


def interpolate(
    dense: DenseIncrements, st: KeyframeStates, t_q: FloatArray, k: np.ndarray,
    incr: tuple[FloatArray, FloatArray, FloatArray] | None = None, with_rot: bool = True,
) -> dict[str, FloatArray]:
    """Interpolated position p(t) (M, 3), velocity v(t) (M, 3), attitude R(t) (M, 3, 3) at
    times ``t_q`` inside intervals ``k``, plus the pieces the Jacobians need. ``incr``:
    ``dense.at(t_q, k)`` if the caller already has it (it depends on the times only);
    ``with_rot=False`` skips R(t) (``"rot"`` is then None)."""
    t_q = np.ascontiguousarray(t_q, dtype=float)
    k = np.ascontiguousarray(k, dtype=np.intp)
    dr, dv, dp = dense.at(t_q, k) if incr is None else incr
    # an interval holding an IMU logging gap has no inertial motion to follow (its one
    # "sample" across the gap is a transient, e.g. a crash, whose integral puts the baro
    # samples after the gap far off; docs/real_logs.md, "IMU logging gap across a crash"):
    # the linear interpolant between the keyframes, attitude R_k, no
    # accelerometer-bias dependence (the gap factors link the keyframes loosely)
    gap = dense.gap if dense.gap is not None else np.zeros(dense.kf_idx.size, dtype=bool)
    p, v, rot, alpha, d, dvel, big_t, tau, imu = interpolant(
        dense.t_kf, dense.dv_end, dense.dp_end, gap, np.ascontiguousarray(dr),
        np.ascontiguousarray(dv), np.ascontiguousarray(dp), t_q, k,
        np.ascontiguousarray(st.pos), np.ascontiguousarray(st.rot),
        np.ascontiguousarray(st.bias_accel), np.ascontiguousarray(st.accel_t), with_rot)
    return {"p": p, "v": v, "rot": rot if with_rot else None, "alpha": alpha, "d": d,
            "dvel": dvel, "T": big_t, "tau": tau, "imu": imu}


GAP_ACCEL_LEVEL = 2.0  # m/s²: unknown acceleration over an IMU logging gap (builders.gap_factors)


def bridge_sd(dense: DenseIncrements, t: FloatArray, k: np.ndarray
              ) -> tuple[FloatArray, FloatArray]:
    """σ of the straight-line interpolant inside an interval holding an IMU logging gap, at
    times ``t`` (M,) in intervals ``k``: an unknown acceleration A ~ N(0, a²) over the interval
    moves p(t) off the line by ½A·τ(T − τ) and v(t) by A·(τ − T/2) (a = ``GAP_ACCEL_LEVEL``).
    Zero outside gap intervals. Returns (position σ (M,) [m], velocity σ (M,) [m/s]); they
    depend on the times only, so the rows stay linear in the state."""
    z = np.zeros(t.size)
    if dense.gap is None or not dense.gap[k].any():
        return z, z
    t_kf = dense.t_kf
    big_t = t_kf[k + 1] - t_kf[k]
    tau = np.clip(t - t_kf[k], 0.0, big_t)
    g = dense.gap[k]
    return (np.where(g, 0.5 * GAP_ACCEL_LEVEL * tau * (big_t - tau), 0.0),
            np.where(g, GAP_ACCEL_LEVEL * np.abs(tau - 0.5 * big_t), 0.0))


def _pos_jacobian(st: KeyframeStates, k: np.ndarray, ip: dict[str, FloatArray],
                  h_att: FloatArray | None) -> FloatArray:
    """∂(p(t) + R(t)·l)/∂(X_k, X_{k+1}) in Pose3 tangent coordinates, (M, 3, 12); ``h_att``:
    the shared model's ∂(R(t) l)/∂ψ (M, 3, 3), None without a lever arm."""
    m = k.size
    rk = st.rot[k]
    alpha = ip["alpha"][:, None, None]
    jac = np.zeros((m, 3, 12))
    # R_k Exp(ω) x ≈ R_k x − R_k [x×] ω
    jac[:, :, 0:3] = -rk @ skew(ip["d"])
    if h_att is not None:
        # R(t)·l = R_k ΔR(τ) l rotates with R_k: ψ = R_k ω
        jac[:, :, 0:3] += body_tilt(h_att, rk)
    jac[:, :, 3:6] = (1 - alpha) * rk
    jac[:, :, 9:12] = alpha * st.rot[k + 1]
    return jac


def baro_rows(
    dense: DenseIncrements, st: KeyframeStates, t_s: FloatArray, z: FloatArray, sd: float,
    h0: float, origin_lla: FloatArray, bias_lag: float, out: FloatArray | None = None,
) -> IntervalRows:
    """Whitened baro rows for samples at ``t_s`` (M,) with altitudes ``z`` (M,) [m].
    ``out``: an (M, N_COLS) array to hold the Jacobian (overwritten; the caller's share of
    one array for all rows, ``problem.interval_rows``), else a new one.

    The sample is assigned to the interval k containing its delayed time t_d = t_s − τd (τd
    of the linearisation point), where the height h(t_d) is interpolated.

    The bias is read at t_b = t_s − ``bias_lag``, a time that does NOT move with τd:
    b = (1−α_b)·b_k + α_b·b_{k+1}, α_b = clip((t_b − t_k)/T, 0, 1). ``bias_lag`` should be
    the latency of the linearisation point, fixed for one Gauss-Newton solve. Reading b at
    the moving t_d instead adds −(b_{k+1} − b_k)/T to ∂/∂τd, a
    slope that jumps at every keyframe (the estimated Gauss-Markov chain has ≈ σ_b·√(2T/τ_b)
    steps), so the cost is kinked along τd and Gauss-Newton crawls along the τd–bias valley
    (measured: 11 instead of 4 iterations on a 1-hour drive). The shared model reads b at
    t_s; the chain estimated with a lag is that b shifted by ``bias_lag`` (< 1 cm for τ_b ≥
    minutes)."""
    t_kf = dense.t_kf
    k_s = interval_of(t_kf, t_s)
    lat_s = st.latency[k_s]
    t_d = np.clip(t_s - lat_s, t_kf[0], t_kf[-1])
    k = interval_of(t_kf, t_d)
    ip = interpolate(dense, st, t_d, k, with_rot=False)
    h, up = height_and_up(ip["p"], origin_lla)
    v_up = np.einsum("ni,ni->n", up, ip["v"])
    alpha = np.clip((t_s - bias_lag - t_kf[k]) / ip["T"], 0.0, 1.0)
    s = st.scale[k_s]
    b = (1 - alpha) * st.baro_bias[k] + alpha * st.baro_bias[k + 1]
    # the prediction and ∂/∂(h, v_up, s, τd, b) at zero residual delay
    pred, jb = baro_arrays(h, v_up, s, 0.0, b, h0)
    dh_dtau = -v_up  # h(t_s − τd): ∂h/∂τd = −v_up(t_s − τd)
    if out is None:
        jac = np.zeros((t_s.size, N_COLS))
    else:
        jac = out
        jac[...] = 0.0
    # upᵀ·_pos_jacobian without the (M, 3, 12) intermediate: with u = R_kᵀ·up,
    # upᵀ(−R_k[d×])ω = (d × u)·ω; translations (1−α)·u and α·R_{k+1}ᵀ·up
    u_k = np.einsum("nji,nj->ni", st.rot[k], up)
    a_h = ip["alpha"][:, None]
    dh = jb[:, 0:1]
    jac[:, 0:3] = dh * np.cross(ip["d"], u_k)
    jac[:, 3:6] = dh * (1 - a_h) * u_k
    jac[:, 9:12] = dh * a_h * np.einsum("nji,nj->ni", st.rot[k + 1], up)
    jac[:, COL_B0] = (1 - alpha) * jb[:, 4]
    jac[:, COL_B1] = alpha * jb[:, 4]
    jac[:, COL_S] = jb[:, 2]
    jac[:, COL_TAU] = jb[:, 0] * dh_dtau  # b is read at t_s − bias_lag: no τd dependence
    jac[:, COL_BA] = (jb[:, 0] * 0.5 * ip["tau"] * (ip["T"] - ip["tau"])
                      * ip["imu"])[:, None] * u_k
    # inside an IMU-gap interval the line's own σ, at t_s (not t_d: no τd dependence)
    sd_r = np.sqrt(sd**2 + bridge_sd(dense, np.clip(t_s, t_kf[0], t_kf[-1]), k)[0] ** 2)
    jac /= sd_r[:, None]
    return IntervalRows(k, (pred - z) / sd_r, jac)


def gnss_rows(
    dense: DenseIncrements, st: KeyframeStates, t_g: FloatArray, pos_t: FloatArray,
    pos_sd: FloatArray, vel_t: FloatArray | None, vel_sd: FloatArray | None,
    lever_b: FloatArray, incr: tuple[FloatArray, FloatArray, FloatArray] | None = None,
    out: FloatArray | None = None, k: np.ndarray | None = None,
    omega_b: FloatArray | None = None,
) -> IntervalRows:
    """Whitened GNSS position (and velocity) rows for fixes at ``t_g`` (M,) strictly inside
    intervals: antenna p(t) + R(t)·l against ``pos_t`` (M, 3) in t [m]; velocity
    v(t) + R(t)(ω × l) against ``vel_t`` (M, 3) [m/s], ω = ``omega_b`` (M, 3) the body rate at
    the fixes [rad/s] (None: the lever-arm rotation term is left out; the gyro-bias column of
    that term, |l|·δb_g, is not modelled). ``incr``: the
    increments ``dense.at`` at the fixes (cached by the caller; they do not change);
    ``out``: an (n_rows, n_cols) array to hold the Jacobian (overwritten), else a new one
    (n_cols: ``n_cols_of`` the GNSS error state's dimension); ``k``: the interval
    of each fix (default: the one holding it; a fix on keyframe k+1 can be given interval k,
    where the interpolant at τ = T is exactly that keyframe).
    The Jacobian is written in place (position rows, then velocity rows): building the
    pieces and stacking them held three copies of it (~100 MB on a 1-hour drive)."""
    t_kf = dense.t_kf
    k = interval_of(t_kf, t_g) if k is None else np.asarray(k, dtype=np.intp)
    lever = None if not np.any(lever_b) else np.asarray(lever_b, float)
    ip = interpolate(dense, st, t_g, k, incr, with_rot=lever is not None)
    m = t_g.size
    bp, bv = bridge_sd(dense, t_g, k)
    if bp.any():  # inside an IMU-gap interval: the straight line's own σ (bridge_sd)
        pos_sd = np.sqrt(pos_sd**2 + bp[:, None] ** 2)
        if vel_sd is not None:
            vel_sd = np.sqrt(vel_sd**2 + bv[:, None] ** 2)
    with_vel = vel_t is not None and vel_sd is not None
    h_att = u = hv_att = None
    if lever is None:
        p_ant = ip["p"].copy()
    else:  # the shared model: antenna = p + C l and, with velocities, v + C (ω × l)
        w_b = omega_b if with_vel and omega_b is not None else np.empty((0, 3))
        d_l, h_att, u, hv_att = antenna_arrays(ip["rot"], lever, w_b)
        p_ant = ip["p"] + d_l
    n_blk = 2 if with_vel else 1
    gm_dim = gm_dim_of(st)
    n_cols = n_cols_of(gm_dim)
    if out is None:
        out = np.zeros((n_blk * 3 * m, n_cols))
    else:
        out[...] = 0.0
    jac_all = out.reshape(n_blk * m, 3, n_cols)  # a view: fix-major rows of each block
    jac = jac_all[:m]
    jac[:, :, 0:12] = _pos_jacobian(st, k, ip, h_att)
    jac[:, :, 0:12] /= pos_sd[:, :, None]
    if gm_dim:  # GNSS error e(t) on its axes, linear between the keyframes
        a_g = ip["alpha"]
        g = st.gnss_gm.reshape(st.gnss_gm.shape[0], gm_dim)
        c0, c1 = gm_cols(gm_dim)
        for j, ax in enumerate(GM_AXES[gm_dim]):
            p_ant[:, ax] += (1 - a_g) * g[k, j] + a_g * g[k + 1, j]
            jac[:, ax, c0.start + j] = (1 - a_g) / pos_sd[:, ax]
            jac[:, ax, c1.start + j] = a_g / pos_sd[:, ax]
    rows_r = [((p_ant - pos_t) / pos_sd).reshape(-1)]
    rk_all = st.rot[k]
    jac[:, :, COL_BA] = (0.5 * ip["tau"] * (ip["T"] - ip["tau"]) * ip["imu"])[:, None, None] \
        * rk_all \
        / pos_sd[:, :, None]
    ks = [np.repeat(k, 3)]
    if with_vel:
        assert vel_t is not None and vel_sd is not None
        big_t = ip["T"][:, None, None]
        rk = st.rot[k]
        jv = jac_all[m:]
        jv[:, :, 0:3] = -rk @ skew(ip["dvel"])
        jv[:, :, 3:6] = -rk / big_t
        jv[:, :, 9:12] = st.rot[k + 1] / big_t
        jv[:, :, COL_BA] = ((0.5 * ip["T"] - ip["tau"]) * ip["imu"])[:, None, None] * rk
        v_ant = ip["v"]
        if lever is not None and omega_b is not None:  # the shared model: + C (ω × l)
            v_ant = v_ant + u
            jv[:, :, 0:3] += body_tilt(hv_att, rk)
        jv /= vel_sd[:, :, None]
        rows_r.append(((v_ant - vel_t) / vel_sd).reshape(-1))
        ks.append(np.repeat(k, 3))
    return IntervalRows(np.concatenate(ks), np.concatenate(rows_r), out)


GROUP_CHUNK = 256  # keyframe intervals per padded block of ``group_information``


def group_information(rows: IntervalRows) -> tuple[np.ndarray, FloatArray, FloatArray,
                                                   FloatArray]:
    """Per-interval information of the rows: Λ_k = Σ JᵀJ (G, 16, 16), η_k = −Σ Jᵀr (G, 16)
    for the groups that have rows, and the cost ½Σr² (float). Returns (groups, Λ, η, cost).
    The groups are padded and multiplied in chunks of ``GROUP_CHUNK`` (the same products;
    padding all at once held two extra copies of every row: ~120 MB on a 1-hour drive)."""
    k_all = rows.k
    order = None if np.all(k_all[1:] >= k_all[:-1]) else np.argsort(k_all, kind="stable")
    k = k_all if order is None else k_all[order]
    groups, start, count = np.unique(k, return_index=True, return_counts=True)
    n_cols = rows.jac.shape[1]
    lam = np.empty((groups.size, n_cols, n_cols))
    eta = np.empty((groups.size, n_cols))
    for g0 in range(0, groups.size, GROUP_CHUNK):
        g1 = min(g0 + GROUP_CHUNK, groups.size)
        a, b = int(start[g0]), int(start[g1 - 1] + count[g1 - 1])
        sel = slice(a, b) if order is None else order[a:b]
        jac, r = rows.jac[sel], rows.r[sel]
        cnt = count[g0:g1]
        pos = np.arange(b - a) - np.repeat(start[g0:g1] - a, cnt)
        gi = np.repeat(np.arange(g1 - g0), cnt)
        pad_j = np.zeros((g1 - g0, int(cnt.max()), n_cols))
        pad_r = np.zeros((g1 - g0, int(cnt.max())))
        pad_j[gi, pos] = jac
        pad_r[gi, pos] = r
        pad_t = np.swapaxes(pad_j, 1, 2)
        lam[g0:g1] = pad_t @ pad_j  # batched BLAS (einsum without optimize is ~10× slower)
        eta[g0:g1] = -(pad_t @ pad_r[:, :, None])[:, :, 0]
    return groups, lam, eta, 0.5 * float(rows.r @ rows.r)


def keyframe_indices(t: FloatArray, dt_kf: float) -> np.ndarray:
    """IMU sample indices of keyframes every ``dt_kf`` seconds (snapped to IMU samples; the
    last sample is always a keyframe; a trailing interval shorter than dt_kf/2 is merged)."""
    targets = np.arange(t[0], t[-1] + 1e-9, dt_kf)
    idx = np.unique(np.clip(np.searchsorted(t, targets - 1e-9), 0, t.size - 1))
    if idx[-1] != t.size - 1:
        if t[-1] - t[idx[-1]] < 0.5 * dt_kf and idx.size > 1:
            idx[-1] = t.size - 1
        else:
            idx = np.append(idx, t.size - 1)
    return idx


def to_tangent(lla: FloatArray, origin_lla: FloatArray) -> FloatArray:
    return lla_to_ned(lla, origin_lla)
