"""The error series the report draws, on the same basis as the numbers in its table.

- simulated drive: estimate − truth at the estimate epochs (``basis = "truth"``), the GNSS
  outages shaded;
- real log with a holdout run: the holdout run's errors at the **withheld** GNSS fixes only
  (``basis = "withheld GNSS"``): altitude ``ĥ + c − h_GNSS`` (``c`` the datum offset of
  ``vnav_graph.evaluation.holdout``) and ``v̂_D − v_D,GNSS``; their RMS is exactly the
  ``alt_rmse_m`` / ``vel_down_rmse_mps`` of ``summary.json``;
- real log without a holdout run: estimate − the GNSS the estimator was given
  (``basis = "given GNSS"``). That is a fit residual, not an accuracy score, and the summary
  has no number for it; the plots say so and print no RMS.

The horizontal error is the norm of the north/east difference [m] (``pos_h`` estimators): on
the holdout basis exactly the series whose RMS is ``horiz_rmse_m``. The heading error (yaw,
``att`` estimators) exists against truth only.

Conventions: altitude +up [m], vertical velocity +down [m/s]. The σ of the altitude against
truth is sqrt(P_DD), against GNSS sqrt(P_DD + σ_GNSS,D²) (the fix is independent of the
estimate); of the horizontal error σ_h = sqrt(P_NN + P_EE) (+ σ_GNSS,N² + σ_GNSS,E² against
GNSS, the holdout run's own σ at the withheld fixes on that basis). No matplotlib here.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..types import ERROR_STATE, Drive, Estimate
from ..types.streams import FloatArray

_ALT = ERROR_STATE["pos_n"].start + 2  # down position row of the error state

TRUTH, WITHHELD, GIVEN = "truth", "withheld GNSS", "given GNSS"


@dataclass(frozen=True)
class ErrorSeries:
    """Errors of one estimator on ``t`` (N,) [s]: altitude error and 1σ [m], v_D error
    [m/s]; the horizontal error's norm [m] and its σ_h = sqrt(σ_N² + σ_E²) [m] (``pos_h``
    estimators); the heading error wrapped to [-180, 180) [deg] and the estimate's σ_yaw [deg]
    (``att`` estimators, against truth only: GNSS gives no heading)."""

    name: str
    t: FloatArray
    alt: FloatArray
    alt_sd: FloatArray | None
    vd: FloatArray | None
    horiz: FloatArray | None = None
    horiz_sd: FloatArray | None = None
    heading: FloatArray | None = None
    heading_sd: FloatArray | None = None


@dataclass(frozen=True)
class ErrorSet:
    """Every estimator's errors on one basis, and the windows to shade.

    ``windows_only``: the series exist only inside ``windows`` (withheld GNSS), so the time
    axis shows the windows side by side.
    """

    basis: str
    series: list[ErrorSeries]
    windows: list[tuple[float, float]]
    windows_only: bool

    @property
    def shaded(self) -> str:
        return {TRUTH: "simulated GNSS outage", WITHHELD: "GNSS withheld (scored)",
                GIVEN: "holdout window"}[self.basis]


def outage_windows(drive: Drive) -> list[tuple[float, float]]:
    """GNSS outage windows (simulated) or holdout windows (real logs) clipped to the drive."""
    w = drive.meta.get("gnss_outages") if drive.source == "simulated" else None
    if w is None:
        w = drive.meta.get("holdout_windows") or drive.meta.get("gnss_outages") or []
    t0, t1 = drive.imu.t[0], drive.imu.t[-1]
    return [(max(float(a), t0), min(float(b), t1)) for a, b in w if b > t0 and a < t1]


def alt_sd(est: Estimate, t: FloatArray) -> FloatArray | None:
    """1σ of the altitude of ``est`` at ``t`` from ``Estimate.cov`` (None without one)."""
    if est.cov is None or est.t_cov is None:
        return None
    var = est.cov[:, _ALT, _ALT]
    ok = np.isfinite(var)
    if ok.sum() < 1:
        return None
    return np.sqrt(np.clip(np.interp(t, est.t_cov[ok], var[ok]), 0.0, None))


def truth_errors(est: Estimate, drive: Drive) -> tuple[FloatArray, FloatArray,
                                                       FloatArray | None]:
    """(t, altitude error, down-velocity error or None) against truth at the estimate epochs
    inside the truth span: the quantities of ``metrics.errors_vs_truth`` (linear
    interpolation of the truth), without interpolating the attitude, which plots do not use
    and which costs a slerp of every epoch."""
    tr, truth = est.trajectory, drive.truth
    assert truth is not None
    m = (tr.t >= truth.t[0]) & (tr.t <= truth.t[-1])
    t = tr.t[m]
    alt = tr.alt[m] - np.interp(t, truth.t, truth.alt)
    vd = None
    if "vel_d" in est.provides:
        vd = tr.vel_down[m] - np.interp(t, truth.t, truth.vel_down)
    return t, alt, vd


def altitude_errors(est: Estimate, drive: Drive) -> tuple[FloatArray, FloatArray,
                                                          FloatArray | None, str]:
    """(t, error, 1σ or None, reference name) of the altitude of ``est`` against truth, or
    against the drive's GNSS fixes (``"GNSS"``) when it has no truth."""
    tr = est.trajectory
    if drive.truth is not None:
        t, e, _ = truth_errors(est, drive)
        return t, e, alt_sd(est, t), "truth"
    if drive.gnss is None:
        raise ValueError("no truth and no GNSS to compare with")
    g = drive.gnss
    m = (g.t >= tr.t[0]) & (g.t <= tr.t[-1])
    t = g.t[m]
    e = np.interp(t, tr.t, tr.alt) - g.lla[m, 2]
    sd = alt_sd(est, t)
    if sd is not None:
        sd = np.sqrt(sd**2 + g.pos_sd[m, 2] ** 2)
    return t, e, sd, "GNSS"


