"""The estimate of a solved graph, shared by ``graph-batch`` and ``graph-isam2``: the
trajectory at the output rate (keyframe states interpolated with the dense IMU increments),
the 18-state covariance at keyframes from the selected inverse of the final normal equations,
the baro calibration with its prior and posterior σ, the user variables, and the notes of
what the solve fell back to.

Units: SI; geodetic lla [rad, rad, m]; velocities local-level NED.
"""

from __future__ import annotations

from typing import Any

import gtsam
import numpy as np
from gtsam.symbol_shorthand import A, B, C, K, V, X

from ....geo.frames import mat_to_quat, ned_to_lla
from ....nav.error_state import component, embed_error_state
from ....sensors.noise import gm_mean_prior_sd
from ....types import ERROR_STATE, ERROR_STATE_DIM, BaroEstimate, Drive, ParamEstimate, Trajectory
from ....types.streams import FloatArray
from ..model import interval_factors as gf
from ..model.problem import Problem, interval_rows, states_from_values
from ..settings import GraphConfig
from .layout import interval_info
from .solve import BatchResult, linear_system


def fallback_notes(res: BatchResult, cfg: GraphConfig, cov_damping: float) -> list[str]:
    """What the solve fell back to (``info["fallbacks"]``, also warnings): Marquardt damping
    added to a numerically singular system, a covariance taken from a damped factorisation
    (its σ are too small), the general sparse solver where the banded one was the default."""
    notes = []
    if res.singular_damping > 0:
        notes.append(f"the Gauss-Newton system was numerically singular: Marquardt damping "
                     f"up to {res.singular_damping:.0e}·diag(H) added (a direction the data "
                     "do not determine)")
    if cov_damping > 0:
        notes.append(f"the covariance comes from a system damped by {cov_damping:.0e}·diag(H): "
                     "its sigmas understate the uncertainty")
    if res.solver == "general" and cfg.solver == "auto":
        notes.append("general sparse solver: the graph does not fit the keyframe band (slower "
                     "than the banded path; docs/extending.md)")
    return notes


def solver_warnings(res: BatchResult, cfg: GraphConfig, what: str = "Gauss-Newton",
                     estimator: str = "graph-batch") -> list[str]:
    """User-facing warning for a solve that did not converge (``info["warnings"]``)."""
    if res.stop == "max_iterations":
        return [f"{what} stopped at max_iterations={cfg.max_iterations} per solve without "
                f"converging (final ½χ² {res.cost:.6g}; at its last linearisation the model "
                f"still predicted {res.predicted_decrease:.3g} less); the estimate may be off "
                "— raise it: "
                f"--config FILE.toml with [{estimator}] max_iterations = "
                f"{max(2 * cfg.max_iterations, 100)} (Python: GraphConfig(max_iterations=...))"]
    if res.stop == "no_descent":
        return [f"{what} found no step that lowers the cost (Levenberg-Marquardt damping up "
                f"to 1e3, final ½χ² {res.cost:.6g}, the model predicting "
                f"{res.predicted_decrease:.3g} less): a flat or strongly nonlinear direction "
                "(e.g. heading without motion); the estimate is a stationary point of "
                "uncertain quality"]
    return []


def output_times(P: Problem) -> FloatArray:
    t = P.drive.imu.t
    n = max(int(round(P.cfg.output_rate_hz and (1.0 / P.cfg.output_rate_hz) / np.median(
        np.diff(t)))), 1)
    idx = np.unique(np.r_[np.arange(0, t.size, n), P.kf_idx])
    idx = idx[(idx >= P.kf_idx[0]) & (idx <= P.kf_idx[-1])]
    return t[idx]


def trajectory(P: Problem, st: gf.KeyframeStates, vals: Any, t_q: FloatArray) -> Trajectory:
    k = gf.interval_of(P.t_kf, t_q)
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
    # the bias of the interval containing t_q; at the last keyframe epoch the last keyframe's
    # own B (the bias link's Gauss-Markov step has decayed it from the last interval's)
    kb = np.where(t_q >= P.t_kf[-1], nk - 1, k)
    bg = bias[kb, 3:6]
    ba = bias[kb, 0:3]
    if P.ka is not None:  # B holds the effective bias b_a + diag(ā_k)·k_a: report b_a
        ba = P.ka.true_bias(ba, vals.atVector(A(0)), kb)
    bb = (1 - alpha) * st.baro_bias[k] + alpha * st.baro_bias[k + 1]
    return Trajectory(t_q, lla, vel_n, q, bg, ba, bb if P.drive.baro is not None else None)


