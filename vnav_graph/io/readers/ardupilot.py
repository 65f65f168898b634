"""ArduPilot DataFlash binary logs (``.bin``) → :class:`~vnav_graph.types.Drive`.

Read with ``pymavlink.DFReader.DFReader_binary`` (the log is self-describing through its FMT
records, so old ``TimeMS`` and newer ``TimeUS`` layouts both work).

Messages used
-------------
- ``IMU`` (instance 0 when an ``I`` field exists): ``GyrX/Y/Z`` [rad/s], ``AccX/Y/Z`` [m/s²,
  gravity included]. ArduPilot logs the IMU in the vehicle body frame, forward-right-down,
  after the board-orientation rotation, so no axis change is applied.
- ``GPS`` (instance 0): ``Status`` (≥ 3 = 3-D fix; others are dropped), ``Lat``/``Lng``
  [deg], ``Alt`` [m **above mean sea level**], ``Spd`` [m/s], ``GCrs`` [deg], ``VZ`` [m/s,
  positive **down**], ``HDop``; GPS time ``Week``/``TimeMS`` (old) or ``GWk``/``GMS`` (new);
  boot time ``T`` [ms] (old) or ``TimeUS`` (new). ``GPA`` ``HAcc``/``VAcc``/``SAcc`` give
  per-fix sigmas when present.
  Old logs carry the same receiver accuracies in ``UBX3`` ``hAcc``/``vAcc``/``sAcc``.
- ``BARO`` (instance 0): ``Press`` [Pa] and ``Alt`` [m relative to the ground calibration].
- ``MAG`` (instance 0; later compasses are ``MAG2``/``MAG3`` or ``I`` > 0 and not read):
  ``MagX/Y/Z`` [milligauss = 0.1 µT]. ArduPilot logs the field already rotated into the body
  frame (forward-right-down, ``COMPASS_ORIENT`` applied) with its calibration offsets
  ``OfsX/Y/Z`` (and motor compensation ``MOfs*``) applied, so only the unit changes
  (× 0.1 → µT). Samples that are exactly (0, 0, 0) (the logger writes a MAG record even
  without a compass) and non-finite ones are dropped and counted; none left → ``Drive.mag``
  is None. σ = ``MAG_SD_UT`` (5 µT per axis, the noise ArduPilot's own EKF assumes,
  ``EK3_MAG_M_NSE`` = 0.05 Ga): the logged values are quantised to 1 mG = 0.1 µT and their
  sample-to-sample noise is a fraction of a µT, but on a multirotor the motor-current
  interference (correlated with throttle, so with the climbs) and the residual hard/soft
  iron dominate, and a σ near the sample noise lets the heading factors pull the tilt and,
  through it, the baro scale (docs/real_logs.md, "ArduPilot DataFlash" and "Magnetometer
  noise, field strength and spread").
- Onboard estimate: ``CTUN.Alt`` (inertial-nav altitude) when ``AHRS_EKF_USE`` = 0, otherwise
  the EKF's ``PD`` from ``XKF1``/``NKF1``/``EKF1`` (first core).

Clock
-----
Boot time in seconds (``TimeMS/1e3`` or ``TimeUS/1e6``). GNSS fixes are stamped with their
GPS time of week mapped onto the boot clock by a robust linear fit of the receipt stamps
``T`` on GPS time (:func:`._common.fit_clock`: removes the ±20 ms receipt jitter, keeps the
mean transport latency). The fit's slope r is the boot clock's advance per GPS second; a
board's boot clock can run several % off, which the gyro yaw integrated against the
magnetometer heading confirms independently of GNSS (docs/real_logs.md, "Boot clock vs GPS
time" in "ArduPilot DataFlash"). With ``clock="auto"`` (default) and |r − 1| > 0.1 % every stream is
re-stamped ``t = t_ref + (t_boot − t_ref)/r`` (:func:`._common.local_to_gps_seconds`,
``t_ref`` = first IMU stamp; IMU, baro, MAG and onboard alike), so IMU intervals are GPS-time
intervals; ``meta["clock"]`` records the basis, r, the fit and the evidence.

Heights
-------
GNSS height is ``GPS.Alt`` (MSL, the geoid undulation of ~50 m is *not* added: the package
uses one consistent height reference per drive and the baro bias absorbs datum offsets; the
drive metadata says ``height_reference = "msl"``). Baro ``alt`` is the ISA pressure altitude
of ``Press`` shifted by a constant so it matches the GNSS height over the first 10 s of fixes
(see ``_common.baro_alt_aligned``); the offset is reported.

Sigmas
------
With ``GPA``: σ_N = σ_E = HAcc, σ_D = VAcc, σ_v = SAcc. Without: σ_N = σ_E = 1.0 m · HDop and
σ_D = 1.5 · σ_N (VDOP ≈ 1.5 HDOP for a typical constellation; 1.0 m user range error of a
single-frequency u-blox), floored at 0.5 m / 1.0 m; velocity σ = (0.3, 0.3, 0.5) m/s.
"""

