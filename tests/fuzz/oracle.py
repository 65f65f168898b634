"""Classify what the reading + validation path did with one corpus case.

Outcomes
--------
- ``rejected``: ``ValueError`` with a one-line message (what the CLI turns into exit 2 with
  nothing written).
- ``warned``: a Drive whose ``meta["warnings"]`` is not empty.
- ``clean``: a Drive without warnings whose streams match the undamaged control's
  (:func:`material_difference` found nothing): the damage hit bytes the readers do not use,
  or the repair was exact.
- ``silent``: a Drive without warnings that differs materially from the control: a **silent
  mis-read** (failure).
- ``traceback``: any other exception (failure). ``hang``: over ``TIME_LIMIT_S`` (failure).
- ``multiline``: a ValueError whose message spans lines (failure: the CLI prints one line).

"Material" thresholds (the smallest differences that change a result an estimator reports):
IMU 1 s mean specific force 0.5 m/s² or rate 0.05 rad/s; any GNSS fix 100 m (horizontal or
vertical; a gate takes smaller single outliers); any baro sample 20 m; a stream present in one
and absent in the other; more than 2 % of the control's samples missing inside the common
time span (a shorter log that reads right is not a mis-read).
"""

from __future__ import annotations

import signal
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

TIME_LIMIT_S = 60
FAILURES = ("silent", "traceback", "hang", "multiline", "control-rejected")


@dataclass
class Outcome:
    id: str
    fmt: str
    family: str
    damaged: bool
    outcome: str
    message: str = ""
    warnings: list[str] = field(default_factory=list)
    difference: str = ""
    seconds: float = 0.0


class _Timeout(Exception):
    pass


def _alarm(signum: int, frame: Any) -> None:
    raise _Timeout()


def load_with_limit(path: Path) -> Any:
    """``load_drive(path)`` under a SIGALRM time limit (main thread only)."""
    from vnav_graph.io import load_drive

    old = signal.signal(signal.SIGALRM, _alarm)
    signal.alarm(TIME_LIMIT_S)
    try:
        return load_drive(path)
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)


def _matched(t_a: np.ndarray, t_b: np.ndarray, tol: float = 1e-4
             ) -> tuple[np.ndarray, np.ndarray]:
    j = np.clip(np.searchsorted(t_b, t_a), 1, max(t_b.size - 1, 1))
    j = np.where(np.abs(t_b[j - 1] - t_a) < np.abs(t_b[j] - t_a), j - 1, j)
    ok = np.abs(t_b[j] - t_a) < tol
    return np.flatnonzero(ok), j[ok]


def _missing_inside(t_ctrl: np.ndarray, t_case: np.ndarray) -> float:
    inside = (t_ctrl >= t_case[0]) & (t_ctrl <= t_case[-1])
    if inside.sum() < 2:
        return 0.0
    i, _ = _matched(t_ctrl[inside], t_case)
    return 1.0 - i.size / inside.sum()


def _block_max(t: np.ndarray, x: np.ndarray) -> float:
    if t.size == 0:
        return 0.0
    k = np.floor(t - t[0]).astype(np.int64)
    n = np.bincount(k)
    ok = n > 0
    m = np.column_stack([np.bincount(k, weights=x[:, c])[ok] / n[ok] for c in range(x.shape[1])])
    return float(np.max(np.abs(m)))