def horizontal_sd(est: Estimate, t: FloatArray) -> FloatArray | None:
    """σ_h = sqrt(σ_N² + σ_E²) [m] of ``est`` at ``t`` (None without both variances)."""
    n = ERROR_STATE["pos_n"].start
    sd_n, sd_e = est.sigma_at(t, n), est.sigma_at(t, n + 1)
    return None if sd_n is None or sd_e is None else np.hypot(sd_n, sd_e)


@dataclass(frozen=True)
class TruthTrack:
    """The truth once per drive: north/east from the origin [m] and unwrapped yaw [rad]."""

    t: FloatArray
    ne: FloatArray
    yaw: FloatArray | None

    @classmethod
    def of(cls, drive: Drive) -> TruthTrack:
        from ..geo.frames import lla_to_ned

        tr = drive.truth
        assert tr is not None
        yaw = None if tr.q_nb is None else np.unwrap(tr.to_rph()[:, 2])
        return cls(tr.t, lla_to_ned(tr.lla, drive.origin_lla)[:, :2], yaw)


def planar_errors(est: Estimate, drive: Drive, track: TruthTrack, t: FloatArray,
                  m: np.ndarray) -> dict[str, FloatArray | None]:
    """Horizontal and heading errors of ``est`` against truth at ``t`` = its epochs ``m``
    (``ErrorSeries`` fields). The truth is interpolated linearly (the yaw unwrapped), as
    ``metrics.errors_vs_truth`` does up to its slerp, which at the truth's IMU rate differs
    from it by far less than the plotted resolution."""
    from ..geo.frames import lla_to_ned

    tr = est.trajectory
    out: dict[str, FloatArray | None] = {"horiz": None, "horiz_sd": None, "heading": None,
                                         "heading_sd": None}
    if "pos_h" in est.provides and np.all(np.isfinite(tr.lla[m, :2])):
        ne = lla_to_ned(tr.lla[m], drive.origin_lla)[:, :2]
        d = ne - np.column_stack([np.interp(t, track.t, track.ne[:, j]) for j in range(2)])
        out["horiz"] = np.hypot(d[:, 0], d[:, 1])
        out["horiz_sd"] = horizontal_sd(est, t)
    if "att" in est.provides and tr.q_nb is not None and track.yaw is not None:
        dyaw = tr.to_rph()[m, 2] - np.interp(t, track.t, track.yaw)
        out["heading"] = np.degrees((dyaw + np.pi) % (2.0 * np.pi) - np.pi)
        sd = est.sigma_at(t, ERROR_STATE["att_n"].start + 2)  # rotation error about down
        out["heading_sd"] = None if sd is None else np.degrees(sd)
    return out


