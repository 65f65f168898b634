"""Errors of an Estimate against truth: altitude, vertical velocity, NEES, baro parameters.

Truth is interpolated to the estimate's stamps, never the other way round.
``evaluate`` returns the per-estimator metric block of ``summary.json`` (docs/design.md); metrics
that do not apply are ``None``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import partial
from typing import Any

import numpy as np

from ..types import ERROR_STATE, Drive, Estimate
from ..types.streams import FloatArray
from .blocks import baro_block, extra_variables_block, fb_separation_block


@dataclass(frozen=True)
class Errors:
    t: FloatArray
    alt: FloatArray  # estimate − truth [m]
    vel_down: FloatArray | None  # [m/s]
    horiz: FloatArray | None = None  # |NE position error| [m], estimates providing pos_h
    heading: FloatArray | None = None  # yaw error wrapped to [-180, 180) [deg], "att"
    heading_sd: FloatArray | None = None  # the estimate's own σ of yaw [deg], from its cov


def errors_vs_truth(est: Estimate, drive: Drive) -> Errors:
    if drive.truth is None:
        raise ValueError("errors_vs_truth: the drive has no truth")
    tr = est.trajectory
    m = (tr.t >= drive.truth.t[0]) & (tr.t <= drive.truth.t[-1])
    t = tr.t[m]
    truth = drive.truth.at(t)
    alt = tr.alt[m] - truth.alt
    vd = None
    if "vel_d" in est.provides:
        vd = tr.vel_down[m] - truth.vel_down
    horiz = None
    if "pos_h" in est.provides:
        from ..geo.frames import lla_to_ned

        d = (lla_to_ned(tr.lla[m], drive.origin_lla)[:, :2]
             - truth.pos_n(drive.origin_lla)[:, :2])
        horiz = np.sqrt(np.sum(d**2, axis=1))
    heading = None
    if "att" in est.provides and tr.q_nb is not None and truth.q_nb is not None:
        dyaw = tr.to_rph()[m, 2] - truth.to_rph()[:, 2]
        heading = np.degrees((dyaw + np.pi) % (2.0 * np.pi) - np.pi)
    heading_sd = None
    if heading is not None:
        sd = est.sigma_at(t, ERROR_STATE["att_n"].start + 2)  # rotation error about down
        heading_sd = None if sd is None else np.degrees(sd)
    return Errors(t, alt, vd, horiz, heading, heading_sd)


# Heading is "known" where the estimate's own yaw σ is at most this [deg]: a magnetometer-free
# INS on a vehicle that has not yet turned or accelerated reports σ_yaw of tens of degrees
# (cold start), and scoring those epochs charges it for what it says it does not know.
HEADING_KNOWN_SD_DEG = 5.0


def heading_known(t: FloatArray, heading: FloatArray | None, sd: FloatArray | None,
                  limit_deg: float = HEADING_KNOWN_SD_DEG,
                  t_ref: float | None = None) -> tuple[float | None, float | None]:
    """(RMS heading error over the epochs with σ_yaw ≤ ``limit_deg`` [deg], the time [s after
    ``t_ref``, default the first epoch] from which σ_yaw stays ≤ ``limit_deg``:
    ``known_after``); None where it never is, or without a heading error or its σ."""
    if heading is None or sd is None:
        return None, None
    known = np.isfinite(sd) & (sd <= limit_deg) & np.isfinite(heading)
    if not known.any():
        return None, None
    rms = float(np.sqrt(np.mean(heading[known] ** 2)))
    return rms, known_after(t, sd, limit_deg, t_ref)


def known_after(t: FloatArray, sd: FloatArray | None, limit_deg: float = HEADING_KNOWN_SD_DEG,
                t_ref: float | None = None) -> float | None:
    """The time [s after ``t_ref``, default ``t[0]``] from which ``sd`` [deg] stays ≤
    ``limit_deg`` to the last epoch; None without ``sd``, or when it is above it at the end."""
    if sd is None or t.size == 0:
        return None
    bad = np.flatnonzero(~(np.isfinite(sd) & (sd <= limit_deg)))
    if bad.size and bad[-1] == t.size - 1:
        return None  # not known at the end
    start = 0 if bad.size == 0 else int(bad[-1]) + 1
    return float(t[start] - (t[0] if t_ref is None else t_ref))


def heading_errors(est: Estimate, drive: Drive
                   ) -> tuple[FloatArray, FloatArray, FloatArray] | None:
    """``(t, heading error, σ_yaw)`` [s, deg, deg] of ``est`` against truth
    (``errors_vs_truth``), None without truth, a heading or its σ."""
    if drive.truth is None:
        return None
    err = errors_vs_truth(est, drive)
    if err.heading is None or err.heading_sd is None:
        return None
    return err.t, err.heading, err.heading_sd


def heading_common(t: FloatArray, heading: FloatArray, sd: FloatArray, t_other: FloatArray,
                   sd_other: FloatArray, limit_deg: float = HEADING_KNOWN_SD_DEG
                   ) -> dict[str, Any]:
    """RMS heading error [deg] of one estimate at the epochs where it and another both report
    σ_yaw ≤ ``limit_deg``: its own epochs ``t`` [s] with its ``sd`` ≤ the limit and the other's
    ``sd_other`` (at ``t_other``, interpolated to ``t``; outside the other's span: not known)
    ≤ the limit. Returns ``{"rmse_deg", "n_epochs", "known_s"}`` (``known_s``: the seconds
    those epochs span, their count times the median step); ``rmse_deg`` None where there are
    none."""
    other = np.full(t.size, np.nan)
    ok = np.isfinite(sd_other)
    if ok.any():
        inside = (t >= t_other[ok][0]) & (t <= t_other[ok][-1])
        other[inside] = np.interp(t[inside], t_other[ok], sd_other[ok])
    both = (np.isfinite(heading) & np.isfinite(sd) & (sd <= limit_deg)
            & np.isfinite(other) & (other <= limit_deg))
    n = int(both.sum())
    step = float(np.median(np.diff(t))) if t.size > 1 else 0.0
    return {"rmse_deg": float(np.sqrt(np.mean(heading[both] ** 2))) if n else None,
            "n_epochs": n, "known_s": n * step}


def outage_max(t: FloatArray, err: FloatArray | None,
               windows: Sequence[Sequence[float]]) -> float | None:
    """max |err| over the samples inside the GNSS outage ``windows`` [(t0, t1), ...] [s];
    None without windows, samples or errors."""
    if err is None or not windows:
        return None
    m = np.zeros(t.size, dtype=bool)
    for a, b in windows:
        m |= (t >= a) & (t < b)
    m &= np.isfinite(err)
    return float(np.max(np.abs(err[m]))) if m.any() else None


def nees_rows(est: Estimate, drive: Drive) -> tuple[np.ndarray, np.ndarray] | None:
    """The covariance epochs ``nees`` scores (inside the truth's span, with finite variances)
    and the position/velocity components it covers; None where it scores nothing."""
    if est.cov is None or est.t_cov is None or drive.truth is None:
        return None
    idx = np.r_[np.arange(18)[ERROR_STATE["pos_n"]], np.arange(18)[ERROR_STATE["vel_n"]]]
    diag = np.diagonal(est.cov, axis1=1, axis2=2)[:, idx]
    rows = np.any(np.isfinite(diag), axis=1)
    if not rows.any():
        return None
    keep = np.isfinite(diag[int(np.argmax(rows))])
    idx, diag = idx[keep], diag[:, keep]
    if idx.size == 0:
        return None
    m = ((est.t_cov >= drive.truth.t[0]) & (est.t_cov <= drive.truth.t[-1])
         & np.all(np.isfinite(diag), axis=1))
    return m, idx


def nees(est: Estimate, drive: Drive) -> tuple[FloatArray, int] | None:
    """NEES over the position/velocity error components the estimate covers (finite rows of
    ``pos_n``/``vel_n`` in its covariance), at the covariance epochs where those are finite
    (``nees_rows``; graph-isam2's real-time output has none between keyframes). Returns
    (nees per such epoch, dof)."""
    rows = nees_rows(est, drive)
    if rows is None:
        return None
    m, idx = rows
    assert est.t_cov is not None and est.cov is not None and drive.truth is not None
    t = est.t_cov[m]
    traj = est.trajectory.at(t)
    truth = drive.truth.at(t)
    e = np.full((t.size, 18), np.nan)
    if "pos_h" in est.provides:
        e[:, 0:3] = traj.pos_n(drive.origin_lla) - truth.pos_n(drive.origin_lla)
    # down error from heights: local vertical, independent of tangent-plane curvature
    e[:, 2] = -(traj.alt - truth.alt)
    e[:, 3:6] = traj.vel_n - truth.vel_n
    e = e[:, idx]
    p = est.cov[m][:, idx[:, None], idx[None, :]]
    val = np.einsum("ni,ni->n", e, np.linalg.solve(p, e[..., None])[..., 0])
    return val, int(idx.size)


# The per-axis NEES of ``nees_axes``: (key, ERROR_STATE components, dof) of each metric's own
# axes (down position = altitude, north/east position = horizontal)
NEES_AXES = (("alt", (2,), 1), ("horiz", (0, 1), 2), ("vel", (3, 4, 5), 3),
             ("vel_down", (5,), 1))


def nees_axes(est: Estimate, drive: Drive, err: Errors | None = None) -> dict[str, Any] | None:
    """Mean NEES per dof on each metric's own axes: ``alt`` (down position, 1 dof), ``horiz``
    (north/east position, 2), ``vel`` (north/east/down velocity, 3), ``vel_down`` (1) at
    the covariance epochs, and ``heading``, the mean of (yaw error / σ_yaw)² at the
    trajectory epochs where σ_yaw is finite. A value is None where the estimate lacks the
    quantity or its variance; the whole block is None without truth or covariance.
    1 = the reported σ matches the error; above 2 the σ does not cover it."""
    if est.cov is None or est.t_cov is None or drive.truth is None:
        return None
    m = (est.t_cov >= drive.truth.t[0]) & (est.t_cov <= drive.truth.t[-1])
    t = est.t_cov[m]
    if t.size == 0:
        return None
    traj = est.trajectory.at(t)
    truth = drive.truth.at(t)
    e = np.full((t.size, 6), np.nan)
    if "pos_h" in est.provides:
        e[:, 0:3] = traj.pos_n(drive.origin_lla) - truth.pos_n(drive.origin_lla)
    e[:, 2] = -(traj.alt - truth.alt)  # down error from heights (as ``nees``)
    if "vel_h" in est.provides:
        e[:, 3:5] = (traj.vel_n - truth.vel_n)[:, :2]
    if "vel_d" in est.provides:
        e[:, 5] = traj.vel_down - truth.vel_down
    cov = est.cov[m][:, :6, :6]
    out: dict[str, Any] = {}
    for key, comps, dof in NEES_AXES:
        idx = np.array(comps)
        ee = e[:, idx]
        p = cov[:, idx[:, None], idx[None, :]]
        ok = np.all(np.isfinite(ee), axis=1) & np.all(np.isfinite(p), axis=(1, 2))
        if not ok.any():
            out[key] = None
            continue
        val = np.einsum("ni,ni->n", ee[ok], np.linalg.solve(p[ok], ee[ok][..., None])[..., 0])
        out[key] = float(np.mean(val)) / dof
    err = err if err is not None else errors_vs_truth(est, drive)
    out["heading"] = None
    if err.heading is not None and err.heading_sd is not None:
        k = np.isfinite(err.heading) & np.isfinite(err.heading_sd) & (err.heading_sd > 0)
        if k.any():
            out["heading"] = float(np.mean((err.heading[k] / err.heading_sd[k]) ** 2))
    return out


def error_p95(err: Errors) -> dict[str, float | None]:
    """The 95th percentile of |error| over the drive: ``alt_p95_m``, ``horiz_p95_m``,
    ``heading_p95_deg``, ``vel_down_p95_mps`` (None where the estimate lacks the quantity)."""
    p95 = partial(finite_stat, stat=lambda v: np.percentile(np.abs(v), 95))
    return {"alt_p95_m": p95(err.alt), "horiz_p95_m": p95(err.horiz),
            "heading_p95_deg": p95(err.heading), "vel_down_p95_mps": p95(err.vel_down)}


METRIC_KEYS = ("alt_rmse_m", "alt_max_abs_m", "horiz_rmse_m", "heading_rmse_deg",
               "heading_known_rmse_deg", "heading_known_after_s", "outage_alt_max_m",
               "outage_horiz_max_m", "vel_down_rmse_mps", "nees_mean", "nees_dof")


# The keys of the ``online`` block (and, with ``lag_s``, the ``lag`` block) of every
# summary.json / holdout.json / bench.json estimator block
ONLINE_KEYS = ("alt_rmse_m", "horiz_rmse_m", "heading_rmse_deg", "heading_known_rmse_deg",
               "heading_known_after_s", "vel_down_rmse_mps", "nees_mean", "nees_dof")


def causal_view(est: Estimate, which: str) -> Estimate | None:
    """``est``'s causal (``which="online"``) or fixed-lag (``"lag"``) estimate as an Estimate
    of its own (trajectory and covariance), or None when it has none. The pure smoothers'
    online estimate is not scored (``base.PURE_SMOOTHERS``: ekf-rts's forward pass is the ekf
    row)."""
    from ..estimators.base import PURE_SMOOTHERS

    tr = getattr(est, which)
    if tr is None or (which == "online" and est.estimator in PURE_SMOOTHERS):
        return None
    cov = getattr(est, f"{which}_cov")
    return Estimate(est.estimator, tr, est.provides, cov=cov,
                    t_cov=None if cov is None else tr.t, info=est.info)


@dataclass(frozen=True)
class CausalErrors:
    """The errors of a causal (or fixed-lag) estimate against truth, epoch by epoch: what its
    ``online`` / ``lag`` block summarises (``causal_metrics``), kept so that two estimates
    can be scored over a common span (``causal_metrics(..., t_from)``)."""

    from_s: float  # its first epoch [s after the drive's start]
    t_ref: float  # the drive's start [s]
    err: Errors | None  # None without truth
    t_nees: FloatArray | None  # the covariance epochs of ``nees``
    nees: FloatArray | None  # NEES of position and velocity there
    nees_dof: int | None


def causal_errors(est: Estimate, drive: Drive, which: str) -> CausalErrors | None:
    """``CausalErrors`` of ``est``'s causal / fixed-lag estimate (``causal_view``), None when
    it has none."""
    view = causal_view(est, which)
    if view is None:
        return None
    t_ref = float(drive.imu.t[0])
    # its first epoch [s after the drive's start]: the ekf's starts when it is aligned
    from_s = float(view.trajectory.t[0] - t_ref)
    if drive.truth is None:
        return CausalErrors(from_s, t_ref, None, None, None, None)
    err = errors_vs_truth(view, drive)
    ne = nees(view, drive)
    t_ne = None
    rows = nees_rows(view, drive)
    if ne is not None and view.t_cov is not None and rows is not None:
        t_ne = view.t_cov[rows[0]]
    return CausalErrors(from_s, t_ref, err, t_ne, None if ne is None else ne[0],
                        None if ne is None else ne[1])


def causal_metrics(ce: CausalErrors, t_from_s: float | None = None) -> dict[str, Any]:
    """``ONLINE_KEYS`` over the epochs from ``t_from_s`` [s after the drive's start; default
    every epoch]: the RMS errors, ``heading_known`` (its own σ_yaw, the top-level block's
    metric; ``heading_known_after_s`` in s after the drive's start) and the mean NEES; null
    without truth or where the estimate lacks the quantity."""
    out: dict[str, Any] = dict.fromkeys(ONLINE_KEYS)
    err = ce.err
    if err is None:
        return out
    t0 = ce.t_ref + (-np.inf if t_from_s is None else t_from_s)
    m = err.t >= t0
    if m.any():
        def cut(x: FloatArray | None) -> FloatArray | None:
            return None if x is None else x[m]

        out["alt_rmse_m"] = _rms(err.alt[m])
        out["horiz_rmse_m"] = _rms(cut(err.horiz))
        out["heading_rmse_deg"] = _rms(cut(err.heading))
        out["vel_down_rmse_mps"] = _rms(cut(err.vel_down))
        out["heading_known_rmse_deg"], out["heading_known_after_s"] = heading_known(
            err.t[m], cut(err.heading), cut(err.heading_sd), t_ref=ce.t_ref)
    if ce.nees is not None and ce.t_nees is not None:
        k = ce.t_nees >= t0
        if k.any():
            out["nees_mean"], out["nees_dof"] = float(np.mean(ce.nees[k])), ce.nees_dof
    return out


def causal_block(est: Estimate, drive: Drive, which: str) -> dict[str, Any] | None:
    """The ``online`` / ``lag`` block: ``ONLINE_KEYS`` of the causal or fixed-lag estimate
    against truth over its own epochs (``causal_metrics``: null without truth or where the
    estimate lacks the quantity), ``from_s`` (its first epoch, s after the drive's start),
    ``lag_s`` (``info["lag_s"]``) in the lag block; None when the estimate has none
    (``causal_view``)."""
    ce = causal_errors(est, drive, which)
    return None if ce is None else causal_block_of(ce, est, which)


def causal_block_of(ce: CausalErrors, est: Estimate, which: str) -> dict[str, Any]:
    """``causal_block`` from the errors ``ce`` already computed."""
    out: dict[str, Any] = {**causal_metrics(ce), "from_s": ce.from_s}
    if which == "lag":
        lag = est.info.get("lag_s")
        out["lag_s"] = None if lag is None else float(lag)
    return out


def _rms(x: FloatArray | None) -> float | None:
    return None if x is None or x.size == 0 else float(np.sqrt(np.mean(x**2)))


def finite_stat(x: FloatArray | None, stat: Any) -> float | None:
    """``stat`` of the finite entries of ``x`` (None without an array or a finite entry)."""
    if x is None:
        return None
    x = x[np.isfinite(x)]
    return float(stat(x)) if x.size else None


# the RMS and the largest |entry| of the finite entries (None as ``finite_stat``)
finite_rms = partial(finite_stat, stat=lambda v: np.sqrt(np.mean(v**2)))
finite_max = partial(finite_stat, stat=lambda v: np.max(np.abs(v)))


def evaluate(est: Estimate, drive: Drive,
             blocks: Sequence[tuple[float, float]] | None = None) -> dict[str, Any]:
    """Metric block for summary.json / bench.json (docs/design.md schema).

    Additions to the docs/design.md block: ``horiz_rmse_m`` (RMS of the north/east position
    error, estimates providing ``pos_h``), ``heading_rmse_deg`` (RMS of the yaw error wrapped
    to ±180°, estimates providing ``att``), ``heading_known_rmse_deg`` and
    ``heading_known_after_s`` (the same over the epochs where the estimate's own σ_yaw ≤
    ``HEADING_KNOWN_SD_DEG``, and the time [s after the drive's start] from which it stays
    there: ``heading_known``),
    ``outage_alt_max_m`` / ``outage_horiz_max_m``
    (max |error| inside the drive's GNSS outages, ``meta["gnss_outages"]``; null without
    outages), ``warnings`` and ``extra_variables`` (the
    variables a graph extension added, ``{"m0": {"est": [...], "sd": [...]}}`` from
    ``info["extra_variables"]``; null for an estimator without them), ``online`` and ``lag``
    (``causal_block``: the same errors of the causal estimate, ``Estimate.online``, and of
    graph-isam2's fixed-lag estimate, ``Estimate.lag``; null where there is none). With
    ``blocks`` (time blocks ``[(t0, t1), ...]`` [s]) the block also has ``per_block``, the
    RMS values per block, which ``pipeline.summarize`` moves to ``summary["comparison"]``
    (the paired comparison of ``vnav_graph.evaluation.compare``), so the estimator block
    stays the bench row. ``nees_axes`` (``nees_axes``: mean NEES/dof on the altitude,
    horizontal, velocity, vertical-velocity and heading axes; null without truth or
    covariance) and ``alt_p95_m`` / ``horiz_p95_m`` / ``heading_p95_deg`` /
    ``vel_down_p95_mps`` (``error_p95``) are read by the win rule
    (``vnav_graph.evaluation.winrule``).
    """
    out: dict[str, Any] = {
        "status": "ok", "error": None, **dict.fromkeys(METRIC_KEYS),
        "runtime_s": float(est.runtime_s),
        "realtime_factor": (drive.duration_s / est.runtime_s) if est.runtime_s > 0 else None,
        "gnss_rejected": est.info.get("gnss_rejected"),
        # fixes the ekf forced in after its refusal limit (null for estimators that force none)
        "gnss_forced": est.info.get("gnss_forced"),
        # [t_start, t_end] [s] of the standstills given zero-velocity updates (ekf, ekf-rts and
        # the graphs, ``nav.standstill``; null for estimators without them)
        "zupt_intervals": est.info.get("zupt_intervals"),
        # things the user should know about this result (e.g. a solver that stopped at its
        # iteration cap); an addition to the docs/design.md block, always a list
        "warnings": [str(w) for w in est.info.get("warnings", [])],
        # what the estimator fell back to (damping of a singular system, the general sparse
        # solver, ...; each also a warning), and the graph's solver path (null elsewhere)
        "fallbacks": [str(f) for f in est.info.get("fallbacks", [])],
        "solver": est.info.get("solver"),
        # graph-isam2: whose answer the trajectory is, "isam2" or "batch" (null elsewhere)
        "isam2_final": est.info.get("isam2_final"),
        # graph smoothers: factors and variables each extension added (null elsewhere)
        "extensions": est.info.get("extensions"),
        "extra_variables": extra_variables_block(est.info.get("extra_variables")),
        # the causal estimate and graph-isam2's fixed-lag one, scored alike (causal_block)
        "online": causal_block(est, drive, "online"),
        "lag": causal_block(est, drive, "lag"),
        # ekf-rts: forward/backward filter separation (null for the others)
        "fb_separation": fb_separation_block(est.info.get("fb_separation")),
        # gnss_gm_auto: the residual autocorrelations and whether the Gauss-Markov GNSS
        # error state was carried (``estimators.gnss_auto``; null without the option)
        "gnss_gm_auto": est.info.get("gnss_gm_auto"),
        # the pass whose real-time answers these are, when a whole-drive check ran the
        # estimator again ({"pass", "why", "decided_at_s"}; null when there was one pass)
        "real_time_pass": est.info.get("real_time_pass"),
        # the win rule's calibration and tails (nees_axes, error_p95; null without truth)
        "nees_axes": None, "alt_p95_m": None, "horiz_p95_m": None, "heading_p95_deg": None,
        "vel_down_p95_mps": None,
    }
    err = None
    if drive.truth is not None:
        err = errors_vs_truth(est, drive)
        out.update(_truth_metrics(est, drive, err, blocks))
    out["baro"] = baro_block(est.baro, drive)
    from .selfcheck import DIVERGED, check_answers, far_off

    check = check_answers(est, causal_view(est, "online"), drive)
    out["self_check"] = check.as_dict()
    out["warnings"] += list(check.flags)
    far = None
    if drive.truth is not None:  # every answer, both axes, against truth
        maxima = answer_maxima(err, causal_errors(est, drive, "online"))
        out["self_check"]["error_max_m"] = {**maxima, "basis": "truth"}
        far = far_off(maxima, "truth")
    if check.diverged:  # kept in the outputs, marked, never ranked (comparison: "ok" only)
        out["status"], out["error"] = DIVERGED, check.reason
    elif far:
        out["status"], out["error"] = DIVERGED, far
    return out


def _truth_metrics(est: Estimate, drive: Drive, err: Errors,
                   blocks: Sequence[tuple[float, float]] | None) -> dict[str, Any]:
    """``evaluate``'s error metrics against the drive's truth (``err``: ``errors_vs_truth``)."""
    out: dict[str, Any] = {}
    out["alt_rmse_m"] = float(np.sqrt(np.mean(err.alt**2)))
    out["alt_max_abs_m"] = float(np.max(np.abs(err.alt)))
    if err.vel_down is not None:
        out["vel_down_rmse_mps"] = float(np.sqrt(np.mean(err.vel_down**2)))
    if err.horiz is not None:
        out["horiz_rmse_m"] = float(np.sqrt(np.mean(err.horiz**2)))
    if err.heading is not None:
        out["heading_rmse_deg"] = float(np.sqrt(np.mean(err.heading**2)))
    out["heading_known_rmse_deg"], out["heading_known_after_s"] = heading_known(
        err.t, err.heading, err.heading_sd, t_ref=float(drive.imu.t[0]))
    outages = drive.meta.get("gnss_outages") or []
    out["outage_alt_max_m"] = outage_max(err.t, err.alt, outages)
    out["outage_horiz_max_m"] = outage_max(err.t, err.horiz, outages)
    if blocks is not None:
        from .compare import block_rmse

        cols = {"alt_rmse_m": block_rmse(err.t, err.alt, blocks),
                "horiz_rmse_m": block_rmse(err.t, err.horiz, blocks),
                "vel_down_rmse_mps": block_rmse(err.t, err.vel_down, blocks)}
        out["per_block"] = [{"t0": a, "t1": b, **{k: v[i] for k, v in cols.items()}}
                            for i, (a, b) in enumerate(blocks)]
    ne = nees(est, drive)
    if ne is not None:
        out["nees_mean"] = float(np.mean(ne[0]))
        out["nees_dof"] = ne[1]
    # additions: calibration on each metric's own axes, and the error's tail
    out["nees_axes"] = nees_axes(est, drive, err)
    out.update(error_p95(err))
    return out


def answer_maxima(err: Errors, online: CausalErrors | None) -> dict[str, float | None]:
    """The largest |error| [m] of the final answer (``err``) and of the causal one, in height
    and horizontally (None where the estimate has no such answer): the self-check's
    ``error_max_m``."""
    def mx(x: FloatArray | None) -> float | None:
        return None if x is None or x.size == 0 else float(np.max(np.abs(x)))

    oe = None if online is None else online.err
    return {"height": mx(err.alt), "horizontal": mx(err.horiz),
            "online_height": None if oe is None else mx(oe.alt),
            "online_horizontal": None if oe is None else mx(oe.horiz)}
