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

Conventions: altitude +up [m], vertical velocity +down [m/s]. The ±3σ band of the altitude
against truth is 3·sqrt(P_DD); against GNSS 3·sqrt(P_DD + σ_GNSS,D²) (the fix is independent
of the estimate). No matplotlib here.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..types import ERROR_STATE, Drive, Estimate, FloatArray

_ALT = ERROR_STATE["pos_n"].start + 2  # down position row of the error state

TRUTH, WITHHELD, GIVEN = "truth", "withheld GNSS", "given GNSS"


@dataclass(frozen=True)
class ErrorSeries:
    """Errors of one estimator: ``t`` (N,) [s], altitude error and 1σ [m], v_D error [m/s]."""

    name: str
    t: FloatArray
    alt: FloatArray
    alt_sd: FloatArray | None
    vd: FloatArray | None


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


def _estimates(results: Sequence[Any]) -> list[Estimate]:
    return [r.estimate for r in results if r.estimate is not None]


def from_truth(drive: Drive, results: Sequence[Any]) -> ErrorSet:
    series = []
    for est in _estimates(results):
        t, e, vd = truth_errors(est, drive)
        series.append(ErrorSeries(est.estimator, t, e, alt_sd(est, t), vd))
    return ErrorSet(TRUTH, series, outage_windows(drive), windows_only=False)


def from_holdout(holdout: Any) -> ErrorSet:
    """From a ``holdout.HoldoutResult``: the errors at the withheld fixes only."""
    series = []
    for name, s in holdout.series.items():
        if s.t is None or s.alt_err is None or s.withheld is None:
            continue
        w = s.withheld
        series.append(ErrorSeries(name, s.t[w], s.alt_err[w],
                                  None if s.alt_sd is None else s.alt_sd[w],
                                  None if s.vd_err is None else s.vd_err[w]))
    return ErrorSet(WITHHELD, series, [tuple(map(float, w)) for w in holdout.windows],
                    windows_only=True)


def from_given_gnss(drive: Drive, results: Sequence[Any]) -> ErrorSet:
    g = drive.gnss
    series = []
    for est in _estimates(results):
        t, e, sd, _ = altitude_errors(est, drive)
        vd = None
        if g is not None and g.vel_n is not None and "vel_d" in est.provides:
            m = (g.t >= t[0]) & (g.t <= t[-1]) if t.size else np.zeros(g.t.size, bool)
            vd = np.interp(g.t[m], est.trajectory.t, est.trajectory.vel_down) - g.vel_n[m, 2]
        series.append(ErrorSeries(est.estimator, t, e, sd, vd))
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
