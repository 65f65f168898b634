"""Shared cleaning steps of the log readers: time-stamp repair, gap detection, baro datum,
GNSS sigma floors and the report that every reader writes into ``Drive.meta``.

Every repair is counted in a :class:`Report`; nothing is changed silently (types.py only
validates, readers repair and report).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ...geo.atmosphere import isa_altitude
from ...types.streams import BoolArray, FloatArray, MagStream

# A gap is reported when consecutive samples are further apart than this many median steps.
GAP_FACTOR = 5.0
# Window after the first valid fix over which the baro datum is aligned to GNSS height [s].
BARO_ALIGN_WINDOW_S = 10.0


@dataclass
class Report:
    """What a reader dropped and repaired, per stream and reason (goes to ``Drive.meta``)."""

    dropped: dict[str, dict[str, int]] = field(default_factory=dict)
    repaired: dict[str, dict[str, int]] = field(default_factory=dict)
    gaps: dict[str, list[list[float]]] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)  # → meta["warnings"] (repairs to know)
    clock_rate: float | None = None  # receiver-vs-logger clock ratio where measured

    def drop(self, stream: str, reason: str, count: int) -> None:
        if count:
            d = self.dropped.setdefault(stream, {})
            d[reason] = d.get(reason, 0) + int(count)

    def repair(self, stream: str, reason: str, count: int) -> None:
        if count:
            d = self.repaired.setdefault(stream, {})
            d[reason] = d.get(reason, 0) + int(count)

    def as_meta(self) -> dict[str, Any]:
        out: dict[str, Any] = {"dropped": self.dropped, "repaired": self.repaired,
                               "gaps": self.gaps, "notes": list(self.notes)}
        if self.warnings:
            out["warnings"] = list(self.warnings)
        return out


def imu_in_si(t: FloatArray, gyro: FloatArray, accel: FloatArray,
              report: Report) -> tuple[FloatArray, FloatArray]:
    """Gyro [rad/s] and specific force [m/s²] of raw IMU samples whose units
    ``io.imu_units.unit_fixes`` decided on the raw values (deg/s, g, g·g0): converted,
    counted under ``meta["repaired"]["imu"]`` and warned. Every reader calls it before any
    range screen of its own, so a sample in the wrong unit is converted, not dropped."""
    from ..imu_units import unit_fixes

    gyro = np.asarray(gyro, dtype=float)
    accel = np.asarray(accel, dtype=float)
    for fix in unit_fixes(t, gyro, accel):
        if fix.field == "gyro":
            gyro = gyro * fix.factor
        else:
            accel = accel * fix.factor
        report.repair("imu", fix.reason, int(np.asarray(t).size))
        report.warnings.append(fix.warning)
    return gyro, accel


def monotonic_mask(t: FloatArray, stream: str, report: Report) -> BoolArray:
    """Mask keeping the samples whose stamp is strictly later than every earlier kept one.

    Duplicated stamps (``t[k] == t_last``) and stamps that jump backwards are dropped and
    counted separately; NaN stamps are dropped as well.
    """
    t = np.asarray(t, dtype=float)
    keep = np.zeros(t.size, dtype=bool)
    last = -np.inf
    n_dup = n_back = n_nan = 0
    for k in range(t.size):
        tk = t[k]
        if not np.isfinite(tk):
            n_nan += 1
        elif tk > last:
            keep[k] = True
            last = tk
        elif tk == last:
            n_dup += 1
        else:
            n_back += 1
    report.drop(stream, "duplicated time stamp", n_dup)
    report.drop(stream, "time stamp not increasing", n_back)
    report.drop(stream, "time stamp not finite", n_nan)
    return keep


def find_gaps(t: FloatArray, stream: str, report: Report,
              nominal_dt: float | None = None) -> None:
    """Record logging gaps (dt > GAP_FACTOR x median dt) as ``[start_s, length_s]`` pairs."""
    if t.size < 3:
        return
    dt = np.diff(t)
    ref = float(np.median(dt)) if nominal_dt is None else nominal_dt
    idx = np.flatnonzero(dt > GAP_FACTOR * ref)
    if idx.size:
        report.gaps[stream] = [[float(t[i]), float(dt[i])] for i in idx]


def finite_rows(*arrays: FloatArray) -> BoolArray:
    """True where every given array (1-D or 2-D) is finite in that row."""
    m = np.ones(np.asarray(arrays[0]).shape[0], dtype=bool)
    for a in arrays:
        a = np.asarray(a, dtype=float)
        m &= np.all(np.isfinite(a.reshape(a.shape[0], -1)), axis=1)
    return m


def baro_alt_aligned(t_baro: FloatArray, alt_raw: FloatArray, t_gnss: FloatArray,
                     h_gnss: FloatArray) -> tuple[FloatArray, float]:
    """Shift a relative barometric altitude into the GNSS height datum.

    ``alt = alt_raw + c`` with ``c = median(h_gnss − interp(alt_raw))`` over the GNSS fixes in
    the first ``BARO_ALIGN_WINDOW_S`` seconds after the first fix. This fixes only the constant
    datum (so the baro bias b(t) of the docs/design.md model starts near zero); scale, latency and
    the drifting bias are left for the estimators.

    Returns
    -------
    alt : (N,) [m, +up] in the GNSS height reference
    offset : c [m]
    """
    m = t_gnss <= t_gnss[0] + BARO_ALIGN_WINDOW_S
    m &= (t_gnss >= t_baro[0]) & (t_gnss <= t_baro[-1])
    if not np.any(m):  # no overlap at the start: use every overlapping fix
        m = (t_gnss >= t_baro[0]) & (t_gnss <= t_baro[-1])
    if not np.any(m):
        raise ValueError("baro and GNSS do not overlap in time; cannot align the baro datum")
    c = float(np.median(h_gnss[m] - np.interp(t_gnss[m], t_baro, alt_raw)))
    return alt_raw + c, c


def pressure_altitude(pressure_pa: FloatArray) -> FloatArray:
    """ISA pressure altitude [m] of static pressure [Pa] (vnav_graph.geo.atmosphere)."""
    return isa_altitude(pressure_pa)


def valid_pressure(p: FloatArray) -> BoolArray:
    """Physically plausible static pressure [Pa] (same range as ``BaroStream``)."""
    return np.isfinite(p) & (p >= 1.0e3) & (p <= 1.2e5)


def onboard_block(t: FloatArray, alt: FloatArray, name: str, offset_m: float,
                  reference: str) -> dict[str, Any]:
    """The ``Drive.meta["onboard"]`` block: the autopilot's own altitude estimate."""
    return {"t": [float(x) for x in t], "alt": [float(x) for x in alt], "name": name,
            "offset_m": float(offset_m), "reference": reference}


