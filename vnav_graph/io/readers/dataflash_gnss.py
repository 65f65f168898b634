"""ArduPilot DataFlash: the GNSS fixes, their sigmas and the clock they put the log on.

Read by :func:`.ardupilot.read_dataflash` (whose docstring gives the messages, the clock
model and the sigma rules): ``read_gnss`` takes the 3-D fixes of ``GPS`` instance 0 with their
GPS time and receipt stamps, ``gnss_boot_time`` fits the boot clock against GPS time,
``speed_evidence`` checks that fit against the logged speed, ``choose_clock`` picks the time
basis and ``gnss_sigmas`` gives each fix its σ from ``GPA``/``UBX3`` accuracies or from HDop.
``time_s``, ``instance0`` and ``col`` read any DataFlash record.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ._common import (
    CLOCK_RATIO_TOL,
    ClockFit,
    Report,
    finite_rows,
    fit_clock,
    monotonic_mask,
)

DEG = np.pi / 180.0
HDOP_UERE_M = 1.0  # user-equivalent range error used with HDop [m]
VDOP_OVER_HDOP = 1.5
SD_FLOOR_H_M = 0.5
SD_FLOOR_V_M = 1.0
DEFAULT_VEL_SD = (0.3, 0.3, 0.5)  # m/s, when the log has no speed accuracy


def time_s(msg: dict[str, Any]) -> float:
    if "TimeUS" in msg:
        return float(msg["TimeUS"]) * 1e-6
    if "TimeMS" in msg:
        return float(msg["TimeMS"]) * 1e-3
    return float("nan")


def instance0(msg: dict[str, Any]) -> bool:
    for key in ("I", "Instance", "C", "Core"):
        if key in msg:
            return int(msg[key]) == 0
    return True


def col(rows: Sequence[dict[str, Any]], *names: str) -> np.ndarray:
    """Column of the first of ``names`` present in the records (NaN where missing)."""
    for n in names:
        if rows and n in rows[0]:
            return np.array([float(r.get(n, np.nan)) for r in rows], dtype=float)
    return np.full(len(rows), np.nan)


def gnss_boot_time(t_recv: np.ndarray, gps_time: np.ndarray,
                    report: Report) -> tuple[np.ndarray, ClockFit | None]:
    """Map GPS time [s] to the boot clock by a robust linear fit of receipt stamps on it.

    ``t_recv ≈ a + r·(gps_time − gps_time[0])`` (:func:`._common.fit_clock`); stamps = the
    fitted line, which removes the receipt jitter and keeps the mean transport latency.
    """
    if not np.all(np.isfinite(gps_time)) or gps_time.size < 5:
        report.notes.append("GNSS stamped with receipt time (no GPS time in the log)")
        return t_recv, None
    fit = fit_clock(t_recv, gps_time)
    report.clock_rate = fit.ratio
    report.notes.append(
        f"GNSS stamped by GPS time of week mapped onto the boot clock (receipt jitter sd "
        f"{fit.sd * 1e3:.1f} ms; {fit.n_outliers} receipt stamps off the fit by > 0.1 s)")
    return fit.local_of_gps(gps_time), fit


def speed_evidence(t_fix: np.ndarray, gps_time: np.ndarray, lla: np.ndarray,
                    vel_n: np.ndarray, span: int = 5) -> dict[str, float] | None:
    """Receiver speed vs position increments on both clocks (clock-choice evidence).

    Median over windows of ``span`` fixes (moving faster than 1 m/s) of
    ``|Δp| / |∫ v_NE dt|`` with dt from GPS time and from the boot-clock stamps. The clock
    on which the receiver's velocity integrates to its own displacement gives ≈ 1.
    """
    if vel_n is None or t_fix.size <= span + 5:
        return None
    from ...geo.earth import radii

    rn, re = radii(float(lla[0, 0]))
    n = (lla[:, 0] - lla[0, 0]) * (rn + lla[:, 2])
    e = (lla[:, 1] - lla[0, 1]) * (re + lla[:, 2]) * np.cos(lla[:, 0])
    j = np.arange(t_fix.size - span)
    disp = np.hypot(n[j + span] - n[j], e[j + span] - e[j])
    speed = np.hypot(vel_n[:, 0], vel_n[:, 1])
    out: dict[str, float] = {}
    for name, t in (("gps_clock", gps_time - gps_time[0]), ("boot_clock", t_fix)):
        dt = np.diff(t)
        cn = np.concatenate([[0.0], np.cumsum(0.5 * (vel_n[1:, 0] + vel_n[:-1, 0]) * dt)])
        ce = np.concatenate([[0.0], np.cumsum(0.5 * (vel_n[1:, 1] + vel_n[:-1, 1]) * dt)])
        integ = np.hypot(cn[j + span] - cn[j], ce[j + span] - ce[j])
        ok = (speed[j] > 1.0) & (integ > 0.5) & (disp < 300.0)
        if ok.sum() < 10:
            return None
        out[f"displacement_over_speed_integral_{name}"] = float(np.median(disp[ok] / integ[ok]))
    out["windows"] = int(ok.sum())
    return out


def decimal_year(gps_time: np.ndarray) -> float | None:
    """Decimal year of the first fix from its GPS week and time of week (None without a
    plausible week: logs before the receiver had the week number)."""
    from ...geo.magfield import decimal_year_from_gps

    ok = gps_time[np.isfinite(gps_time) & (gps_time > 1500 * 604800.0)]  # after 2008
    return None if ok.size == 0 else round(float(decimal_year_from_gps(float(ok[0]))), 4)


@dataclass(frozen=True)
class Fixes:
    """The usable 3-D fixes of GPS instance 0, stamped on the boot clock."""

    t: np.ndarray  # boot-clock stamps [s] (GPS time mapped by ``clock_fit``, or receipt)
    gps_time: np.ndarray  # GPS seconds (week·604800 + time of week)
    lla: np.ndarray
    vel_n: np.ndarray | None
    pos_sd: np.ndarray
    vel_sd: np.ndarray | None
    clock_fit: ClockFit | None


def read_gnss(msgs: dict[str, list[dict[str, Any]]], name: str, report: Report) -> Fixes:
    """3-D fixes of ``GPS`` (instance 0) with their sigmas (``ardupilot`` module docstring)."""
    gps_rows = [r for r in msgs["GPS"] if instance0(r)]
    if not gps_rows:
        raise ValueError(f"{name}: DataFlash log has no GPS records")
    status = col(gps_rows, "Status")
    lat = col(gps_rows, "Lat")
    lon = col(gps_rows, "Lng")
    alt = col(gps_rows, "Alt")
    spd = col(gps_rows, "Spd")
    crs = col(gps_rows, "GCrs")
    vz = col(gps_rows, "VZ")
    hdop = col(gps_rows, "HDop")
    if "T" in gps_rows[0]:
        t_recv = col(gps_rows, "T") * 1e-3
    else:
        t_recv = np.array([time_s(r) for r in gps_rows])
    week = col(gps_rows, "Week", "GWk")
    tow_ms = col(gps_rows, "TimeMS", "GMS") if "T" in gps_rows[0] else col(gps_rows, "GMS")
    gps_time = week * 604800.0 + tow_ms * 1e-3

    m = status >= 3
    report.drop("gnss", "no 3-D fix (Status < 3)", int((~m).sum()))
    bad_pos = ~finite_rows(np.column_stack([lat, lon, alt])) | ((lat == 0) & (lon == 0))
    report.drop("gnss", "invalid position", int((m & bad_pos).sum()))
    m &= ~bad_pos
    if m.sum() < 2:
        raise ValueError(f"{name}: no GNSS 3-D fixes in the log")
    idx = np.flatnonzero(m)
    gtime = gps_time[idx]
    # the same fix logged twice (same GPS time) is a duplicate, whatever its receipt stamp
    clock_fit: ClockFit | None
    if np.all(np.isfinite(gtime)):
        keep = monotonic_mask(gtime, "gnss", report)
        idx, gtime = idx[keep], gtime[keep]
        t_gnss, clock_fit = gnss_boot_time(t_recv[idx], gtime, report)
    else:
        clock_fit = None
        keep = monotonic_mask(t_recv[idx], "gnss", report)
        idx = idx[keep]
        t_gnss = t_recv[idx]
        report.notes.append("GNSS stamped with receipt time (GPS time missing)")
    lla = np.column_stack([lat[idx] * DEG, lon[idx] * DEG, alt[idx]])
    vel_n: np.ndarray | None = np.column_stack(
        [spd[idx] * np.cos(crs[idx] * DEG), spd[idx] * np.sin(crs[idx] * DEG), vz[idx]])
    pos_sd, vel_sd = gnss_sigmas(msgs["GPA"] or msgs["UBX3"], t_recv[idx], hdop[idx], report)
    if not np.all(np.isfinite(vel_n)):
        report.notes.append("GNSS velocity incomplete in the log: velocity not used")
        vel_n = vel_sd = None
    return Fixes(t_gnss, gtime, lla, vel_n, pos_sd, vel_sd, clock_fit)


def choose_clock(clock: str, fixes: Fixes, t_ref: float, report: Report) -> dict[str, Any]:
    """``meta["clock"]``: boot time, or boot time re-expressed in GPS seconds (module
    docstring, Clock); its ``basis`` starts with "GPS" when the streams are to be re-stamped."""
    clock_meta: dict[str, Any] = {"basis": "autopilot boot time [s]",
                                  "boot_clock_per_gps_second": report.clock_rate}
    clock_fit = fixes.clock_fit
    if clock_fit is None:
        return clock_meta
    ev = speed_evidence(fixes.t, fixes.gps_time, fixes.lla, fixes.vel_n)
    clock_meta["fit"] = {"offset_s": clock_fit.offset, "receipt_jitter_sd_s": clock_fit.sd,
                         "receipts_off_fit": clock_fit.n_outliers}
    clock_meta["evidence"] = ev or {}
    r = clock_fit.ratio
    off = abs(r - 1.0) > CLOCK_RATIO_TOL
    if clock == "gps" or (clock == "auto" and off):
        clock_meta["basis"] = "GPS time [s] (boot clock rescaled)"
        clock_meta["t_ref_s"] = t_ref
        report.repair("clock", "boot-clock stamps rescaled to GPS seconds "
                      "(t = t_ref + (t_boot - t_ref)/r)", 1)
        report.notes.append(
            f"CLOCK REPAIRED: the boot clock advanced {r:.5f} s per GPS second "
            f"({(r - 1) * 100:+.2f} %); IMU, baro, GNSS and onboard stamps are rescaled to "
            f"GPS seconds keeping t = {t_ref:.3f} s fixed (the raw boot clock: Python "
            "vnav_graph.io.readers.ardupilot.read_dataflash(path, clock='boot'))")
    elif off:
        report.notes.append(
            f"WARNING: the boot clock advanced {r:.5f} s per GPS second "
            f"({(r - 1) * 100:+.2f} %); streams kept on the boot clock (read_dataflash "
            f"clock='boot'): IMU "
            "intervals are then off by this factor if GPS time is right")
    return clock_meta


def gnss_sigmas(gpa_rows: list[dict[str, Any]], t_fix: np.ndarray, hdop: np.ndarray,
                 report: Report) -> tuple[np.ndarray, np.ndarray]:
    n = t_fix.size
    gpa = [r for r in gpa_rows if instance0(r)]
    acc_name = "HAcc/VAcc" if gpa and "VAcc" in gpa[0] else "hAcc/vAcc"
    if gpa and acc_name.split("/")[1] in gpa[0]:
        t_gpa = np.array([time_s(r) for r in gpa])
        hacc, vacc, sacc = (col(gpa, k, k[0].lower() + k[1:]) for k in ("HAcc", "VAcc", "SAcc"))
        j = np.clip(np.searchsorted(t_gpa, t_fix), 0, len(gpa) - 1)
        near = np.abs(t_gpa[j] - t_fix) < 0.1
        sh = np.where(near, hacc[j], np.nan)
        sv = np.where(near, vacc[j], np.nan)
        ss = np.where(near, sacc[j], np.nan)
    else:
        sh = sv = ss = np.full(n, np.nan)
    bad_hdop = ~np.isfinite(hdop) | (hdop <= 0) | (hdop > 50)
    report.repair("gnss", "HDop invalid: default sigma 2.5 m used", int(bad_hdop.sum()))
    sh_dop = np.where(bad_hdop, 2.5, HDOP_UERE_M * hdop)
    use_dop = ~(np.isfinite(sh) & (sh > 0))
    sh = np.maximum(np.where(use_dop, sh_dop, sh), SD_FLOOR_H_M)
    sv = np.maximum(np.where(~np.isfinite(sv) | (sv <= 0), VDOP_OVER_HDOP * sh, sv),
                    SD_FLOOR_V_M)
    report.notes.append(
        "GNSS sigmas from " + (f"receiver {acc_name} ({int((~use_dop).sum())} fixes)"
                               if not use_dop.all() else
                               f"HDop x {HDOP_UERE_M} m (vertical x {VDOP_OVER_HDOP})"))
    ss_ok = np.isfinite(ss) & (ss > 0)
    vel_sd = np.column_stack([
        np.where(ss_ok, ss, DEFAULT_VEL_SD[0]), np.where(ss_ok, ss, DEFAULT_VEL_SD[1]),
        np.where(ss_ok, 1.5 * ss, DEFAULT_VEL_SD[2])])
    return np.column_stack([sh, sh, sv]), vel_sd