def cov_18(P: Problem, cov_of: Any, vals: Any, k: int, kb: int | None = None,
           seg: int = 0) -> FloatArray:
    """18×18 ERROR_STATE covariance at keyframe k from the selected inverse of the final
    normal equations (joint marginal of X_k, V_k, B_k, C_k and the global (s, τd);
    ``cov_of``: ``layout.BandedCovariance``, ``general.GeneralCovariance`` or anything with
    ``joint(keys)``, e.g. graph-isam2's marginals ``isam2.answers.IsamMarginals``).
    ``kb``: the bias variable B(kb) (default k; graph-isam2's newest keyframe k + 1 has B(k)
    until the next update); ``seg``: the (s, τd) K(seg) and k_a A(seg) (graph-isam2's
    segment; the batch's one global variable is 0).

    Pose3 tangent (ω_b, v_b): att_t = R ω_b, δp_t = R v_b; then t → local NED with C_nt.
    ConstantBias (accel, gyro) → bias_gyro 9:12, bias_accel 12:15 (body frame); with the
    accelerometer scale factors, b_a = B_a(k) − diag(ā_k)·k_a (A(0) joins the marginal)."""
    kb = k if kb is None else kb
    keys = [X(k), V(k), B(kb)] + ([C(k), K(seg)] if P.drive.baro is not None else [])
    if P.ka is not None:
        keys.append(A(seg))
    full = cov_of.joint(keys)
    n = full.shape[0]
    r = vals.atPose3(X(k)).rotation().matrix()
    lla = ned_to_lla(vals.atPose3(X(k)).translation()[None, :], P.origin)
    c_nt = gf.rot_t_n(lla, P.origin)[0].T
    es = ERROR_STATE
    tmat = np.zeros((ERROR_STATE_DIM, n))
    tmat[es["att_n"], 0:3] = c_nt @ r
    tmat[es["pos_n"], 3:6] = c_nt @ r
    tmat[es["vel_n"], 6:9] = c_nt
    tmat[es["bias_accel"], 9:12] = np.eye(3)
    tmat[es["bias_gyro"], 12:15] = np.eye(3)
    if P.ka is not None:
        tmat[es["bias_accel"], n - 3:n] = -np.diag(P.ka.f_mean[kb])
    if P.drive.baro is not None:  # C(k), then K(0) = (s, τd); without a baro: NaN rows
        tmat[component("baro_bias"), 15] = 1.0
        tmat[component("baro_scale"), 16] = 1.0
        tmat[component("baro_latency"), 17] = 1.0
    return embed_error_state(full, tmat)


def value_of(vals: Any, key: int) -> list[float] | None:
    """A variable's value as a flat list (vector, scalar, Pose3 as its 4×4 matrix, Rot3 as
    its 3×3 matrix), None for other types."""
    for get in ("atVector", "atDouble", "atPose3", "atRot3"):
        try:
            v = getattr(vals, get)(key)
        except RuntimeError:
            continue
        if hasattr(v, "matrix"):
            v = v.matrix()
        return np.atleast_1d(np.asarray(v, float)).ravel().tolist()
    return None


def extra_variables(lay: Any, cov_of: Any, vals: Any) -> dict[str, dict[str, Any]]:
    """Variables outside the keyframe template and K(0) (added by a user): value, σ of each
    tangent component and their covariance, keyed by GTSAM's key name (e.g. "m0")."""
    out = {}
    for key in lay.extra_keys:
        cov = cov_of.joint([key])
        out[gtsam.DefaultKeyFormatter(key)] = {
            "est": value_of(vals, key), "sd": np.sqrt(np.clip(np.diag(cov), 0, None)).tolist(),
            "cov": cov.tolist()}
    return out


