"""Set-up pieces of ``graph-isam2`` (``isam2``): its iSAM2 parameters and relinearisation
thresholds, the baro-calibration segments, the GNSS fixes of each interval, keyframe 0's
factors, the error raised by a failed update (``UpdateFailed``) and the ``Estimate.info``
it reports."""

from __future__ import annotations

from typing import Any

import gtsam
import numpy as np
from gtsam.symbol_shorthand import A, B, C, G, K, V, X

from ....util.failures import failure_message
from ..model import interval_factors as gf
from ..model.cpp_factors import keyframe_fixes, prior_factors
from ..model.extend import Collected, key_name
from ..model.problem import Problem
from ..settings import GraphConfig
from ..solver.outputs import solver_warnings, value_of
from .py_factors import LINEAR_ONLY


class UpdateFailed(RuntimeError):
    """An iSAM2 update failed or diverged: ``GraphISAM2.run`` retries the pass once with its
    robust settings on this type (and on no other error)."""


def update_error(P: Problem, k: int, exc: BaseException | None, gap: bool) -> UpdateFailed:
    """An ``UpdateFailed`` naming the keyframe, its time and the likely cause.

    GTSAM's IndeterminantLinearSystemException reaches Python with an empty or generic
    message; this replaces it (and a diverged, non-finite estimate) with one that says where.
    """
    t0, t1 = float(P.t_kf[k]), float(P.t_kf[k + 1])
    imu_t = P.drive.imu.t
    j0, j1 = int(P.kf_idx[k]), int(P.kf_idx[k + 1])
    max_dt = float(np.max(np.diff(imu_t[j0:j1 + 1]))) if j1 > j0 else float("nan")
    n_fix = int(np.sum(P.g_use & (P.g_t >= t0 - 5.0) & (P.g_t <= t1)))
    causes = []
    if gap:
        causes.append(f"an IMU logging gap of {max_dt:.1f} s in this interval")
    if n_fix == 0:
        causes.append("no usable GNSS fix in the last 5 s (position/velocity unconstrained)")
    if P.g_vel is None:
        causes.append("GNSS without velocity (attitude/velocity weakly observable)")
    if not causes:
        causes.append("a linearisation point far from the solution (diverged prediction)")
    what = ("iSAM2 update raised " + failure_message(exc, typed=True) if exc is not None
            else "the online estimate became non-finite or diverged")
    return UpdateFailed(
        f"graph-isam2: {what} at keyframe {k + 1} (t = {t1:.2f} s, interval "
        f"[{t0:.2f}, {t1:.2f}] s, largest IMU spacing {max_dt:.3g} s); likely cause: "
        + "; ".join(causes) + ". graph-batch (damped batch solver) may still work.")


def segments(P: Problem) -> np.ndarray:
    """Calibration segment index of every keyframe, numbered densely (0, 1, 2, ...).

    Segments are ``segment_s`` long in time; one with no keyframe (a logging gap longer than
    a segment) gets no index, so consecutive keyframes differ by at most one segment and the
    random walk between K(j-1) and K(j) spans the real time between them
    (:func:`_segment_span`).
    """
    seg = P.cfg.segment_s
    if not np.isfinite(seg):
        return np.zeros(P.n_kf, dtype=int)
    raw = np.floor((P.t_kf - P.t_kf[0]) / seg + 1e-9).astype(int)
    return np.unique(raw, return_inverse=True)[1].astype(int)


def interval_fixes(P: Problem) -> list[np.ndarray]:
    """The fixes of each interval, once (fixes and keyframes are in time order): strictly
    inside it, and — with the GNSS error state — on the keyframe that ends it (the one on
    keyframe 0 goes with interval 0)."""
    g_between = np.flatnonzero((P.g_kf == -1) & P.g_use)
    cuts = np.arange(1, P.n_kf - 1)
    fixes_of = np.split(g_between, np.searchsorted(
        gf.interval_of(P.t_kf, P.g_t[g_between]), cuts))
    if P.gm is not None:
        on_kf = np.flatnonzero((P.g_kf >= 0) & P.g_use)
        ends = np.split(on_kf, np.searchsorted(np.maximum(P.g_kf[on_kf] - 1, 0), cuts))
        fixes_of = [np.r_[a, b] for a, b in zip(fixes_of, ends, strict=True)]
    return fixes_of


