"""A drive from plain text files described by a TOML column map (``docs/column_maps.md``).

The map sits next to the data (any ``*.toml`` in the folder with an ``[imu]`` table is found
by ``find_map``) or is given with ``vnav-graph run FOLDER --map MAP.toml``; every file it
names is relative to the data folder. Tables:

- ``[imu]``: ``file``, ``delimiter`` (default ``,``), ``header`` (the first line names the
  columns; default false), ``accel`` / ``gyro``: three columns each (0-based indices, or
  names with ``header = true``), ``accel_unit`` ``"g"`` | ``"m/s^2"``, ``gyro_unit``
  ``"deg/s"`` | ``"rad/s"``, ``rpy_deg``: the mounting (below), ``gravity_g`` [m/s²] for g
  (default 9.80665).
- ``[imu.time]``: ``base`` = ``"seconds"`` (``column``; ``epoch`` = ``"gps"`` (GPST seconds
  since 1980-01-06), ``"unix"`` (UTC) or ``"none"`` (relative)), ``"gps-week-seconds"``
  (``week_column``, ``column``), ``"iso-utc"`` (``column``) or ``"tag-counter-ms"``
  (``column``: a millisecond counter, ``tag``: the RTKLIB time-tag file,
  ``io.readers.timetag``); ``offset_s``: added to every IMU stamp [s].
- ``[gnss]``: ``file``, ``format`` (``"rtklib-pos"`` or ``"nmea"``), ``height_datum`` (for a
  file whose header is silent), ``sd_scale`` (σ multiplier per quality), ``min_quality``.
- ``[truth]`` (optional; what ``--truth`` uses by default): ``file``, ``height_datum``,
  ``fix_only``.
- ``[lever_arms]``: ``imu``, ``gnss``, ``truth``: each point's position from one common
  origin in body axes (forward, right, down) [m]; the antenna's lever arm is gnss − imu.
- ``geoid_separation_m``: N = ellipsoidal − MSL height [m], needed when two files' heights
  are on different datums.

Mounting: ``accel_b = C · accel_sensor`` (and the same for the gyro) with
``C = (Rz(yaw) Ry(pitch) Rx(roll))ᵀ`` of ``rpy_deg`` — the convention of Groves'
``Euler_to_CTM`` used by RTKLIB-explorer's GNSS_IMU configs, so their angles are copied as
they are. The drive's clock is GPST seconds minus the whole second before the first IMU
sample (``meta["t0_gpst_s"]``); its heights are in the GNSS file's datum.
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

import numpy as np

from ...types import Drive
from ...types.streams import GnssStream, ImuStream
from ._common import Report, find_gaps, monotonic_mask
from .gpstime import gps_to_unix, unix_to_gps, week_tow_to_gps

__all__ = ["FORMAT", "find_map", "load_map", "mounting_matrix", "read_mapped"]

FORMAT = "column-map"
G0 = 9.80665
ACCEL_UNITS = {"g": None, "m/s^2": 1.0, "m/s2": 1.0, "mps2": 1.0}
GYRO_UNITS = {"deg/s": np.pi / 180.0, "dps": np.pi / 180.0, "rad/s": 1.0, "radps": 1.0}
TIME_BASES = ("seconds", "gps-week-seconds", "iso-utc", "tag-counter-ms")
GNSS_FORMATS = ("rtklib-pos", "nmea")
TOP_KEYS = {"imu", "gnss", "truth", "lever_arms", "geoid_separation_m", "name", "notes"}
TABLE_KEYS = {
    "imu": {"file", "delimiter", "header", "accel", "gyro", "accel_unit", "gyro_unit",
            "rpy_deg", "gravity_g", "time"},
    "imu.time": {"base", "column", "week_column", "epoch", "tag", "offset_s"},
    "gnss": {"file", "format", "height_datum", "sd_scale", "min_quality"},
    "truth": {"file", "height_datum", "fix_only"},
    "lever_arms": {"imu", "gnss", "truth"},
}


def find_map(folder: str | Path) -> Path | None:
    """The one ``*.toml`` in ``folder`` with an ``[imu]`` table, or None; ValueError when
    there are several."""
    found = []
    for p in sorted(Path(folder).glob("*.toml")):
        try:
            doc = tomllib.loads(p.read_text(encoding="utf-8"))
        except (tomllib.TOMLDecodeError, OSError, UnicodeDecodeError):
            continue
        if isinstance(doc.get("imu"), dict):
            found.append(p)
    if len(found) > 1:
        names = ", ".join(p.name for p in found)
        raise ValueError(f"{Path(folder).name}: several column maps ({names}): give one "
                         "with --map")
    return found[0] if found else None


def load_map(path: str | Path) -> dict[str, Any]:
    """The map's tables, checked (ValueError, one line, naming the key)."""
    p = Path(path)
    try:
        doc = tomllib.loads(p.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ValueError(f"no such column map: {p}") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"{p.name}: not a TOML file ({exc})") from None
    unknown = set(doc) - TOP_KEYS
    if unknown:
        raise ValueError(f"{p.name}: unknown key(s) {', '.join(sorted(unknown))} (known: "
                         f"{', '.join(sorted(TOP_KEYS))})")
    for table, known in TABLE_KEYS.items():
        t = doc
        for part in table.split("."):
            t = t.get(part) if isinstance(t, dict) else None
        extra = set(t) - known if isinstance(t, dict) else set()
        if extra:
            raise ValueError(f"{p.name}: unknown key(s) {', '.join(sorted(extra))} in "
                             f"[{table}] (known: {', '.join(sorted(known))})")
    if not isinstance(doc.get("imu"), dict) or "file" not in doc["imu"]:
        raise ValueError(f"{p.name}: needs an [imu] table with file = ...")
    imu = doc["imu"]
    for key in ("accel", "gyro"):
        cols = imu.get(key)
        if not (isinstance(cols, list) and len(cols) == 3):
            raise ValueError(f"{p.name}: imu.{key} must list 3 columns")
    if imu.get("accel_unit", "m/s^2") not in ACCEL_UNITS:
        raise ValueError(f"{p.name}: imu.accel_unit must be one of {', '.join(ACCEL_UNITS)}")
    if imu.get("gyro_unit", "rad/s") not in GYRO_UNITS:
        raise ValueError(f"{p.name}: imu.gyro_unit must be one of {', '.join(GYRO_UNITS)}")
    tb = imu.get("time")
    if not isinstance(tb, dict) or tb.get("base") not in TIME_BASES:
        raise ValueError(f"{p.name}: imu.time.base must be one of {', '.join(TIME_BASES)}")
    gn = doc.get("gnss")
    if gn is not None and (not isinstance(gn, dict) or gn.get("format") not in GNSS_FORMATS
                           or "file" not in gn):
        raise ValueError(f"{p.name}: [gnss] needs file and format (one of "
                         f"{', '.join(GNSS_FORMATS)})")
    for key in ("imu", "gnss", "truth"):
        v = (doc.get("lever_arms") or {}).get(key)
        if v is not None and not (isinstance(v, list) and len(v) == 3):
            raise ValueError(f"{p.name}: lever_arms.{key} must be 3 numbers [m]")
    return doc


