"""graph-isam2's causal answers, recorded during the online pass (``online.OnlinePass``):
the newest keyframe's state and covariance after each update (``Estimate.online``,
``Estimate.online_cov``) and the
fixed-lag estimate (``Estimate.lag``, ``Estimate.lag_cov``): after the update at t, the
latest keyframe at or before t − L (L = ``GraphConfig.isam2_lag_s``) and its covariance.

Both covariances are iSAM2's marginals (``ISAM2.jointMarginalCovariance`` of the keyframe's
X, V, B, C and its segment's K, A) put into the ERROR_STATE layout by the batch outputs'
``cov_18``. The newest keyframe k + 1 has no bias variable of its own until the next update
(B(k + 1) enters with interval k + 1): its bias block is B(k)'s, the bias over the interval
that ends at it.
"""

from __future__ import annotations

import time
from typing import Any

import gtsam
import numpy as np
from gtsam.symbol_shorthand import B, C, V, X

from ....geo.frames import mat_to_quat, ned_to_lla, quat_to_mat
from ....types import ERROR_STATE_DIM, Trajectory
from ....types.streams import FloatArray
from ..model import interval_factors as gf
from ..model.problem import Problem
from ..solver.outputs import cov_18


class IsamMarginals:
    """``joint(keys)`` of iSAM2's current Bayes tree (the interface ``cov_18`` reads)."""

    def __init__(self, isam: Any) -> None:
        self.isam = isam

    def joint(self, keys: list[int]) -> FloatArray:
        # its full matrix is in the order of ``keys`` (checked against the blocks ``at``)
        return np.asarray(self.isam.jointMarginalCovariance(keys).fullMatrix())


class Answers:
    """The online states and covariances and the fixed-lag records of one pass over ``P``.

    online: (n_kf, 10) p, v (t frame), quaternion (filled from ``online_rot`` after the
    pass); online_bias: (n_kf, 6) the biases (accel, gyro) known at each keyframe's update,
    with which the real-time output propagates the IMU between keyframes (``real_time``);
    online_cov: (n_kf, 18, 18), NaN where not computed; lag_kf: keyframe of each lag record;
    lag_t: the update time it was read at; lag_state: (n, 10) p, v (t frame), quaternion;
    lag_cov: (n, 18, 18)."""

    def __init__(self, P: Problem, seg: np.ndarray, lag_s: float) -> None:
        self.P, self.seg, self.lag_s = P, seg, lag_s
        nk = P.n_kf
        self.online = np.zeros((nk, 10))
        self.online_rot = np.zeros((nk, 3, 3))
        self.online_bias = np.zeros((nk, 6))
        self.online_cov = np.full((nk, ERROR_STATE_DIM, ERROR_STATE_DIM), np.nan)
        self.lag_kf: list[int] = []
        self.lag_t: list[float] = []
        self.lag_state: list[FloatArray] = []
        self.lag_rot: list[FloatArray] = []
        self.lag_cov: list[FloatArray] = []
        self.seconds = 0.0  # time spent here [s]

    def cov(self, isam: Any, vals: Any, k: int, kb: int) -> FloatArray:
        return cov_18(self.P, IsamMarginals(isam), vals, k, kb, int(self.seg[k]))

    def record(self, k: int, arrays: tuple[Any, ...]) -> None:
        """Keyframe k's online state: its estimate in the running arrays (rot, pos, vel,
        bias, ...) right after its update."""
        rot, pos, vel, bias = arrays[0:4]
        self.online[k, 0:6] = np.r_[pos[k], vel[k]]
        self.online_rot[k] = rot[k]
        self.online_bias[k] = bias[k]

    def after_update(self, isam: Any, k: int, arrays: tuple[Any, ...]) -> None:
        """After the update that created keyframe k + 1 (``arrays``: the states read back):
        its state and covariance, and the lag record due at t_{k+1}."""
        self.record(k + 1, arrays)
        t0 = time.perf_counter()
        self._after_update(isam, k, gtsam.Pose3(gtsam.Rot3(arrays[0][k + 1]), arrays[1][k + 1]))
        self.seconds += time.perf_counter() - t0

    def _after_update(self, isam: Any, k: int, pose_new: Any) -> None:
        P = self.P
        vals = gtsam.Values()
        vals.insert(X(k + 1), pose_new)
        self.online_cov[k + 1] = self.cov(isam, vals, k + 1, k)
        t = float(P.t_kf[k + 1])
        j = int(np.searchsorted(P.t_kf, t - self.lag_s, side="right")) - 1
        if j < 0 or (self.lag_kf and j <= self.lag_kf[-1]) or j > k:
            return  # before the lag's first keyframe, or already recorded
        keys = [X(j), V(j), B(j)] + ([C(j)] if P.drive.baro is not None else [])
        est = isam.calculateEstimate(gtsam.KeyVector(keys))
        pose = est.atPose3(X(j))
        self.lag_kf.append(j)
        self.lag_t.append(t)
        self.lag_state.append(np.r_[pose.translation(), est.atVector(V(j))])
        self.lag_rot.append(pose.rotation().matrix())
        self.lag_cov.append(self.cov(isam, est, j, j))

    def keep(self, other: Answers, n: int) -> None:
        """Keyframes 0 … n − 1 and the lag records of the updates that created them from
        ``other`` (the causal start's pass, ``causal.causal_pass``)."""
        for name in ("online", "online_rot", "online_bias", "online_cov"):
            getattr(self, name)[:n] = getattr(other, name)[:n]
        t_n = float(self.P.t_kf[n]) if n < self.P.n_kf else np.inf
        a = sum(1 for t in other.lag_t if t < t_n)
        b = sum(1 for t in self.lag_t if t < t_n)
        for name in ("lag_kf", "lag_t", "lag_state", "lag_rot", "lag_cov"):
            setattr(self, name, getattr(other, name)[:a] + getattr(self, name)[b:])

    def lag_answer(self) -> tuple[Trajectory | None, Any, dict[str, Any]]:
        """``Estimate.lag`` and ``lag_cov`` from the records, and their info."""
        info = {"lag_s": float(self.lag_s), "lag_epochs": len(self.lag_kf),
                "isam2_marginals_s": self.seconds,
                "online_cov_epochs": int(np.sum(np.isfinite(self.online_cov[:, 0, 0])))}
        if not self.lag_kf:
            return None, None, info
        arr = np.column_stack([np.asarray(self.lag_state), mat_to_quat(np.asarray(self.lag_rot))])
        tr = online_trajectory(self.P, arr, self.P.t_kf[np.asarray(self.lag_kf)])
        # the lag actually realised: update time minus the keyframe's [s]
        info["lag_realised_max_s"] = float(np.max(np.asarray(self.lag_t) - tr.t))
        return tr, np.asarray(self.lag_cov), info


