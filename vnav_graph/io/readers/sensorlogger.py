"""Sensor Logger (smartphone app) exports → :class:`~vnav_graph.types.Drive`.

Two layouts are read:

1. **Per-sensor CSV folder** (the app's raw export): one CSV per sensor with columns
   ``time`` [ns since the Unix epoch], ``seconds_elapsed`` [s since the recording start] and
   axis columns named ``x, y, z`` (the file order is ``z, y, x``; columns are read by name).
   The clock is ``seconds_elapsed``. IMU: ``AccelerometerUncalibrated`` (else
   ``Accelerometer`` + ``Gravity``) and ``GyroscopeUncalibrated`` (else ``Gyroscope``), about
   100 Hz; the gyro is linearly interpolated onto the accelerometer stamps. Baro:
   ``Barometer`` ``pressure`` [hPa → Pa]. GNSS: ``Location``. Magnetometer (optional):
   ``Magnetometer`` (else ``MagnetometerUncalibrated``) ``x, y, z`` [µT].
2. **Merged 1 Hz CSV** (e.g. resampled by a user pipeline): one row per second, ``time`` as ISO
   UTC (or epoch ns), GNSS ``latitude, longitude, altitude``, ``horizontalAccuracy``,
   ``verticalAccuracy``; IMU ``acc_x/y/z`` [m/s², gravity included], ``gyro_x/y/z`` [rad/s];
   ``pressure`` [hPa]; optional magnetometer ``mag_x/y/z`` [µT]. Every row is a **1 s mean**
   (IMU included), so the drive metadata says
   ``averaged_1s = True``; stamps are put at the bin centre (label + 0.5 s).

Phone axes and conventions (https://github.com/tszheichoi/awesome-sensor-logger, UNITS.md,
COORDINATES.md, CROSSPLATFORM.md)
------------------------------------------------------------------------------------------
Device axes d: x to the right of the screen, y to the top, z out of the screen (right-handed).
Android (and iOS with "Standardise Units & Frames" on) report the specific force f_d [m/s²]
(a phone flat on a table reads +g on z). iOS by default reports −f_d, and the uncalibrated
accelerometer in g. The sign is taken from ``Metadata.csv`` (``platform``, ``standardisation``);
the unit from the content (median |a| ≈ 1 → g, ≈ 9.8 → m/s²). The merged CSV has no metadata
and is read in the Android convention (its at-rest specific force must point up: checked by
the caller of the 1 Hz data only through the resulting (0, 0, −g)). Gyro rates are
right-handed about the device axes on both platforms (the Gravity vector obeys
dg/dt = −ω × g; docs/real_logs.md, "Sensor Logger (phones)").

Body frame b (forward-right-down) for a phone
---------------------------------------------
A phone has no vehicle axes, so b is defined by a constant *mounting alignment*
``f_b = R_bd f_d``, ``ω_b = R_bd ω_d``:

- z_b (down) = −(mean specific force over the whole recording) / |…| — the mean is the
  gravity reaction when the phone's mounting is fixed (car) or its average pose (body-worn);
- x_b (forward) = the horizontal part of the device's top axis y_d, or of its back −z_d when
  the top points within 60° of the vertical (phone upright in a car mount, screen to the
  driver), normalised;
- y_b = z_b × x_b.

A phone lying flat, screen up, gets exactly x_b = y_d, y_b = x_d, z_b = −z_d; R_bd is in
``Drive.meta["imu_mounting"]["mat_bd"]`` and a static phone reads about (0, 0, −g).

Magnetometer
------------
Sensor Logger reports the field in µT in the same device axes on both platforms (no sign
difference, unlike the accelerometer, whose iOS sign is the inertial force). It is mapped
to b with exactly the accelerometer's mounting matrix, ``B_b = R_bd B_d``, so it shares the
IMU's axes. Non-finite and exactly-zero samples are dropped and counted; a folder without a
magnetometer file or a merged CSV without ``mag_*`` columns gives
``Drive.mag = None``. σ = ``MAG_SD_UT`` = 5 µT per axis (the autopilots' EKF default, as in
the other readers): a phone magnetometer is noisier
than an autopilot's (≈ 0.5 µT) and in a car the engine, speakers, phone mount and the car's
steel body add hard/soft-iron and time-varying fields of several µT, up to more than the
Earth's own (docs/real_logs.md, "Sensor Logger (phones)").

Heights and sigmas
------------------
GNSS ``altitude`` is WGS-84 ellipsoidal height (UNITS.md). σ_N = σ_E = horizontalAccuracy /
1.5 (the reported value is a 68 % radius; a 2-D Gaussian's 68 % radius is 1.51 σ),
σ_D = verticalAccuracy (68 % ≈ 1 σ in 1-D); floored at 0.5 m / 1.0 m because phones
under-report. Fixes with non-positive accuracy (iOS marks invalid with −1) are dropped. Phone
GNSS has no vertical velocity, so ``vel_n`` is None. Baro ``alt`` is the ISA pressure altitude
shifted by a constant so it matches the GNSS height over the first 10 s of fixes.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ...types import Drive
from ...util.failures import failure_message
from ._common import (
    Report,
    finite_rows,
    monotonic_mask,
)
from .phone_streams import (
    G0,
    aligned_imu,
    baro_from_pressure,
    gnss_from_fixes,
    mag_from_phone,
    time_column,
    time_meta,
)

_FOLDER_HEADER = ("time", "seconds_elapsed")


# ---------------------------------------------------------------------------- detection
def _header(line: str) -> list[str]:
    return [c.strip().strip('"') for c in next(csv.reader([line]), [])]


def is_sensorlogger_folder(path: Path) -> bool:
    """True when ``path`` holds at least one CSV whose header starts ``time,seconds_elapsed``."""
    for f in sorted(path.glob("*.csv")):
        try:
            with open(f, encoding="utf-8", errors="replace") as fh:
                if tuple(_header(fh.readline())[:2]) == _FOLDER_HEADER:
                    return True
        except OSError:
            continue
    return False


def is_merged_csv(head: bytes) -> bool:
    """True when the bytes start with a CSV header holding time, position and IMU columns."""
    try:  # utf-8-sig: spreadsheet programs write a byte-order mark before the header
        first = head.decode("utf-8-sig").splitlines()[0]
    except (UnicodeDecodeError, IndexError):
        return False
    cols = set(_header(first))
    return {"time", "latitude", "longitude"} <= cols and (
        {"acc_x", "acc_y", "acc_z"} <= cols or "pressure" in cols)


def well_formed_rows(text: str) -> tuple[str, int]:
    """The CSV text with only the rows whose field count equals the header's, and the number
    of rows dropped.

    pandas' ``on_bad_lines="skip"`` drops rows with too many fields but pads a row with too
    few with NaN, so one missing comma shifts every later field of that row into the wrong
    column (a GNSS fix 8,500 km away). Blank lines are ignored, not counted.
    """
    lines = text.splitlines()
    if not lines:
        return text, 0
    rows = csv.reader(lines)
    try:
        n_head = len(next(rows))
    except (StopIteration, csv.Error):
        return text, 0
    keep = [lines[0]]
    bad = 0
    for k, line in enumerate(lines[1:], start=1):
        if not line.strip():
            continue
        try:
            n = len(next(csv.reader([line])))
        except csv.Error:
            n = -1
        if n == n_head:
            keep.append(lines[k])
        else:
            bad += 1
    return "\n".join(keep) + "\n", bad


def _read_csv(path: Path, what: str, report: Report | None = None) -> pd.DataFrame:
    text = path.read_bytes().decode("utf-8-sig", errors="replace")
    text, bad = well_formed_rows(text)
    if report is not None:
        report.drop(what, "malformed CSV line (wrong field count)", bad)
    try:
        df = pd.read_csv(io.StringIO(text), on_bad_lines="skip")
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path.name}: cannot parse {what} CSV ({failure_message(exc)})"
                         ) from None
    if df.empty:
        raise ValueError(f"{path.name}: {what} CSV has no data rows (truncated?)")
    return df


def _num(df: pd.DataFrame, col: str) -> np.ndarray:
    if col not in df.columns:
        return np.full(len(df), np.nan)
    return pd.to_numeric(df[col], errors="coerce").to_numpy(dtype=float)


def _xyz(df: pd.DataFrame, path: Path) -> np.ndarray:
    missing = [c for c in ("x", "y", "z") if c not in df.columns]
    if missing:
        raise ValueError(f"{path.name}: missing axis column(s) {missing}")
    return np.column_stack([_num(df, c) for c in ("x", "y", "z")])


# --------------------------------------------------------------------------- the folder
def _metadata(folder: Path) -> dict[str, str]:
    f = folder / "Metadata.csv"
    if not f.exists():
        return {}
    with open(f, encoding="utf-8", errors="replace") as fh:
        rows = list(csv.reader(fh))
    if len(rows) < 2:
        return {}
    return {k.strip(): v.strip() for k, v in zip(rows[0], rows[1], strict=False)}


def read_sensorlogger_folder(path: str | Path) -> Drive:
    """Read a Sensor Logger per-sensor CSV export folder (see the module docstring)."""
    folder = Path(path)
    report = Report()
    meta_csv = _metadata(folder)
    platform = meta_csv.get("platform", "").lower()
    standardised = meta_csv.get("standardisation", "").lower() == "true"
    ios_sign = platform == "ios" and not standardised
    if not platform:
        report.notes.append("no Metadata.csv platform: Android sign convention assumed")

    def load(name: str) -> pd.DataFrame | None:
        f = folder / f"{name}.csv"
        return _read_csv(f, name, report) if f.exists() else None

    def stamped(df: pd.DataFrame) -> np.ndarray:
        return _num(df, "seconds_elapsed")

    t_a, a, acc_src = _folder_accel(load, stamped, folder, report, ios_sign)
    gyro_df = load("GyroscopeUncalibrated")
    gyro_src = "GyroscopeUncalibrated"
    if gyro_df is None:
        gyro_df, gyro_src = load("Gyroscope"), "Gyroscope"
    if gyro_df is None:
        raise ValueError(f"{folder.name}: Sensor Logger folder has no gyroscope CSV")
    t_w = stamped(gyro_df)
    w = _xyz(gyro_df, folder / f"{gyro_src}.csv")
    okw = finite_rows(w) & np.isfinite(t_w)
    kw = np.flatnonzero(okw)[monotonic_mask(t_w[okw], "gyro", report)]
    t_w, w = t_w[kw], w[kw]
    if t_w.size < 2:
        raise ValueError(f"{folder.name}: gyroscope CSV has no valid samples")
    # gyro onto accelerometer stamps (both ~100 Hz, offsets of a few ms)
    inside = (t_a >= t_w[0]) & (t_a <= t_w[-1])
    report.drop("imu", "accelerometer sample outside the gyro time span", int((~inside).sum()))
    t_a, a = t_a[inside], a[inside]
    w_i = np.column_stack([np.interp(t_a, t_w, w[:, j]) for j in range(3)])
    report.repair("imu", "gyro linearly interpolated onto accelerometer stamps", int(t_a.size))
    imu, mount = aligned_imu(t_a, a, w_i, report)

    loc = load("Location")
    if loc is None:
        raise ValueError(f"{folder.name}: Sensor Logger folder has no Location.csv (no GNSS)")
    t_l, vals = _fixes(stamped(loc), loc, report)
    gnss = gnss_from_fixes(t_l, *(vals[:, j] for j in range(5)), report)

    bar = load("Barometer")
    baro, off = (None, None)
    if bar is not None:
        baro, off = baro_from_pressure(stamped(bar), _num(bar, "pressure"), gnss, report)
    else:
        report.notes.append("no Barometer.csv: drive has no barometer")
    mag = None
    for name in ("Magnetometer", "MagnetometerUncalibrated"):
        mag_df = load(name)
        if mag_df is None:
            continue
        if {"x", "y", "z"} <= set(mag_df.columns):
            mag = mag_from_phone(stamped(mag_df), _xyz(mag_df, folder / f"{name}.csv"), mount, imu,
                       report, f"{name}.csv")
        else:
            report.notes.append(f"{name}.csv has no x, y, z columns: drive has no "
                                "magnetometer")
        break
    else:
        report.notes.append("no Magnetometer.csv: drive has no magnetometer")
    report.notes.append(f"IMU from {acc_src} and {gyro_src}; clock = seconds_elapsed")
    report.notes.append("phone GNSS has no vertical velocity: vel_n not provided")
    meta = {
        **time_meta(loc["time"] if "time" in loc.columns else None, t_l, folder),
        "source": "log", "name": folder.name, "format": "sensorlogger-folder",
        "vehicle": "unknown",  # a phone: carried on anything
        "device": meta_csv.get("device name"), "platform": platform or None,
        "clock": "Sensor Logger seconds_elapsed [s]",
        "imu_frame": "phone mounting alignment (see imu_mounting)", "imu_mounting": mount,
        "height_reference": "ellipsoid", "baro_alt_offset_m": off, "averaged_1s": False,
        **report.as_meta(),
    }
    return Drive(imu, gnss, baro, gnss.lla[0].copy(), meta=meta, mag=mag)


def _folder_accel(load: Any, stamped: Any, folder: Path, report: Report,
                  ios_sign: bool) -> tuple[np.ndarray, np.ndarray, str]:
    """Accelerometer stamps, samples [m/s², gravity included] and source of a folder export:
    the raw ``AccelerometerUncalibrated`` preferred, else ``Accelerometer`` + ``Gravity``;
    samples in g converted, the iOS sign convention undone."""
    acc_df = load("AccelerometerUncalibrated")
    if acc_df is not None:
        t_a = stamped(acc_df)
        a = _xyz(acc_df, folder / "AccelerometerUncalibrated.csv")
        acc_src = "AccelerometerUncalibrated"
    else:
        user, grav = load("Accelerometer"), load("Gravity")
        if user is None or grav is None:
            raise ValueError(f"{folder.name}: Sensor Logger folder has no accelerometer with "
                             "gravity (AccelerometerUncalibrated, or Accelerometer + Gravity)")
        t_a = stamped(user)
        g_xyz = _xyz(grav, folder / "Gravity.csv")
        a = _xyz(user, folder / "Accelerometer.csv") + np.column_stack(
            [np.interp(t_a, stamped(grav), g_xyz[:, j]) for j in range(3)])
        acc_src = "Accelerometer + Gravity"
    med = float(np.nanmedian(np.linalg.norm(a, axis=1)))
    if 0.5 < med < 2.0:
        a = a * G0
        report.notes.append(f"{acc_src} in g (median |a| {med:.2f}): converted to m/s^2")
    elif not 4.9 < med < 19.6:
        raise ValueError(f"{folder.name}: accelerometer median |a| = {med:.3g}: neither g nor "
                         "m/s^2 with gravity included")
    if ios_sign:
        a = -a
        report.notes.append("iOS sign convention (standardisation off): acceleration negated")
    return t_a, a, acc_src


def _fixes(t_l: np.ndarray, loc: pd.DataFrame, report: Report) -> tuple[np.ndarray, np.ndarray]:
    """``Location.csv`` stamps (NaN for a stale fix from before the recording and for a
    re-delivered one, every field identical to the previous row) and the columns latitude,
    longitude, altitude, horizontal and vertical accuracy."""
    stale = t_l < 0
    report.drop("gnss", "stale fix from before the recording start (seconds_elapsed < 0)",
                int(stale.sum()))
    cols = ["latitude", "longitude", "altitude", "horizontalAccuracy", "verticalAccuracy"]
    vals = np.column_stack([_num(loc, c) for c in cols])
    rep = np.zeros(len(loc), dtype=bool)
    last = None
    for k in range(len(loc)):  # re-delivery of an old fix: every field identical
        if last is not None and np.array_equal(vals[k], last):
            rep[k] = True
        last = vals[k]
    rep &= ~stale
    report.drop("gnss", "repeated fix (all fields identical to the previous row)",
                int(rep.sum()))
    t_l = np.where(stale | rep, np.nan, t_l)
    return t_l, vals


# ---------------------------------------------------------------------- the merged CSV
def read_merged_csv(path: str | Path) -> Drive:
    """Read a merged, 1 s averaged Sensor Logger CSV (see the module docstring)."""
    path = Path(path)
    report = Report()
    text = path.read_bytes().decode("utf-8-sig", errors="replace")
    text, bad = well_formed_rows(text)
    report.drop("rows", "malformed CSV line (wrong field count)", bad)
    n_lines = text.count("\n")
    df = _read_csv_text(text, path)
    need = ["acc_x", "acc_y", "acc_z", "gyro_x", "gyro_y", "gyro_z"]
    missing = [c for c in need if c not in df.columns]
    if missing:
        raise ValueError(f"{path.name}: merged CSV lacks IMU column(s) {missing}")
    if n_lines - 1 > len(df):
        report.drop("rows", "malformed CSV line", n_lines - 1 - len(df))
    t = _merged_time(df, path)
    t0 = float(np.nanmin(t))
    dt = np.diff(t[np.isfinite(t)])
    t = t - t0 + 0.5  # stamp each 1 s mean at its bin centre (labels are bin starts)
    f_d = np.column_stack([_num(df, c) for c in ("acc_x", "acc_y", "acc_z")])
    w_d = np.column_stack([_num(df, c) for c in ("gyro_x", "gyro_y", "gyro_z")])
    imu, mount = aligned_imu(t, f_d, w_d, report)
    gnss = gnss_from_fixes(t, _num(df, "latitude"), _num(df, "longitude"), _num(df, "altitude"),
                 _num(df, "horizontalAccuracy"), _num(df, "verticalAccuracy"), report)
    baro, off = (None, None)
    if "pressure" in df.columns:
        baro, off = baro_from_pressure(t, _num(df, "pressure"), gnss, report)
    else:
        report.notes.append("no pressure column: drive has no barometer")
    mag = None
    if {"mag_x", "mag_y", "mag_z"} <= set(df.columns):
        mag_d = np.column_stack([_num(df, c) for c in ("mag_x", "mag_y", "mag_z")])
        mag = mag_from_phone(t, mag_d, mount, imu, report, "mag_x/y/z columns (1 s means)")
    else:
        report.notes.append("no mag_x/y/z columns: drive has no magnetometer")
    report.notes.append("every row is a 1 s mean (IMU, GNSS and baro averaged over the bin); "
                        "stamps at bin centres; Android sign convention assumed for acc")
    report.notes.append("phone GNSS has no vertical velocity: vel_n not provided")
    meta = {
        **time_meta(df["time"] if "time" in df.columns else None, t, path, shift=0.5),
        "source": "log", "name": path.stem, "format": "sensorlogger-merged-1hz",
        "vehicle": "unknown",  # a phone: carried on anything
        "clock": "seconds since the first row's time + 0.5 s (bin centre)",
        "row_period_s": float(np.median(dt)) if dt.size else None,
        "imu_frame": "phone mounting alignment (see imu_mounting)", "imu_mounting": mount,
        "height_reference": "ellipsoid", "baro_alt_offset_m": off,
        "averaged_1s": True,
        "averaging_note": "rows are 1 s means of the phone sensors; the IMU is averaged, not "
                          "point-sampled, so it cannot resolve motion faster than 0.5 Hz",
        **report.as_meta(),
    }
    return Drive(imu, gnss, baro, gnss.lla[0].copy(), meta=meta, mag=mag)


def _read_csv_text(text: str, path: Path) -> pd.DataFrame:
    try:
        df = pd.read_csv(io.StringIO(text), on_bad_lines="skip")
    except (pd.errors.ParserError, pd.errors.EmptyDataError) as exc:
        raise ValueError(f"{path.name}: cannot parse CSV ({failure_message(exc)})") from None
    if len(df) < 10:
        raise ValueError(f"{path.name}: merged CSV has only {len(df)} data rows (truncated?)")
    return df


def _merged_time(df: pd.DataFrame, path: Path) -> np.ndarray:
    if "seconds_elapsed" in df.columns:
        return _num(df, "seconds_elapsed")
    tc = time_column(df["time"], path)
    if tc is None:
        raise ValueError(f"{path.name}: cannot parse the time column")
    return tc[0]  # the caller shifts the stamps to the first row