def mounting_matrix(rpy_deg: Any) -> np.ndarray:
    """C taking sensor axes into body axes (module docstring)."""
    from ...geo.frames import quat_to_mat, rph_to_quat

    r = np.radians(np.asarray(rpy_deg, dtype=float))
    return np.asarray(quat_to_mat(rph_to_quat(r))).reshape(3, 3).T


def lever(doc: dict[str, Any], point: str) -> np.ndarray | None:
    """Position of ``point`` relative to the IMU in body axes [m], or None if not given."""
    arms = doc.get("lever_arms") or {}
    if point not in arms:
        return None
    return np.asarray(arms[point], dtype=float) - np.asarray(arms.get("imu", [0, 0, 0]),
                                                             dtype=float)


def _columns(frame: Any, spec: list[Any], what: str) -> np.ndarray:
    import pandas as pd

    out = []
    for c in spec:
        if isinstance(c, int):
            if not 0 <= c < frame.shape[1]:
                raise ValueError(f"{what}: column {c} not in the file ({frame.shape[1]} "
                                 "columns)")
            out.append(frame.iloc[:, c])
        else:
            if c not in frame.columns:
                raise ValueError(f"{what}: no column named {c!r}")
            out.append(frame[c])
    return np.column_stack([pd.to_numeric(s, errors="coerce").to_numpy(float) for s in out])