def segment_span(P: Problem, seg: np.ndarray, j: int) -> float:
    """Time [s] from the start of segment j-1 to the start of segment j (≥ segment_s when a
    gap swallowed whole segments): the length of the K(j-1) → K(j) random walk."""
    t0 = float(P.t_kf[np.argmax(seg == j - 1)])
    t1 = float(P.t_kf[np.argmax(seg == j)])
    return max(float(P.cfg.segment_s), t1 - t0)


def newest_last(P: Problem, seg: np.ndarray, k: int, b_last: int) -> Any:
    """iSAM2's constraint map putting keyframe k's variables (X, V, its B — B(b_last) while
    B(k) has not entered —, C, G) and its segment's K, A last in a re-elimination's
    ordering."""
    last = gtsam.KeyGroupMap()
    j = int(seg[k])
    keys = [X(k), V(k), B(min(k, b_last))]
    keys += [C(k), K(j)] if P.drive.baro is not None else []
    keys += [G(k)] if P.gm is not None else []
    keys += [A(j)] if P.ka is not None else []
    for key in keys:
        last.insert2(key, 1)
    return last


def threshold_map(cfg: GraphConfig, ext: Collected | None = None,
                  linear: set[str] | None = None) -> Any:
    """Per-variable-type relinearisation thresholds (tangent-space components); the letters
    of the extensions' variables get theirs (``Variable.relinearize_threshold``), those in
    ``linear`` none (only linear factors touch them: ``py_factors.LINEAR_ONLY``)."""
    if cfg.relinearize_typed is None:
        return cfg.relinearize_threshold
    rot, trans, vel, ba, bg = cfg.relinearize_typed
    m = gtsam.ISAM2ThresholdMap()
    m.insert(("x", np.array([rot] * 3 + [trans] * 3)))
    m.insert(("v", np.full(3, vel)))
    m.insert(("b", np.array([ba] * 3 + [bg] * 3)))
    m.insert(("c", np.full(1, 1e9)))
    m.insert(("k", np.full(2, 1e9)))
    gm = cfg.gnss_gm  # the GNSS error state G(k) (1 to 3 axes): linear factors only
    m.insert(("g", np.full(1 if gm is None else gm.dim, 1e9)))
    m.insert(("a", np.full(3, 1e9)))  # the accelerometer scale factors: linear factors only
    if ext is not None:
        for ch, thr in ext.threshold_entries(cfg.relinearize_threshold).items():
            m.insert((ch, np.full(thr.size, LINEAR_ONLY) if ch in (linear or ()) else thr))
    return m


def estimate_info(P: Problem, cfg: GraphConfig, res: Any, out: dict[str, Any], upd_ms: Any,
                  brk: Any, robust: bool, fallback: str | None, times: dict[str, float],
                  isam_k: list[float] | None, n_seg: int, name: str) -> dict[str, Any]:
    """``Estimate.info`` of graph-isam2."""
    return {
        "keyframes": P.n_kf, "iterations_final": res.iterations,
        "converged_final": res.converged, "stop_final": res.stop,
        "predicted_decrease_final": res.predicted_decrease,
        "gnss_rejected": P.gnss_rejected, "gnss_rejected_pregate": P.g_rej_pre,
        "gnss_rejected_velocity_screen": P.g_rej_vel,
        "gnss_rejected_postsolve": P.g_rej_post,
        "observability": out["observability"],
        "update_ms": upd_ms,
        "update_breakdown": brk,
        "update_p50_ms": float(np.percentile(upd_ms, 50)) if upd_ms.size else 0.0,
        "update_p99_ms": float(np.percentile(upd_ms, 99)) if upd_ms.size else 0.0,
        **times,
        "isam2_last_segment_calibration": isam_k,
        "segments": n_seg,
        "isam2_fallback": fallback,
        # keyframe 0's attitude, where the online pass starts (graph.init.initial_states)
        **P.init_info(), **P.zupt_info(), **P.sensor_info(),
        "warnings": solver_warnings(res, cfg, "final smoothing pass", name)
        + ([] if fallback is None else [
            f"iSAM2 update failed and was retried with dogleg ({fallback})"]),
        "isam2_settings": {"keyframe_dt": cfg.keyframe_dt, "dogleg": robust,
                           "relinearize_skip": cfg.relinearize_skip,
                           "relinearize_typed": cfg.relinearize_typed,
                           "relinearize_threshold": cfg.relinearize_threshold},
    }