def outputs(P: Problem, res: BatchResult, pri: dict[str, float],
             calib_key: int | None) -> dict[str, Any]:
    vals = res.values
    lay = res.layout
    st = states_from_values(P, vals, res.calib_of_kf)
    traj = trajectory(P, st, vals, output_times(P))
    # covariance of the final linear system: banded factorisation + selected inversion, or
    # GTSAM's marginals of the eliminated graph (general path)
    system = res.system
    if system is None:
        # the rows' Jacobian (~44 MB on a 1-hour drive) is needed only for their information
        # blocks: not kept alive under the system and the covariance (graph-isam2's own
        # estimate reaches here with it)
        rows = res.rows
        if rows.jac.shape[0] != rows.r.size:
            # released with the system (graph-isam2's check pass, when it is chosen after
            # iSAM2's own estimate was evaluated): linearised again at the solution
            rows = interval_rows(P, st, pri, res.bias_lag)
        info = interval_info(lay, rows)
        res.rows = rows.without_jac()
        del rows
        system = linear_system(P, lay, res.graph, vals, info)
        del info
    cov_of = system.covariance()
    cov_damping = system.damping
    nk = P.n_kf
    sel = np.unique(np.linspace(0, nk - 1, min(P.cfg.cov_epochs, nk)).astype(int))
    cov = np.array([cov_18(P, cov_of, vals, int(k)) for k in sel])
    out: dict[str, Any] = {"trajectory": traj, "cov": cov, "t_cov": P.t_kf[sel],
                           "cov_damping": cov_damping,
                           "extra": extra_variables(lay, cov_of, vals),
                           "accel_scale": accel_scale_info(P, vals, cov_of)}
    if P.drive.baro is None or calib_key is None:
        out["baro"] = None
        out["observability"] = {}
        return out
    kc = vals.atVector(calib_key)
    pk = cov_of.joint([calib_key])
    # sigma of the time-averaged bias b̄ = (1/K) Σ b_k: uᵀ H⁻¹ u with u = 1/K on every C(k)
    u = {C(k): np.full(1, 1.0 / nk) for k in range(nk)}
    b_mean = float(np.mean(st.baro_bias))
    hu = cov_of.solve(u, [C(k) for k in range(nk)] + [calib_key])
    b_var = max(float(sum(float(u[key][0] * hu[key][0]) for key in u)), 0.0)
    b_sd = float(np.sqrt(b_var))
    # b is referenced to h0 (docs/design.md): at a height Δh above h0 an error δs moves it by
    # −δs·Δh, so a flight far above h0 ties b̄ to s (sortie: corr −0.995)
    cov_sb = float(hu[calib_key][0])
    corr_sb = cov_sb / np.sqrt(b_var * pk[0, 0]) if b_var > 0 and pk[0, 0] > 0 else 0.0
    b_sd_given_s = float(np.sqrt(max(b_var - cov_sb**2 / pk[0, 0], 0.0))) if pk[0, 0] > 0 \
        else b_sd
    dur = float(P.t_kf[-1] - P.t_kf[0])
    b_prior = gm_mean_prior_sd(pri["b_sd"], pri["b_tau"], dur)
    baro = BaroEstimate(
        scale=ParamEstimate(float(kc[0]), float(np.sqrt(pk[0, 0])), pri["s_sd"], 0.0),
        latency_s=ParamEstimate(float(kc[1]), float(np.sqrt(pk[1, 1])), pri["tau_sd"],
                                pri["tau0"]),
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


def accel_scale_info(P: Problem, vals: Any, cov_of: Any) -> dict[str, Any]:
    """``info["accel_scale_estimated"]``, and with it ``accel_scale`` / ``accel_scale_sd``
    (k_a, 3 components [-]), the EKF's keys."""
    if P.ka is None:
        return {"accel_scale_estimated": False}
    return {"accel_scale_estimated": True, "accel_scale": vals.atVector(A(0)).tolist(),
            "accel_scale_sd": np.sqrt(np.clip(np.diag(cov_of.joint([A(0)])), 0, None)).tolist()}


def gnss_gm_info(P: Problem) -> dict[str, Any]:
    """``info["gnss_gm"]`` (and ``gnss_height_gm``: ``GnssGM.info``, as the EKF reports it)
    when the solve carried the GNSS error state, else nothing."""
    if P.gm is None:
        return {}
    return P.gm.info()


def provides(drive: Drive) -> frozenset[str]:
    q = {"alt", "vel_d", "pos_h", "vel_h", "att", "cov"}
    if drive.baro is not None:
        q.add("baro")
    return frozenset(q)