def _estimates(results: Sequence[Any]) -> list[Estimate]:
    return [r.estimate for r in results if r.estimate is not None]


def from_truth(drive: Drive, results: Sequence[Any]) -> ErrorSet:
    series = []
    track = TruthTrack.of(drive)
    assert drive.truth is not None
    for est in _estimates(results):
        t, e, vd = truth_errors(est, drive)
        tt = est.trajectory.t
        m = (tt >= drive.truth.t[0]) & (tt <= drive.truth.t[-1])
        series.append(ErrorSeries(est.estimator, t, e, alt_sd(est, t), vd,
                                  **planar_errors(est, drive, track, t, m)))
    return ErrorSet(TRUTH, series, outage_windows(drive), windows_only=False)


def from_holdout(holdout: Any) -> ErrorSet:
    """From a ``holdout.HoldoutResult``: the errors at the withheld fixes only."""
    series = []
    for name, s in holdout.series.items():
        if s.t is None or s.alt_err is None or s.withheld is None:
            continue
        w = s.withheld
        h = None if s.horiz_err is None else s.horiz_err[w]
        has_h = h is not None and np.isfinite(h).any()
        h_sd = s.horiz_sd
        series.append(ErrorSeries(name, s.t[w], s.alt_err[w],
                                  None if s.alt_sd is None else s.alt_sd[w],
                                  None if s.vd_err is None else s.vd_err[w],
                                  h if has_h else None,
                                  h_sd[w] if has_h and h_sd is not None else None))
    return ErrorSet(WITHHELD, series, [tuple(map(float, w)) for w in holdout.windows],
                    windows_only=True)


def horizontal_vs_fixes(est: Estimate, drive: Drive, t: FloatArray
                        ) -> tuple[FloatArray | None, FloatArray | None]:
    """(|NE error| [m], 3σ-ready σ_h = sqrt(P_NN + P_EE + σ_GNSS,N² + σ_GNSS,E²) [m]) of
    ``est`` against the drive's GNSS fixes at their times ``t``; (None, None) without pos_h."""
    from ..geo.frames import lla_to_ned

    g, tr = drive.gnss, est.trajectory
    if g is None or "pos_h" not in est.provides or not np.all(np.isfinite(tr.lla[:, :2])):
        return None, None
    m = np.isin(g.t, t)
    lla_e = np.column_stack([np.interp(g.t[m], tr.t, tr.lla[:, j]) for j in range(3)])
    d = (lla_to_ned(lla_e, drive.origin_lla)[:, :2]
         - lla_to_ned(g.lla[m], drive.origin_lla)[:, :2])
    sd = horizontal_sd(est, g.t[m])
    if sd is not None:
        sd = np.sqrt(sd**2 + g.pos_sd[m, 0] ** 2 + g.pos_sd[m, 1] ** 2)
    return np.hypot(d[:, 0], d[:, 1]), sd


def from_given_gnss(drive: Drive, results: Sequence[Any]) -> ErrorSet:
    g = drive.gnss
    series = []
    for est in _estimates(results):
        t, e, sd, _ = altitude_errors(est, drive)
        vd = None
        if g is not None and g.vel_n is not None and "vel_d" in est.provides:
            m = (g.t >= t[0]) & (g.t <= t[-1]) if t.size else np.zeros(g.t.size, bool)
            vd = np.interp(g.t[m], est.trajectory.t, est.trajectory.vel_down) - g.vel_n[m, 2]
        series.append(ErrorSeries(est.estimator, t, e, sd, vd,
                                  *horizontal_vs_fixes(est, drive, t)))
    return ErrorSet(GIVEN, series, outage_windows(drive), windows_only=False)


def error_set(drive: Drive, results: Sequence[Any], holdout: Any = None) -> ErrorSet:
    """The errors to draw for this drive (module docstring)."""
    if drive.truth is not None:
        return from_truth(drive, results)
    if holdout is not None:
        return from_holdout(holdout)
    if drive.gnss is None:
        raise ValueError("no truth and no GNSS to compare with")
    return from_given_gnss(drive, results)
