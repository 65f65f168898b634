"""PX4 ULog (``.ulg``) → :class:`~vnav_graph.types.Drive`, read with ``pyulog``.

Topics used (first instance, ``multi_id`` 0)
---------------------------------------------
- ``sensor_combined``: ``timestamp`` [µs], ``gyro_rad[0..2]`` [rad/s],
  ``accelerometer_m_s2[0..2]`` [m/s², gravity included]. PX4 logs them in the body frame,
  forward-right-down (after the board rotation), so no axis change is applied.
- ``sensor_gps`` (newer) or ``vehicle_gps_position`` (older): ``fix_type`` (≥ 3 kept),
  ``lat``/``lon`` [1e-7 deg] or ``latitude_deg``/``longitude_deg``, ``alt_ellipsoid`` [mm] or
  ``altitude_ellipsoid_m`` (used when present), else ``alt`` [mm] / ``altitude_msl_m``;
  ``eph``/``epv`` [m] as σ_h/σ_v (floored at 0.5 / 1.0 m), ``vel_n/e/d_m_s`` with
  ``vel_ned_valid``, ``s_variance_m_s`` [m/s] as velocity σ. Stamp: ``timestamp_sample`` when
  present, else ``timestamp``.
- ``vehicle_air_data``: ``baro_pressure_pa`` [Pa] (``timestamp_sample`` when present);
  fallback ``sensor_baro`` ``pressure`` (hPa in old firmware, Pa in new — told apart by size).
- Onboard estimate: ``vehicle_local_position`` ``z`` [m, down, relative to ``ref_alt``].
- Magnetometer: ``vehicle_magnetometer`` ``magnetometer_ga[0..2]`` (the calibrated, selected
  compass) preferred, else ``sensor_mag`` ``x, y, z`` (old firmware); both in Gauss, × 100 →
  µT, body frame FRD (PX4 applies the compass rotation and calibration before logging).
  Stamp ``timestamp_sample`` when present, else ``timestamp``. Non-finite, exactly (0, 0, 0)
  and out-of-range samples are dropped and counted; none left → ``Drive.mag`` is None.
  σ = ``MAG_SD_UT`` (5 µT per axis, what PX4's own EKF2 assumes, ``EKF2_MAG_NOISE`` = 0.05 Ga:
  sensor noise of a few 0.1 µT plus multirotor motor interference and residual iron).

Clock: PX4 boot time in seconds. Baro ``alt`` is the ISA pressure altitude shifted to the GNSS
height over the first 10 s of fixes; the onboard altitude −z gets the same kind of offset.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ...types import Drive
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
    onboard_block,
    pressure_altitude,
    t0_unix_meta,
    valid_pressure,
    year_meta,
)

MAGIC = b"ULog\x01\x12\x35"
DEG = np.pi / 180.0
SD_FLOOR_H_M = 0.5
SD_FLOOR_V_M = 1.0
DEFAULT_VEL_SD = 0.3  # m/s
GAUSS_UT = 100.0  # µT per Gauss
MAG_SD_UT = 5.0  # magnetometer white-noise σ per axis [µT] (module docstring)
_TOPICS = ["sensor_combined", "sensor_gps", "vehicle_gps_position", "vehicle_air_data",
           "sensor_baro", "vehicle_local_position", "vehicle_magnetometer", "sensor_mag"]


def is_ulog(head: bytes) -> bool:
    return head[:7] == MAGIC


def _topic(ulog: Any, name: str) -> dict[str, np.ndarray] | None:
    for d in ulog.data_list:
        if d.name == name and d.multi_id == 0:
            return d.data
    return None


def _f(d: dict[str, np.ndarray], *names: str) -> np.ndarray | None:
    for n in names:
        if n in d:
            return np.asarray(d[n], dtype=float)
    return None


def _stamp(d: dict[str, np.ndarray]) -> np.ndarray:
    ts = _f(d, "timestamp_sample")
    if ts is None or not np.all(ts > 0):
        ts = _f(d, "timestamp")
    assert ts is not None
    return ts * 1e-6


# MAVLink MAV_TYPE → the vehicle types ``Drive.meta["vehicle"]`` names (as the ArduPilot
# reader does from its firmware banner)
_MAV_TYPES = {1: "fixed-wing", 2: "multirotor", 13: "multirotor", 14: "multirotor",
              15: "multirotor", 29: "multirotor", 3: "helicopter", 4: "helicopter",
              10: "ground", 19: "vtol", 20: "vtol", 21: "vtol", 22: "vtol", 23: "vtol"}


def vehicle_of_mav_type(mav_type: Any) -> str:
    """The vehicle type of a PX4 log from its ``MAV_TYPE`` parameter (quadrotor 2,
    hexa 13, octo 14, tri 15, dodeca 29: "multirotor"; 1 "fixed-wing"; 3, 4 "helicopter";
    10 "ground"; 19–23 "vtol"), "unknown" otherwise or without it."""
    try:
        return _MAV_TYPES.get(int(mav_type), "unknown")
    except (TypeError, ValueError):
        return "unknown"


def read_ulog(path: str | Path) -> Drive:
    """Read a PX4 ULog into a Drive (see the module docstring)."""
    from pyulog import ULog

    path = Path(path)
    report = Report()
    try:
        ulog = ULog(str(path), _TOPICS)
    except Exception as exc:  # pyulog raises assorted errors on corrupt files
        raise ValueError(f"{path.name}: cannot parse ULog ({type(exc).__name__}: {exc})") from None
    if getattr(ulog, "file_corruption", False):
        report.notes.append("pyulog reported file corruption: damaged records skipped")
        report.drop("log", "corrupt records skipped (pyulog reported file corruption)", 1)

    sc = _topic(ulog, "sensor_combined")
    if sc is None or len(sc.get("timestamp", [])) < 10:
        raise ValueError(f"{path.name}: ULog has no sensor_combined IMU data")
    t_imu = _stamp(sc)
    gyro = np.column_stack([_f(sc, f"gyro_rad[{i}]") for i in range(3)])
    acc = np.column_stack([_f(sc, f"accelerometer_m_s2[{i}]") for i in range(3)])
    ok = finite_rows(gyro, acc)
    report.drop("imu", "non-finite sample", int((~ok).sum()))
    t_imu, gyro, acc = t_imu[ok], gyro[ok], acc[ok]
    gyro, acc = imu_in_si(t_imu, gyro, acc, report)
    keep = monotonic_mask(t_imu, "imu", report)
    t_imu, gyro, acc = t_imu[keep], gyro[keep], acc[keep]
    if t_imu.size < 10:
        raise ValueError(f"{path.name}: only {t_imu.size} usable sensor_combined samples "
                         "(NaN values or time stamps not increasing)")
    find_gaps(t_imu, "imu", report)

    gnss, href = _read_gps(ulog, path, report)
    baro, off = _read_baro(ulog, gnss, report)
    mag = _read_mag(ulog, report, t_imu)
    meta: dict[str, Any] = {
        **_gps_time_meta(ulog),
        "source": "log", "name": path.stem, "format": "px4-ulog",
        "clock": "PX4 boot time [s]",
        "imu_frame": "PX4 body frame (forward-right-down), used as logged",
        "height_reference": href, "baro_alt_offset_m": off, "averaged_1s": False,
        "vehicle": vehicle_of_mav_type(ulog.initial_parameters.get("MAV_TYPE")),
    }
    lp = _topic(ulog, "vehicle_local_position")
    if lp is not None and "z" in lp:
        t = _stamp(lp)
        h = -np.asarray(lp["z"], dtype=float)
        ok = np.isfinite(t) & np.isfinite(h)
        if "z_valid" in lp:
            ok &= np.asarray(lp["z_valid"]) != 0
        t, h = t[ok], h[ok]
        k = monotonic_mask(t, "onboard", Report())
        if k.sum() >= 2:
            alt, o = baro_alt_aligned(t[k], h[k], gnss.t, gnss.lla[:, 2])
            meta["onboard"] = onboard_block(
                t[k], alt, "vehicle_local_position (PX4 EKF)", o,
                "-z + offset matching the GNSS height over the first 10 s of fixes")
    meta.update(report.as_meta())
    return Drive(ImuStream(t_imu, gyro, acc), gnss, baro, gnss.lla[0].copy(), meta=meta,
                 mag=mag)


def _read_mag(ulog: Any, report: Report, t_imu: np.ndarray) -> MagStream | None:
    """``vehicle_magnetometer`` (else ``sensor_mag``) → MagStream: boot-clock stamps [s],
    field [Gauss] × 100 → µT in body FRD (module docstring)."""
    for name, cols in (("vehicle_magnetometer", [f"magnetometer_ga[{i}]" for i in range(3)]),
                       ("sensor_mag", ["x", "y", "z"])):
        d = _topic(ulog, name)
        if d is not None and all(c in d for c in cols) and len(d.get("timestamp", [])):
            field = np.column_stack([np.asarray(d[c], dtype=float) for c in cols]) * GAUSS_UT
            return mag_stream(_stamp(d), field, MAG_SD_UT, report, t_imu, name)
    report.notes.append("no vehicle_magnetometer / sensor_mag topic: drive has no magnetometer")
    return None


def _gps_time_meta(ulog: Any) -> dict[str, float]:
    """What the receiver's UTC time (``time_utc_usec``, 0 before a fix) tells: the
    ``decimal_year`` for the WMM epoch and ``t0_unix_s`` (``t0_unix_meta``); {} without it."""
    g = _topic(ulog, "sensor_gps") or _topic(ulog, "vehicle_gps_position")
    if g is None or "time_utc_usec" not in g:
        return {}
    unix = np.asarray(g["time_utc_usec"], dtype=float) * 1e-6
    return {**year_meta(decimal_year_unix(unix)), **t0_unix_meta(unix, _stamp(g))}


def _read_gps(ulog: Any, path: Path, report: Report) -> tuple[GnssStream, str]:
    g = _topic(ulog, "sensor_gps")
    if g is None:
        g = _topic(ulog, "vehicle_gps_position")
    if g is None:
        raise ValueError(f"{path.name}: ULog has no sensor_gps / vehicle_gps_position")
    t = _stamp(g)
    lat = _f(g, "latitude_deg")
    lon = _f(g, "longitude_deg")
    if lat is None or lon is None:
        lat, lon = _f(g, "lat") * 1e-7, _f(g, "lon") * 1e-7
    h_ell = _f(g, "altitude_ellipsoid_m")
    if h_ell is None and "alt_ellipsoid" in g:
        h_ell = _f(g, "alt_ellipsoid") * 1e-3
    h_msl = _f(g, "altitude_msl_m")
    if h_msl is None and "alt" in g:
        h_msl = _f(g, "alt") * 1e-3
    if h_ell is not None and np.any(h_ell != 0):
        h, href = h_ell, "ellipsoid"
    elif h_msl is not None:
        h, href = h_msl, "msl"
    else:
        raise ValueError(f"{path.name}: GNSS topic has no altitude field")
    fix = _f(g, "fix_type")
    m = np.ones(t.size, bool) if fix is None else fix >= 3
    report.drop("gnss", "no 3-D fix (fix_type < 3)", int((~m).sum()))
    bad = ~finite_rows(np.column_stack([lat, lon, h])) | ((lat == 0) & (lon == 0))
    report.drop("gnss", "invalid position", int((m & bad).sum()))
    m &= ~bad
    eph, epv = _f(g, "eph"), _f(g, "epv")
    sh = np.maximum(np.nan_to_num(eph, nan=2.5) if eph is not None else 2.5, SD_FLOOR_H_M)
    sv = np.maximum(np.nan_to_num(epv, nan=5.0) if epv is not None else 5.0, SD_FLOOR_V_M)
    sh = np.broadcast_to(sh, t.shape)
    sv = np.broadcast_to(sv, t.shape)
    idx = np.flatnonzero(m)
    idx = idx[monotonic_mask(t[idx], "gnss", report)]
    if idx.size < 2:
        raise ValueError(f"{path.name}: no GNSS 3-D fixes in the log")
    find_gaps(t[idx], "gnss", report)
    lla = np.column_stack([lat[idx] * DEG, lon[idx] * DEG, h[idx]])
    vel = [_f(g, f"vel_{a}_m_s") for a in "ned"]
    vel_n = vel_sd = None
    if all(v is not None for v in vel):
        vn = np.column_stack(vel)[idx]
        valid = _f(g, "vel_ned_valid")
        if np.all(np.isfinite(vn)) and (valid is None or np.all(valid[idx] != 0)):
            s = _f(g, "s_variance_m_s")
            s = np.full(idx.size, DEFAULT_VEL_SD) if s is None else np.where(
                s[idx] > 0, s[idx], DEFAULT_VEL_SD)
            vel_n, vel_sd = vn, np.column_stack([s, s, 1.5 * s])
        else:
            report.notes.append("GNSS velocity not valid on every fix: velocity not used")
    return GnssStream(t[idx], lla, np.column_stack([sh[idx], sh[idx], sv[idx]]), vel_n,
                      vel_sd), href


def _read_baro(ulog: Any, gnss: GnssStream,
               report: Report) -> tuple[BaroStream | None, float | None]:
    ad = _topic(ulog, "vehicle_air_data")
    if ad is not None and "baro_pressure_pa" in ad:
        t, p = _stamp(ad), _f(ad, "baro_pressure_pa")
    else:
        sb = _topic(ulog, "sensor_baro")
        if sb is None or "pressure" not in sb:
            report.notes.append("no baro topic: drive has no barometer")
            return None, None
        t, p = _stamp(sb), _f(sb, "pressure")
        if np.nanmedian(p) < 2000.0:  # old firmware logged hPa (mbar)
            p = p * 100.0
            report.notes.append("sensor_baro pressure in hPa: converted to Pa")
    assert p is not None
    ok = valid_pressure(p)
    report.drop("baro", "missing or implausible pressure", int((~ok).sum()))
    t, p = t[ok], p[ok]
    k = monotonic_mask(t, "baro", report)
    t, p = t[k], p[k]
    if t.size < 2:
        return None, None
    find_gaps(t, "baro", report)
    alt, off = baro_alt_aligned(t, pressure_altitude(p), gnss.t, gnss.lla[:, 2])
    report.notes.append(f"baro alt = ISA pressure altitude + {off:.2f} m (datum aligned to GNSS "
                        "height over the first 10 s of fixes)")
    return BaroStream(t, p, alt), off