def _imu_time(frame: Any, tb: dict[str, Any], folder: Path, report: Report
              ) -> tuple[np.ndarray, str]:
    """Absolute GPST seconds (or relative seconds for epoch none) of every row, and a note."""
    import pandas as pd

    base = tb["base"]
    col = tb.get("column")
    if col is None:
        raise ValueError(f"imu.time: base {base} needs column = ...")
    if base == "iso-utc":
        s = frame.iloc[:, col] if isinstance(col, int) else frame[col]
        ts = pd.to_datetime(s, utc=True, errors="coerce")
        unix = (ts - pd.Timestamp("1970-01-01", tz="UTC")).dt.total_seconds().to_numpy(float)
        return unix_to_gps(unix), "IMU time: ISO UTC stamps (converted to GPST)"
    v = _columns(frame, [col], "imu.time")[:, 0]
    if base == "seconds":
        epoch = tb.get("epoch", "none")
        if epoch == "gps":
            return v, "IMU time: GPST seconds"
        if epoch == "unix":
            return unix_to_gps(v), "IMU time: Unix UTC seconds (converted to GPST)"
        if epoch == "none":
            return v, "IMU time: relative seconds (no absolute time)"
        raise ValueError(f"imu.time.epoch must be gps, unix or none, not {epoch!r}")
    if base == "gps-week-seconds":
        week = _columns(frame, [tb.get("week_column")], "imu.time.week_column")[:, 0]
        return week_tow_to_gps(week, v), "IMU time: GPS week and seconds of week"
    from .timetag import counter_to_gpst, read_tag

    if "tag" not in tb:
        raise ValueError("imu.time: base tag-counter-ms needs tag = <time-tag file>")
    tag = read_tag(folder / tb["tag"])
    ok = np.isfinite(v)
    t = np.full(v.size, np.nan)
    t[ok], rate = counter_to_gpst(v[ok], tag)
    return t, (f"IMU time: millisecond counter mapped through {tb['tag']} onto GPST "
               f"(device clock {rate:.6f} s per GPST second)")