def extra_online_of(isam: Any, est: Any, ext: Collected | None) -> dict[str, dict[str, Any]]:
    """The extensions' variables as iSAM2 holds them after the last update (value, σ and
    covariance from ``ISAM2.marginalCovariance``), by key name; {} without extensions."""
    out: dict[str, dict[str, Any]] = {}
    if ext is None:
        return out
    for key in ext.variables:
        cov = np.atleast_2d(isam.marginalCovariance(key))
        out[key_name(key)] = {"est": value_of(est, key),
                              "sd": np.sqrt(np.clip(np.diag(cov), 0, None)).tolist(),
                              "cov": cov.tolist()}
    return out


def first_keyframe(P: Problem, r0: Any, p0: Any, v0: Any, k0: Any, yaw_sd: float
                   ) -> tuple[Any, Any, list[tuple[int, int]]]:
    """Factors (priors, fixes) and values of keyframe 0 for the first iSAM2 update, and
    (fix index, position in that graph) of its keyframe-fix factors."""
    graph0 = prior_factors(P, r0, p0, v0, P.pri, K(0), yaw_sd)
    vals0 = gtsam.Values()
    vals0.insert(X(0), gtsam.Pose3(gtsam.Rot3(r0), p0))
    vals0.insert(V(0), v0)
    vals0.insert(B(0), gtsam.imuBias.ConstantBias())
    if P.drive.baro is not None:
        vals0.insert(C(0), np.zeros(1))
        vals0.insert(K(0), k0)
    if P.gm is not None:
        vals0.insert(G(0), np.zeros(P.gm.dim))
    if P.ka is not None:
        vals0.insert(A(0), np.zeros(3))
    fix_at: list[tuple[int, int]] = []
    if P.gm is None:  # with G(k), keyframe fixes enter as rows of the interval they end
        for i, f in keyframe_fixes(P, 0):
            fix_at.append((i, graph0.size()))
            graph0.add(f)
    return graph0, vals0, fix_at


def isam2_params(cfg: GraphConfig, robust: bool, ext: Collected | None = None,
                 linear: set[str] | None = None) -> Any:
    """ISAM2Params of one pass: typed relinearisation thresholds (``threshold_map``),
    Gauss-Newton (or, for the robust retry, dogleg) with the configured wildfire threshold,
    QR factorisation."""
    params = gtsam.ISAM2Params()
    params.setRelinearizeThreshold(threshold_map(cfg, ext, linear))
    params.relinearizeSkip = cfg.relinearize_skip
    params.enableRelinearization = cfg.relinearize_threshold > 0
    params.enablePartialRelinearizationCheck = cfg.partial_relinearization_check
    if robust:
        dl = gtsam.ISAM2DoglegParams()
        if cfg.wildfire_threshold is not None:
            dl.setWildfireThreshold(cfg.wildfire_threshold)
        params.setOptimizationParams(dl)
    elif cfg.wildfire_threshold is not None:
        params.setOptimizationParams(gtsam.ISAM2GaussNewtonParams(cfg.wildfire_threshold))
    # QR: Cholesky of the squared information failed ("indeterminate system") on
    # hill-drives with the consumer IMU (whitened gyro-bias rows ~1e4 next to metre-level
    # position rows); QR keeps the conditioning of the Jacobian.
    params.setFactorization("QR")
    return params