def online_trajectory(P: Problem, online: FloatArray, t: FloatArray | None = None) -> Trajectory:
    """(n, 10) p, v (t frame), quaternion at ``t`` (default: the keyframes) as a trajectory."""
    lla = ned_to_lla(online[:, 0:3], P.origin)
    c_tn = gf.rot_t_n(lla, P.origin)
    vel_n = np.einsum("nji,nj->ni", c_tn, online[:, 3:6])
    q = mat_to_quat(np.swapaxes(c_tn, 1, 2) @ quat_to_mat(online[:, 6:10]))
    return Trajectory(P.t_kf if t is None else t, lla, vel_n, q)


def real_time(P: Problem, online: FloatArray, rot: FloatArray, bias: FloatArray,
              online_cov: FloatArray, t_out: FloatArray
              ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """graph-isam2's real-time output at the output epochs ``t_out``: at a keyframe its
    online state, between keyframes k and k + 1 the online state of k propagated with the IMU
    samples since (the data up to that epoch: the state of k + 1 comes with the next update),

        p(τ) = p_k + v_k τ + ½ a τ² + R_k (Δp(τ) − ½ b_a τ²),
        v(τ) = v_k + a τ + R_k (Δv(τ) − b_a τ),   R(τ) = R_k ΔR(τ) Exp(−b_g τ),

    with a = g_t(p_k) − 2 Ω×v_k, ΔR, Δv, Δp the keyframe interval's dense increments
    (``DenseIncrements.at``, trapezoidal from keyframe k) and b_a, b_g the biases known at
    k's update (first order in the bias over one interval). Inside an interval that holds an
    IMU logging gap nothing is propagated: only its keyframe epochs are output.

    ``online`` (n_kf, 10) p, v (t frame), quaternion; ``rot`` (n_kf, 3, 3) its attitude;
    ``bias`` (n_kf, 6) accel, gyro; ``online_cov`` (n_kf, 18, 18). Returns the epochs, the
    (M, 10) states in ``online``'s layout, the (M, 3, 3) attitudes and the covariances (the
    keyframes', NaN between them: the propagation's own covariance is not computed)."""
    from ....nav.rotations import so3_exp

    t_kf = P.t_kf
    t_q = np.unique(np.r_[t_out[(t_out >= t_kf[0]) & (t_out <= t_kf[-1])], t_kf])
    k = np.clip(np.searchsorted(t_kf, t_q, side="right") - 1, 0, t_kf.size - 1)
    on_kf = np.abs(t_q - t_kf[k]) < 1e-9
    gap = P.gap if P.gap.size else np.zeros(max(t_kf.size - 1, 0), dtype=bool)
    keep = on_kf | ~gap[np.minimum(k, gap.size - 1)] if gap.size else on_kf | True
    t_q, k, on_kf = t_q[keep], k[keep], on_kf[keep]
    out = online[k].copy()
    r_out = rot[k].copy()
    cov = np.full((t_q.size, ERROR_STATE_DIM, ERROR_STATE_DIM), np.nan)
    cov[on_kf] = online_cov[k[on_kf]]
    mid = np.flatnonzero(~on_kf)
    if mid.size:
        km = k[mid]
        tau = (t_q[mid] - t_kf[km])[:, None]
        dr, dv, dp = P.dense.at(t_q[mid], km)
        p_k, v_k, r_k = online[km, 0:3], online[km, 3:6], rot[km]
        b_a, b_g = bias[km, 0:3], bias[km, 3:6]
        a = gf.gravity_t(p_k, P.origin) - 2.0 * np.cross(P.omega_t, v_k)
        out[mid, 0:3] = (p_k + v_k * tau + 0.5 * a * tau**2
                         + np.einsum("nij,nj->ni", r_k, dp - 0.5 * b_a * tau**2))
        out[mid, 3:6] = v_k + a * tau + np.einsum("nij,nj->ni", r_k, dv - b_a * tau)
        corr = np.array([so3_exp(-bg * tt) for bg, tt in zip(b_g, tau[:, 0], strict=True)])
        r_out[mid] = r_k @ dr @ corr
    return t_q, out, r_out, cov