def material_difference(d: Any, c: Any) -> str:
    """'' when ``d`` reads the same as the control ``c`` (thresholds in the module docstring),
    else the first difference found."""
    for s in ("gnss", "baro"):
        if (getattr(d, s) is None) != (getattr(c, s) is None):
            return f"{s} present in one and not the other"
    if _missing_inside(c.imu.t, d.imu.t) > 0.02:
        return f"imu: {100 * _missing_inside(c.imu.t, d.imu.t):.0f} % of samples missing"
    i, j = _matched(d.imu.t, c.imu.t)
    if i.size < 0.5 * min(len(d.imu), len(c.imu)):
        return "imu: time stamps differ"
    if i.size:
        ta = d.imu.t[i]
        da = _block_max(ta, d.imu.accel_b[i] - c.imu.accel_b[j])
        dg = _block_max(ta, d.imu.gyro_b[i] - c.imu.gyro_b[j])
        if da > 0.5 or dg > 0.05:
            return f"imu: 1 s mean differs by {da:.3g} m/s^2, {dg:.3g} rad/s"
    if d.gnss is not None:
        if _missing_inside(c.gnss.t, d.gnss.t) > 0.02:
            return "gnss: fixes missing"
        i, j = _matched(d.gnss.t, c.gnss.t, 0.05)
        if i.size < 0.5 * min(len(d.gnss), len(c.gnss)):
            return "gnss: time stamps differ"
        from vnav_graph.geo.frames import lla_to_ned

        dn = lla_to_ned(d.gnss.lla[i], c.gnss.lla[0]) - lla_to_ned(c.gnss.lla[j], c.gnss.lla[0])
        if i.size and float(np.max(np.abs(dn))) > 100.0:
            return f"gnss: a fix differs by {float(np.max(np.abs(dn))):.0f} m"
    if d.baro is not None:
        if _missing_inside(c.baro.t, d.baro.t) > 0.02:
            return "baro: samples missing"
        i, j = _matched(d.baro.t, c.baro.t, 0.02)
        if i.size < 0.5 * min(len(d.baro), len(c.baro)):
            return "baro: time stamps differ"
        db = np.abs(d.baro.altitude[i] - c.baro.altitude[j])
        if i.size and float(np.max(db)) > 20.0:
            return f"baro: a sample differs by {float(np.max(db)):.0f} m"
    return ""


def classify(case: Any, path: Path, control: Any, seconds: float, drive: Any = None,
             exc: BaseException | None = None) -> Outcome:
    o = Outcome(case.id, case.fmt, case.family, case.damaged, "", seconds=seconds)
    if exc is not None:
        if isinstance(exc, _Timeout):
            o.outcome = "hang"
        elif isinstance(exc, ValueError):
            msg = str(exc)
            o.message = msg
            o.outcome = "multiline" if "\n" in msg.strip() else "rejected"
            if not case.damaged and case.family == "control":
                o.outcome = "control-rejected"
        else:
            o.outcome = "traceback"
            o.message = "".join(traceback.format_exception_only(type(exc), exc)).strip()
        return o
    o.warnings = list(drive.meta.get("warnings") or [])
    if o.warnings:
        o.outcome = "warned"
        return o
    if control is None:
        o.outcome = "clean" if not case.damaged else "silent"
        o.difference = "" if not case.damaged else "no control to compare with"
        return o
    o.difference = material_difference(drive, control)
    o.outcome = "silent" if o.difference else "clean"
    return o


# ------------------------------------------------------------ run answers (summary.json)
WRONG_M = 1000.0  # an answer this far off is not one (evaluation.selfcheck.LOST_M)


def wrong_but_ok(summary: dict[str, Any]) -> list[str]:
    """Every estimator reported "ok" in a ``summary.json`` while one of its answers, the final
    trajectory or the causal ``online`` one, is more than ``WRONG_M`` off in height or
    horizontally: against truth (a simulated drive) or the withheld fixes (a log's holdout
    run). Read from ``alt_max_abs_m``, the self-checks' ``error_max_m`` (both answers, both
    axes; the holdout run's in ``holdout_self_check``) and the RMS errors of the ``online``
    block. One line per violation; [] when none."""
    bad = []
    for name, m in summary["estimators"].items():
        if m["status"] != "ok":
            continue
        seen: dict[str, Any] = {"alt_max_abs_m": m.get("alt_max_abs_m"),
                                "horiz_rmse_m": m.get("horiz_rmse_m")}
        for key in ("self_check", "holdout_self_check"):
            em = (m.get(key) or {}).get("error_max_m") or {}
            seen.update({f"{key}.{k}": v for k, v in em.items() if k != "basis"})
        on = m.get("online") or {}
        seen.update({f"online.{k}": on.get(k) for k in ("alt_rmse_m", "horiz_rmse_m")})
        bad += [f"{name}: {k} = {v:.0f} m, status ok" for k, v in seen.items()
                if isinstance(v, (int, float)) and v > WRONG_M]
    return bad


def answers_checked(summary: dict[str, Any]) -> list[str]:
    """The estimators of a summary whose self-check did not look at both answers: an "ok"
    estimator with a causal answer (an ``online`` block) must have the online self-check."""
    out = []
    for name, m in summary["estimators"].items():
        sc = m.get("self_check")
        if m["status"] not in ("ok", "diverged") or sc is None:
            continue
        if m.get("online") is not None and sc.get("online") is None:
            out.append(f"{name}: online answer not self-checked")
    return out