from __future__ import annotations

import io
import os
from contextlib import redirect_stdout
from pathlib import Path
from typing import Any

import numpy as np

from ...types import Drive
from ...types.streams import BaroStream, GnssStream, ImuStream, MagStream
from ._common import (
    Report,
    baro_alt_aligned,
    find_gaps,
    finite_rows,
    gps_to_unix,
    imu_in_si,
    local_to_gps_seconds,
    mag_stream,
    monotonic_mask,
    onboard_block,
    pressure_altitude,
    t0_unix_meta,
    valid_pressure,
)
from .dataflash_gnss import (
    choose_clock,
    col,
    decimal_year,
    instance0,
    read_gnss,
    time_s,
)

MILLIGAUSS_UT = 0.1  # µT per milligauss (MAG.MagX/Y/Z)
MAG_SD_UT = 5.0  # magnetometer white-noise σ per axis [µT] (module docstring)
HEAD = b"\xa3\x95"

_TYPES = ["IMU", "GPS", "GPA", "UBX3", "BARO", "MAG", "CTUN", "EKF1", "NKF1", "XKF1", "PARM",
          "MSG"]


def is_dataflash(head: bytes) -> bool:
    """True when the first bytes look like a DataFlash binary log (FMT record first)."""
    return len(head) >= 3 and head[:2] == HEAD and head[2] == 0x80


def _collect(path: Path) -> tuple[dict[str, list[dict[str, Any]]], Any]:
    from pymavlink import DFReader

    reader = None
    try:
        with redirect_stdout(io.StringIO()):  # pymavlink prints on odd records
            reader = DFReader.DFReader_binary(str(path), zero_time_base=True)
            out: dict[str, list[dict[str, Any]]] = {k: [] for k in _TYPES}
            while True:
                m = reader.recv_match(type=_TYPES)
                if m is None:
                    break
                out[m.get_type()].append(m.to_dict())
    except Exception as exc:  # pymavlink raises assorted errors on corrupt data
        raise ValueError(f"{path.name}: cannot parse DataFlash log ({type(exc).__name__}: "
                         f"{exc})") from None
    finally:
        # the reader keeps the file and a memory map open; left to the garbage collector,
        # "ResourceWarning: unclosed file" landed in whichever estimator's warnings of the
        # report ran when it was collected. Its record formats stay readable after close.
        # what close() does in recent pymavlink; 2.4.37 (our floor) has no close().
        if reader is not None:
            for name in ("data_map", "filehandle"):
                handle = getattr(reader, name, None)
                if handle is not None:
                    try:
                        handle.close()
                    except (OSError, ValueError, BufferError):
                        pass
    return out, reader


def _truncated_tail(path: Path, reader: Any) -> bool:
    """True when the last record in the file is cut short (file truncated)."""
    size = os.path.getsize(path)
    with open(path, "rb") as fh:
        fh.seek(max(0, size - 1024))
        tail = fh.read()
    pos = tail.rfind(HEAD)
    if pos < 0 or pos + 2 >= len(tail):
        return False
    fmt = reader.formats.get(tail[pos + 2])
    if fmt is None:
        return False
    return pos + fmt.len > len(tail)