# Clock ratios within this fraction of 1 are treated as "same clock" (a crystal is good to
# ~1e-4; a boot clock off by several % is a board's fault, docs/real_logs.md "ArduPilot
# DataFlash").
CLOCK_RATIO_TOL = 1e-3


@dataclass
class ClockFit:
    """Robust straight line ``t_local ≈ offset + ratio·(t_gps − t_gps0)``.

    ``ratio`` is the local (logger) clock's advance per GPS second, ``sd`` the residual sd of
    the inliers [s] (receipt jitter), ``n_outliers`` the stamps off the line by more than the
    inlier threshold.
    """

    offset: float
    ratio: float
    t_gps0: float
    sd: float
    n_outliers: int

    def local_of_gps(self, t_gps: FloatArray) -> FloatArray:
        """Local-clock stamp of GPS times [s]."""
        return self.offset + self.ratio * (np.asarray(t_gps, dtype=float) - self.t_gps0)


def fit_clock(t_local: FloatArray, t_gps: FloatArray, inlier_s: float = 0.1) -> ClockFit:
    """Fit the logger clock against GPS time from receipt stamps of GNSS fixes.

    Least squares of ``t_local`` on ``x = t_gps − t_gps[0]`` with an intercept, refitted
    twice on the stamps within ``inlier_s`` of the line (receipt delays of a busy logger are
    one-sided outliers).

    Parameters
    ----------
    t_local : (N,) receipt stamps on the logger clock [s]
    t_gps : (N,) GPS time of the same fixes [s] (any origin), N ≥ 5

    Raises
    ------
    ValueError
        Fewer than 5 stamps on the line.
    """
    t_local = np.asarray(t_local, dtype=float)
    x = np.asarray(t_gps, dtype=float) - float(t_gps[0])
    inl = np.ones(x.size, dtype=bool)
    for _ in range(3):
        if inl.sum() < 5:
            raise ValueError("GNSS receipt stamps do not follow GPS time (corrupt GPS records?)")
        a_mat = np.column_stack([np.ones(int(inl.sum())), x[inl]])
        coef, *_ = np.linalg.lstsq(a_mat, t_local[inl], rcond=None)
        res = t_local - (coef[0] + coef[1] * x)
        inl = np.abs(res) < inlier_s
    if inl.sum() < 5:
        raise ValueError("GNSS receipt stamps do not follow GPS time (corrupt GPS records?)")
    return ClockFit(float(coef[0]), float(coef[1]), float(t_gps[0]), float(np.std(res[inl])),
                    int((~inl).sum()))


def local_to_gps_seconds(t_local: FloatArray, ratio: float, t_ref: float) -> FloatArray:
    """Re-express logger-clock stamps in GPS seconds, keeping ``t_ref`` fixed.

    ``t = t_ref + (t_local − t_ref) / ratio``, where ``ratio`` is the logger clock's advance
    per GPS second (:func:`fit_clock`). Intervals become GPS-time intervals; the stamp
    ``t_ref`` (the first IMU sample) keeps its value so the drive's time axis starts where
    it did. A GNSS fix at GPS time g then sits at ``t_ref + (offset − t_ref)/ratio + (g − g0)``:
    exactly GPS time up to one constant.
    """
    return t_ref + (np.asarray(t_local, dtype=float) - t_ref) / ratio


