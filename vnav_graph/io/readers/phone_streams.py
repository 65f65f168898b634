"""Sensor Logger (phone) samples → streams, shared by the folder and the merged-CSV readers.

``mounting_rotation`` and ``aligned_imu`` turn the phone's axes into a forward-right-down
body frame from the mean specific force (the conventions and their checks are in the
``sensorlogger`` module docstring); ``gnss_from_fixes``, ``baro_from_pressure`` and
``mag_from_phone`` build the GNSS, baro and magnetometer streams with their sigmas and
drops; ``time_column``, ``epoch_scale`` and ``time_meta`` read the absolute time column.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ...types.streams import BaroStream, GnssStream, ImuStream, MagStream
from ._common import (
    Report,
    baro_alt_aligned,
    decimal_year_unix,
    find_gaps,
    finite_rows,
    imu_in_si,
    mag_stream,
    monotonic_mask,
    pressure_altitude,
    t0_unix_meta,
    valid_pressure,
    year_meta,
)

G0 = 9.80665
DEG = np.pi / 180.0
SD_FLOOR_H_M = 0.5
SD_FLOOR_V_M = 1.0
R68_OVER_SIGMA_2D = 1.5
MAG_SD_UT = 5.0  # phone magnetometer white-noise σ per axis [µT] (``sensorlogger`` docstring)


# --------------------------------------------------------------------- mounting alignment
def mounting_rotation(f_d_mean: np.ndarray) -> np.ndarray:
    """R_bd (3×3) of the documented phone mounting alignment from the mean specific force
    f_d_mean (3,) in device axes [m/s²]; see the ``sensorlogger`` module docstring."""
    n = float(np.linalg.norm(f_d_mean))
    if not n > 0.5 * G0:
        raise ValueError(f"mean specific force {n:.2f} m/s^2 is far from 1 g: cannot find the "
                         "phone's down axis (accelerometer unit or sign wrong?)")
    z_b = -f_d_mean / n
    for cand in (np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, -1.0])):
        h = cand - np.dot(cand, z_b) * z_b
        if np.linalg.norm(h) > 0.5:  # the candidate is more than 30° away from the vertical
            break
    x_b = h / np.linalg.norm(h)
    y_b = np.cross(z_b, x_b)
    return np.vstack([x_b, y_b, z_b])


def aligned_imu(t: np.ndarray, f_d: np.ndarray, w_d: np.ndarray,
                 report: Report) -> tuple[ImuStream, dict[str, Any]]:
    ok = finite_rows(f_d, w_d)
    report.drop("imu", "non-finite sample", int((~ok).sum()))
    t, f_d, w_d = t[ok], f_d[ok], w_d[ok]
    w_d, f_d = imu_in_si(t, w_d, f_d, report)  # units before the mounting's 1 g test
    keep = monotonic_mask(t, "imu", report)
    t, f_d, w_d = t[keep], f_d[keep], w_d[keep]
    if t.size < 10:
        raise ValueError(f"only {t.size} valid IMU samples")
    find_gaps(t, "imu", report)
    r_bd = mounting_rotation(f_d.mean(axis=0))
    mount = {"mat_bd": r_bd.tolist(),
             "method": "z_b = -mean specific force; x_b = horizontal part of the phone's top "
                       "(or back) axis; device axes x right, y top, z out of screen"}
    return ImuStream(t, w_d @ r_bd.T, f_d @ r_bd.T), mount


def mag_from_phone(t: np.ndarray, mag_d: np.ndarray, mount: dict[str, Any], imu: ImuStream,
         report: Report, source: str) -> MagStream | None:
    """Phone magnetometer [µT, device axes] → MagStream in b with the IMU's mounting matrix
    (``B_b = R_bd B_d``); cleaning by :func:`._common.mag_stream`."""
    r_bd = np.asarray(mount["mat_bd"], dtype=float)
    return mag_stream(t, mag_d @ r_bd.T, MAG_SD_UT, report, imu.t, source)


# ------------------------------------------------------------------------------- GNSS
def gnss_from_fixes(t: np.ndarray, lat_deg: np.ndarray, lon_deg: np.ndarray, h: np.ndarray,
          hacc: np.ndarray, vacc: np.ndarray, report: Report) -> GnssStream:
    pos = np.column_stack([lat_deg, lon_deg, h])
    t_ok = np.isfinite(t)  # rows already rejected by the caller carry NaN stamps
    ok = finite_rows(pos) & t_ok
    report.drop("gnss", "missing position", int((t_ok & ~ok).sum()))
    bad_acc = ok & ~((hacc > 0) & (vacc > 0))  # NaN compares False → dropped too
    report.drop("gnss", "accuracy missing or invalid (<= 0)", int(bad_acc.sum()))
    ok &= ~bad_acc
    zero = ok & (lat_deg == 0) & (lon_deg == 0)
    report.drop("gnss", "position (0, 0)", int(zero.sum()))
    ok &= ~zero
    idx = np.flatnonzero(ok)
    keep = monotonic_mask(t[idx], "gnss", report)
    idx = idx[keep]
    if idx.size < 2:
        raise ValueError("fewer than 2 valid GNSS fixes")
    tg = t[idx]
    find_gaps(tg, "gnss", report)
    lla = np.column_stack([lat_deg[idx] * DEG, lon_deg[idx] * DEG, h[idx]])
    sh = np.maximum(hacc[idx] / R68_OVER_SIGMA_2D, SD_FLOOR_H_M)
    sv = np.maximum(vacc[idx], SD_FLOOR_V_M)
    return GnssStream(tg, lla, np.column_stack([sh, sh, sv]))


def baro_from_pressure(t: np.ndarray, p_hpa: np.ndarray, gnss: GnssStream,
          report: Report) -> tuple[BaroStream | None, float | None]:
    p = p_hpa * 100.0  # hPa → Pa
    ok = valid_pressure(p) & np.isfinite(t)
    report.drop("baro", "missing or implausible pressure", int((~ok).sum()))
    t, p = t[ok], p[ok]
    keep = monotonic_mask(t, "baro", report)
    t, p = t[keep], p[keep]
    if t.size < 2:
        report.notes.append("fewer than 2 valid pressure samples: drive has no barometer")
        return None, None
    find_gaps(t, "baro", report)
    alt, off = baro_alt_aligned(t, pressure_altitude(p), gnss.t, gnss.lla[:, 2])
    report.notes.append(f"baro alt = ISA pressure altitude + {off:.2f} m (datum aligned to GNSS "
                        "height over the first 10 s of fixes); pressure converted hPa -> Pa")
    return BaroStream(t, p, alt), off


# Unix epochs of 1973..2286 in each unit span [1e8, 1e10) s; the decade tells the unit (a
# single "> 1e14 means ns" rule read µs as ns and ms as s). Below 1e8: plain seconds (a
# relative clock); the sanity checks refuse it when its row interval is implausible.
EPOCH_UNITS = ((0.0, 1e8, 1.0), (1e8, 1e10, 1.0), (1e11, 1e13, 1e-3), (1e14, 1e16, 1e-6),
                (1e17, 1e19, 1e-9))


def epoch_scale(median: float, path: Path) -> float:
    """Seconds per unit of a numeric epoch column, told from its magnitude."""
    for lo, hi, scale in EPOCH_UNITS:
        if lo <= abs(median) < hi:
            return scale
    raise ValueError(f"{path.name}: numeric time column (median {median:.6g}) is not a Unix "
                     "epoch in s, ms, µs or ns")


def time_column(col: pd.Series, path: Path) -> tuple[np.ndarray, float] | None:
    """Stamps [s] of a time column and the Unix time [s] of their zero: a numeric epoch in
    s, ms, µs or ns (Sensor Logger: ns; absolute, zero 0; ``ValueError`` when its magnitude
    is none of these) or ISO UTC text (seconds since its first stamp, exact; None when more
    than half of it does not parse)."""
    num = pd.to_numeric(col, errors="coerce")
    if num.notna().mean() > 0.9:
        v = num.to_numpy(dtype=float)
        return v * epoch_scale(float(np.nanmedian(v)), path), 0.0
    ts = pd.to_datetime(col, errors="coerce", utc=True)
    if ts.isna().mean() > 0.5:
        return None
    first = ts.dropna().iloc[0]
    return (ts - first).dt.total_seconds().to_numpy(dtype=float), float(first.timestamp())


def time_meta(col: pd.Series | None, t: np.ndarray, path: Path,
               shift: float = 0.0) -> dict[str, float]:
    """What a Unix-epoch or ISO time column beside the stamps ``t`` tells, parsed once:
    ``decimal_year`` of its first stamp (the date of the Earth's field for the magnetometer)
    and ``t0_unix_s`` (``t0_unix_meta``; ``shift``: 0.5 s for the merged CSV's bin centres);
    {} when it holds no absolute time."""
    if col is None:
        return {}
    try:
        tc = time_column(col, path)
    except ValueError:
        return {}
    if tc is None:
        return {}
    return {**year_meta(decimal_year_unix(tc[0] + tc[1])),
            **t0_unix_meta(tc[0] + tc[1] + shift, t)}