def _unparsed_records(path: Path, reader: Any, parsed: dict[str, int]) -> dict[str, int]:
    """Records of IMU/GPS/BARO whose 3-byte header occurs in the file more often than the
    parser returned them (beyond 2 % + 5: a header byte pattern can occur inside data).

    pymavlink skips ahead to the next valid header after damage; when it lands on a false
    one it can lose minutes of records without an error.
    """
    ids = {getattr(f, "name", None): t for t, f in getattr(reader, "formats", {}).items()}
    data = path.read_bytes()
    out = {}
    for name in ("IMU", "GPS", "BARO"):
        t = ids.get(name)
        if t is None or not isinstance(t, int) or not 0 <= t < 256:
            continue
        n_file = data.count(HEAD + bytes([t]))
        n_lost = n_file - parsed.get(name, 0)
        if n_lost > 0.02 * n_file + 5:
            out[name] = int(n_lost)
    return out


CLOCK_CHOICES = ("auto", "gps", "boot")


HELI_FRAME_CLASSES = (6, 11, 13)  # FRAME_CLASS: helicopter, dual heli, heli quad


def vehicle_kind(firmware: str | None, msg_records: list[Any], params: dict[str, Any]) -> str:
    """The vehicle type from the firmware banner: "multirotor" (Copter that is not a
    helicopter by ``FRAME_CLASS`` or an older log's "Frame: HELI" message), "helicopter",
    "fixed-wing" (Plane), "ground" (Rover), else "unknown"."""
    fw = str(firmware or "")
    if fw.startswith(("ArduPlane", "APM:Plane")):
        return "fixed-wing"
    if fw.startswith(("ArduRover", "APM:Rover")):
        return "ground"
    if not fw.startswith(("ArduCopter", "APM:Copter")):
        return "unknown"
    frames = [str(r.get("Message", "")) for r in msg_records
              if str(r.get("Message", "")).startswith("Frame:")]
    heli = "heli" in fw.lower() or any("HELI" in f.upper() for f in frames)
    fc = params.get("FRAME_CLASS")
    if fc is not None and int(fc) in HELI_FRAME_CLASSES:
        heli = True
    return "helicopter" if heli else "multirotor"


def read_dataflash(path: str | Path, clock: str = "auto") -> Drive:
    """Read an ArduPilot DataFlash binary log into a Drive (see the module docstring).

    Parameters
    ----------
    path : the ``.bin`` log
    clock : ``"auto"`` (default) puts every stream on GPS seconds when the boot clock's
        advance per GPS second differs from 1 by more than ``CLOCK_RATIO_TOL`` (0.1 %), else
        keeps the boot clock; ``"gps"`` always maps (when GPS time is logged); ``"boot"``
        never maps (the boot clock as logged).
    """
    if clock not in CLOCK_CHOICES:
        raise ValueError(f"clock must be one of {CLOCK_CHOICES}, not {clock!r}")
    path = Path(path)
    report = Report()
    msgs, reader = _collect(path)
    if _truncated_tail(path, reader):
        report.drop("log", "incomplete last record (file truncated)", 1)
    lost = _unparsed_records(path, reader, {k: len(v) for k, v in msgs.items()})
    for name, n in lost.items():
        report.drop(name.lower() if name in ("IMU", "GPS", "BARO") else "log",
                    f"{name} records in the file but not parsed (corrupt bytes: parser lost "
                    "sync)", n)
    params = {r.get("Name"): r.get("Value") for r in msgs["PARM"]}
    firmware = next((r.get("Message") for r in msgs["MSG"]
                     if str(r.get("Message", "")).startswith(("Ardu", "APM"))), None)

    t_imu, gyro, acc = _read_imu(msgs["IMU"], path.name, report)
    fixes = read_gnss(msgs, path.name, report)
    t_ref = float(t_imu[0])
    clock_meta = choose_clock(clock, fixes, t_ref, report)
    basis_gps = clock_meta["basis"].startswith("GPS")
    t_gnss = fixes.t
    if basis_gps:
        assert fixes.clock_fit is not None
        t_imu = local_to_gps_seconds(t_imu, fixes.clock_fit.ratio, t_ref)
        t_gnss = local_to_gps_seconds(t_gnss, fixes.clock_fit.ratio, t_ref)

    def tmap(t: np.ndarray) -> np.ndarray:
        assert fixes.clock_fit is not None or not basis_gps
        return local_to_gps_seconds(t, fixes.clock_fit.ratio, t_ref) if basis_gps else t

    find_gaps(t_imu, "imu", report)
    find_gaps(t_gnss, "gnss", report)
    gnss = GnssStream(t_gnss, fixes.lla, fixes.pos_sd, fixes.vel_n, fixes.vel_sd)
    baro, baro_offset = _read_baro(msgs["BARO"], gnss, report, tmap)
    onboard = _onboard(msgs, params, gnss, report, tmap)
    mag = _read_mag(msgs["MAG"], report, tmap, t_imu)

    meta: dict[str, Any] = {
        "source": "log",
        "name": path.stem,
        "format": "ardupilot-dataflash",
        "firmware": firmware,
        "vehicle": vehicle_kind(firmware, msgs["MSG"], params),
        "clock": clock_meta,
        "imu_frame": "ArduPilot body frame (forward-right-down), used as logged",
        "height_reference": "msl",
        "height_note": "GPS.Alt is above mean sea level (not ellipsoidal); every height in this "
                       "drive uses that reference",
        "baro_alt_offset_m": baro_offset,
        "averaged_1s": False,
        "boot_clock_per_gps_second": report.clock_rate,
        **report.as_meta(),
    }
    if fixes.clock_fit is not None:  # GPS time of the fixes: the drive's absolute time
        ok = fixes.gps_time > 1500 * 604800.0  # with a week number (after 2008)
        meta.update(t0_unix_meta(gps_to_unix(fixes.gps_time[ok]), t_gnss[ok]))
    year = decimal_year(fixes.gps_time)
    if year is not None:
        meta["decimal_year"] = year  # the date of the Earth's field (geo.magfield)
    if onboard is not None:
        meta["onboard"] = onboard
    return Drive(ImuStream(t_imu, gyro, acc), gnss, baro, fixes.lla[0].copy(), meta=meta,
                 mag=mag)