# Largest plausible |component| of a magnetometer sample [µT] (``MagStream``'s own limit).
MAG_MAX_UT = 1000.0


def mag_stream(t: FloatArray, field_ut: FloatArray, sd_ut: float, report: Report,
               t_imu: FloatArray, source: str) -> MagStream | None:
    """Cleaned :class:`~vnav_graph.types.MagStream`, or None when nothing usable is left.

    Parameters
    ----------
    t : (N,) stamps already on the drive's clock [s]
    field_ut : (N, 3) flux density in body FRD [µT]
    sd_ut : white-noise σ per axis [µT] (the reader's documented default)
    t_imu : the IMU stamps [s]; a stream that does not overlap them is not used
    source : what the samples are (for the notes), e.g. ``"MAG"``

    Dropped and counted under ``meta["dropped"]["mag"]``: non-finite samples, samples that
    are exactly (0, 0, 0) (a logger writing a compass that is absent or not yet started),
    components above ``MAG_MAX_UT``, duplicated or backward stamps.
    """
    t = np.asarray(t, dtype=float)
    f = np.asarray(field_ut, dtype=float).reshape(-1, 3)
    ok = finite_rows(f) & np.isfinite(t)
    report.drop("mag", "non-finite sample", int((~ok).sum()))
    zero = ok & np.all(f == 0.0, axis=1)
    report.drop("mag", "all-zero sample (no compass)", int(zero.sum()))
    ok &= ~zero
    big = ok & (np.max(np.abs(np.nan_to_num(f)), axis=1) > MAG_MAX_UT)
    report.drop("mag", f"outside physical range (> {MAG_MAX_UT:g} µT)", int(big.sum()))
    ok &= ~big
    t, f = t[ok], f[ok]
    keep = monotonic_mask(t, "mag", report)
    t, f = t[keep], f[keep]
    if t.size < 2 or t[-1] < t_imu[0] or t[0] > t_imu[-1]:
        why = "does not overlap the IMU" if t.size >= 2 else f"{t.size} valid samples"
        report.notes.append(f"{source}: {why}: drive has no magnetometer")
        return None
    find_gaps(t, "mag", report)
    report.notes.append(f"magnetometer from {source}: {t.size} samples, body FRD [µT], "
                        f"sd {sd_ut:g} µT per axis (reader default)")
    return MagStream(t, f, sd_ut)


def decimal_year_unix(seconds: Any) -> float | None:
    """Decimal year of the first plausible Unix time (2000–2100) in ``seconds``, or None: the
    date of the Earth's field for ``geo.magfield`` (``meta["decimal_year"]``)."""
    from datetime import UTC, datetime

    from ...geo.magfield import decimal_year_from_datetime

    v = np.asarray(seconds, dtype=float).ravel()
    ok = v[np.isfinite(v) & (v > 946684800.0) & (v < 4102444800.0)]
    if ok.size == 0:
        return None
    return round(float(decimal_year_from_datetime(datetime.fromtimestamp(float(ok[0]), UTC))), 4)


GPS_EPOCH_UNIX_S = 315964800.0  # 1980-01-06T00:00:00Z
# GPS - UTC [s] from the Unix time each leap second took effect (13 s before 2006)
_GPS_LEAPS = ((1136073600.0, 14.0), (1230768000.0, 15.0), (1341100800.0, 16.0),
              (1435708800.0, 17.0), (1483228800.0, 18.0))


def gps_to_unix(gps_s: Any) -> np.ndarray:
    """GPS seconds (week * 604800 + time of week) → Unix time [s, UTC]."""
    u = np.asarray(gps_s, dtype=float) + GPS_EPOCH_UNIX_S
    leap = np.full(u.shape, 13.0)
    for start, n in _GPS_LEAPS:
        leap = np.where(u - n >= start, n, leap)
    return u - leap


def t0_unix_meta(unix_s: Any, t: Any) -> dict[str, float]:
    """``{"t0_unix_s": x}``: the Unix time [s, UTC] of t = 0 on the drive's clock, the median
    of (absolute time - drive-clock stamp) over the samples that have both; {} without a
    plausible Unix time (1973..2286). Export uses it for UTC time stamps (GPX)."""
    u, tt = np.asarray(unix_s, dtype=float), np.asarray(t, dtype=float)
    d = (u - tt)[np.isfinite(u) & np.isfinite(tt) & (u > 0)]
    if d.size == 0:
        return {}
    t0 = float(np.median(d))
    if not 1e8 <= t0 + float(np.nanmax(tt)) < 1e10:
        return {}
    return {"t0_unix_s": t0}


def year_meta(year: float | None) -> dict[str, float]:
    """``{"decimal_year": year}``, or {} when the log has no date."""
    return {} if year is None else {"decimal_year": year}