def read_imu(doc: dict[str, Any], folder: Path, report: Report
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
    """GPST (or relative) stamps, gyro [rad/s] and specific force [m/s²] in body axes, and
    whether the stamps are absolute."""
    import pandas as pd

    imu = doc["imu"]
    path = folder / imu["file"]
    if not path.is_file():
        raise ValueError(f"imu.file: no such file {imu['file']} in {folder.name}")
    sep = imu.get("delimiter", ",")
    names = None
    if not imu.get("header", False):  # widest of the first lines: a cut first line is shorter
        with open(path, encoding="utf-8", errors="replace") as fh:
            names = list(range(max(ln.count(sep) + 1 for _, ln in zip(range(200), fh,
                                                                      strict=False))))
    try:
        frame = pd.read_csv(path, sep=sep, names=names,
                            header=0 if imu.get("header", False) else None,
                            skipinitialspace=True, dtype=str, on_bad_lines="skip",
                            engine="python" if len(sep) > 1 else "c")
    except (pd.errors.ParserError, UnicodeDecodeError, pd.errors.EmptyDataError) as exc:
        raise ValueError(f"{path.name}: cannot read as delimited text ({exc})") from None
    acc = _columns(frame, imu["accel"], "imu.accel")
    gyr = _columns(frame, imu["gyro"], "imu.gyro")
    t_abs, note = _imu_time(frame, imu["time"], folder, report)
    ok = np.isfinite(t_abs) & np.all(np.isfinite(acc), axis=1) & np.all(np.isfinite(gyr), axis=1)
    report.drop("imu", "incomplete or unreadable row", int((~ok).sum()))
    acc, gyr, t_abs = acc[ok], gyr[ok], t_abs[ok]
    if t_abs.size < 10:
        raise ValueError(f"{path.name}: fewer than 10 readable IMU rows")
    unit = imu.get("accel_unit", "m/s^2")
    acc = acc * (float(imu.get("gravity_g", G0)) if ACCEL_UNITS[unit] is None else 1.0)
    gyr = gyr * GYRO_UNITS[imu.get("gyro_unit", "rad/s")]
    c = mounting_matrix(imu.get("rpy_deg", [0.0, 0.0, 0.0]))
    acc, gyr = acc @ c.T, gyr @ c.T
    off = float(imu["time"].get("offset_s", 0.0))
    t_abs = t_abs + off
    report.notes.append(note + (f", offset {off:+g} s" if off else ""))
    report.notes.append(f"IMU from {imu['file']}: accel in {unit}, gyro in "
                        f"{imu.get('gyro_unit', 'rad/s')}, mounting roll/pitch/yaw "
                        f"{imu.get('rpy_deg', [0, 0, 0])} deg")
    absolute = not (imu["time"]["base"] == "seconds"
                    and imu["time"].get("epoch", "none") == "none")
    return t_abs, gyr, acc, absolute


def read_mapped(folder: str | Path, map_path: str | Path | None = None,
                height_datum: str | None = None) -> Drive:
    """The drive a column map describes (module docstring). ``height_datum``: the GNSS file's
    datum when neither its header nor the map states it."""
    folder = Path(folder)
    if map_path is None:
        map_path = find_map(folder)
        if map_path is None:
            raise ValueError(f"{folder.name}: no column map (*.toml with an [imu] table) in "
                             "the folder: give one with --map")
    doc = load_map(map_path)
    report = Report()
    t_abs, gyr, acc, absolute = read_imu(doc, folder, report)
    keep = monotonic_mask(t_abs, "imu", report)
    t_abs, gyr, acc = t_abs[keep], gyr[keep], acc[keep]
    t0 = float(np.floor(t_abs[0])) if absolute else 0.0
    t_imu = t_abs - t0
    find_gaps(t_imu, "imu", report)
    imu = ImuStream(t_imu, gyr, acc)
    gnss, datum = None, "ellipsoid"
    meta: dict[str, Any] = {}
    gn = doc.get("gnss")
    if gn is not None:
        if not absolute:
            raise ValueError("imu.time: relative seconds cannot be aligned with a GNSS file "
                             "(give an absolute time base)")
        gnss, datum, notes = _gnss(doc, folder, t0, height_datum)
        report.notes.extend(notes)
        cut = (gnss.t >= t_imu[0]) & (gnss.t <= t_imu[-1])
        report.drop("gnss", "outside the IMU time span", int((~cut).sum()))
        if not cut.any():
            raise ValueError(f"{gn['file']}: no GNSS epoch inside the IMU time span "
                             "(different days or time systems?)")
        gnss = gnss.select(cut)
    if absolute:
        meta["t0_gpst_s"] = t0
        meta["t0_unix_s"] = float(gps_to_unix(t0))
        from ._common import decimal_year_unix

        y = decimal_year_unix([meta["t0_unix_s"]])
        if y is not None:
            meta["decimal_year"] = y
    origin = gnss.lla[0] if gnss is not None else np.zeros(3)
    meta.update(report.as_meta())
    meta.update(source="log", name=str(doc.get("name") or folder.name), format=FORMAT,
                height_reference=datum, column_map=str(Path(map_path).name),
                gnss_file=None if gn is None else str(gn["file"]))
    return Drive(imu, gnss, None, origin, meta=meta)


def _gnss(doc: dict[str, Any], folder: Path, t0: float, height_datum: str | None
          ) -> tuple[GnssStream, str, list[str]]:
    gn = doc["gnss"]
    path = folder / gn["file"]
    if not path.is_file():
        raise ValueError(f"gnss.file: no such file {gn['file']} in {folder.name}")
    stated = gn.get("height_datum", height_datum)
    if gn["format"] == "rtklib-pos":
        from .rtklib_pos import gnss_stream, read_pos

        sol = read_pos(path, stated)
        g, notes = gnss_stream(sol, t0, sol.height_datum or "ellipsoid",
                               lever_arm_b=lever(doc, "gnss"), sd_scale=gn.get("sd_scale"),
                               min_quality=gn.get("min_quality"))
        notes += _report_lines(sol.report, "gnss")
        return g, str(sol.height_datum), notes
    from .nmea import read_nmea
    from .rtklib_pos import gnss_stream

    sol = read_nmea(path)
    g, notes = gnss_stream(sol, t0, str(sol.height_datum), lever_arm_b=lever(doc, "gnss"),
                           sd_scale=gn.get("sd_scale"), min_quality=gn.get("min_quality"))
    return g, str(sol.height_datum), notes + sol.report.notes + _report_lines(sol.report,
                                                                              "gnss")


def _report_lines(rep: Report, stream: str) -> list[str]:
    out = []
    for kind in ("dropped", "repaired"):
        for reason, n in (getattr(rep, kind).get(stream) or {}).items():
            out.append(f"{stream} file: {kind} {n}: {reason}")
    return out