def _read_mag(rows: list[dict[str, Any]], report: Report, tmap: Any,
              t_imu: np.ndarray) -> MagStream | None:
    """``MAG`` instance 0 → MagStream: stamps on the drive's clock (``tmap`` of the boot
    stamps [s], as IMU and BARO), ``MagX/Y/Z`` [mG] × 0.1 → µT, body FRD as logged; all-zero,
    non-finite and out-of-range samples dropped (:func:`._common.mag_stream`)."""
    rows = [r for r in rows if instance0(r)]
    if not rows:
        report.notes.append("no MAG records: drive has no magnetometer")
        return None
    t = tmap(np.array([time_s(r) for r in rows]))
    field = np.column_stack([col(rows, f"Mag{a}") for a in "XYZ"]) * MILLIGAUSS_UT
    return mag_stream(t, field, MAG_SD_UT, report, t_imu, "MAG (instance 0)")


def _read_imu(rows: list[dict[str, Any]], name: str,
              report: Report) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Boot-clock stamps [s], gyro [rad/s] and specific force [m/s²] of IMU instance 0:
    non-finite, out-of-range and non-increasing samples dropped (and reported)."""
    imu_rows = [r for r in rows if instance0(r)]
    if len(imu_rows) < 10:
        raise ValueError(f"{name}: DataFlash log has no IMU data "
                         f"({len(imu_rows)} IMU records; truncated or not a flight log?)")
    t_imu = np.array([time_s(r) for r in imu_rows])
    gyro = np.column_stack([col(imu_rows, f"Gyr{a}") for a in "XYZ"])
    acc = np.column_stack([col(imu_rows, f"Acc{a}") for a in "XYZ"])
    ok = finite_rows(gyro, acc)
    report.drop("imu", "non-finite sample", int((~ok).sum()))
    gyro, acc = imu_in_si(t_imu, gyro, acc, report)  # units first, then the range screen
    phys = (np.max(np.abs(gyro), axis=1) <= 50.0) & (np.max(np.abs(acc), axis=1) <= 2000.0)
    report.drop("imu", "outside physical range", int((ok & ~phys).sum()))
    ok &= phys
    t_imu, gyro, acc = t_imu[ok], gyro[ok], acc[ok]
    keep = monotonic_mask(t_imu, "imu", report)
    t_imu, gyro, acc = t_imu[keep], gyro[keep], acc[keep]
    if t_imu.size < 10:
        why = "; ".join(f"{c} {r}" for r, c in report.dropped.get("imu", {}).items())
        raise ValueError(f"{name}: only {t_imu.size} of {len(imu_rows)} IMU records are "
                         f"usable ({why or 'fields missing'}; corrupt FMT records or NaN "
                         "samples?)")
    return t_imu, gyro, acc


def _read_baro(rows: list[dict[str, Any]], gnss: GnssStream, report: Report,
               tmap: Any = None) -> tuple[BaroStream | None, float | None]:
    rows = [r for r in rows if instance0(r)]
    if not rows:
        report.notes.append("no BARO records: drive has no barometer")
        return None, None
    t = np.array([time_s(r) for r in rows])
    if tmap is not None:
        t = tmap(t)
    press = col(rows, "Press")
    alt_rel = col(rows, "Alt")
    health = col(rows, "Health")
    ok = np.isfinite(t)
    if np.isfinite(health).all():
        report.drop("baro", "sensor reported unhealthy", int((ok & (health == 0)).sum()))
        ok &= health != 0
    have_p = valid_pressure(press)
    if have_p[ok].mean() > 0.5:
        report.drop("baro", "invalid pressure", int((ok & ~have_p).sum()))
        ok &= have_p
        t, press = t[ok], press[ok]
        keep = monotonic_mask(t, "baro", report)
        t, press = t[keep], press[keep]
        raw = pressure_altitude(press)
        desc = "ISA pressure altitude of BARO.Press"
    else:
        ok &= np.isfinite(alt_rel)
        t, alt_rel = t[ok], alt_rel[ok]
        keep = monotonic_mask(t, "baro", report)
        t, raw, press = t[keep], alt_rel[keep], None
        desc = "BARO.Alt (relative to the ground calibration)"
    if t.size < 2:
        report.notes.append("fewer than 2 valid baro samples: drive has no barometer")
        return None, None
    find_gaps(t, "baro", report)
    alt, offset = baro_alt_aligned(t, raw, gnss.t, gnss.lla[:, 2])
    report.notes.append(f"baro alt = {desc} + {offset:.2f} m (datum aligned to GNSS height "
                        "over the first 10 s of fixes)")
    return BaroStream(t, press, alt), offset


def _onboard(msgs: dict[str, list[dict[str, Any]]], params: dict[str, Any], gnss: GnssStream,
             report: Report, tmap: Any = None) -> dict[str, Any] | None:
    """Autopilot's own altitude in the drive's height reference (relative alt + offset)."""
    ekf_used = params.get("AHRS_EKF_USE")
    candidates: list[tuple[str, list[dict[str, Any]], str, float]] = []
    ekf_rows = next(((n, msgs[n]) for n in ("XKF1", "NKF1", "EKF1") if msgs[n]), None)
    ctun = msgs["CTUN"]
    if ctun and "Alt" in ctun[0]:
        candidates.append(("ctun.alt (inertial nav)", ctun, "Alt", 1.0))
    if ekf_rows is not None and "PD" in ekf_rows[1][0]:
        ekf = (f"{ekf_rows[0].lower()}.pd (EKF)", [r for r in ekf_rows[1] if instance0(r)],
               "PD", -1.0)
        if ekf_used is None or float(ekf_used) != 0.0:
            candidates.insert(0, ekf)
        else:
            candidates.append(ekf)
    for name, rows, key, sign in candidates:
        t = np.array([time_s(r) for r in rows])
        if tmap is not None:
            t = tmap(t)
        h = sign * col(rows, key)
        ok = np.isfinite(t) & np.isfinite(h)
        t, h = t[ok], h[ok]
        keep = monotonic_mask(t, "onboard", Report())
        t, h = t[keep], h[keep]
        if t.size < 2:
            continue
        try:
            alt, off = baro_alt_aligned(t, h, gnss.t, gnss.lla[:, 2])
        except ValueError:
            continue
        return onboard_block(t, alt, name, off,
                             "relative altitude + offset matching the GNSS height over the "
                             "first 10 s of fixes")
    return None
