"""The four export writers and ``export_run`` (the package docstring describes the formats)."""

from __future__ import annotations

import json
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ..suggest import did_you_mean
from .run_info import DRIVE_INFO, TRUTH_TABLE

FORMATS = ("csv", "kml", "gpx", "tum")
EXPORT_DIR = "export"
SUMMARY_SCHEMA = "vnav_graph.summary/1"
GPX_NS = "https://github.com/vnav-graph/vnav_graph/gpx/1"
CSV_FLOAT = "%.12g"  # 12 significant digits: 1e-12 rad of latitude is 6 µm

# unit of a table column, by its name's suffix (Estimate.to_dataframe's naming)
_UNITS = (("_mps2", "m/s^2"), ("_radps", "rad/s"), ("_mps", "m/s"), ("_rad", "rad"),
          ("_m", "m"), ("_s", "s"))


def parse_formats(spec: str | Iterable[str]) -> list[str]:
    """``"csv,kml"`` (or a list) → validated format names; ValueError on an unknown one."""
    items = [s.strip().lower() for s in (spec.split(",") if isinstance(spec, str) else spec)]
    items = [s for s in items if s]
    if not items:
        raise ValueError(f"no export format given (choose from {', '.join(FORMATS)})")
    for s in items:
        if s not in FORMATS:
            raise ValueError(f"unknown export format '{s}'{did_you_mean(s, FORMATS)} "
                             f"(choose from {', '.join(FORMATS)})")
    return list(dict.fromkeys(items))


def column_unit(name: str) -> str:
    """The unit of an estimate-table column ("1" for the dimensionless baro scale)."""
    for suffix, unit in _UNITS:
        if name.endswith(suffix):
            return unit
    return "1"


@dataclass
class Track:
    """One trajectory of a run folder: an estimator's or the truth."""

    name: str
    table: pd.DataFrame

    @property
    def horizontal(self) -> bool:
        return bool(np.isfinite(self.table["lat_rad"]).any()) if "lat_rad" in self.table else False

    @property
    def has_pose(self) -> bool:
        cols = ("pos_n_m", "pos_e_m", "pos_d_m", "roll_rad", "pitch_rad", "yaw_rad")
        return all(c in self.table for c in cols)


@dataclass
class RunFolder:
    """What ``export_run`` reads from a ``run`` output folder."""

    path: Path
    summary: dict[str, Any]
    info: dict[str, Any]
    tables: dict[str, Path]  # estimator (and "truth") -> Parquet

    @property
    def windows(self) -> list[tuple[str, float, float]]:
        """Labelled time windows for the KML placemarks: the drive's GNSS gaps and a real
        log's holdout windows."""
        out = [("GNSS outage", float(a), float(b)) for a, b in self.info.get("gnss_gaps_s", [])]
        ev = self.summary.get("evaluation") or {}
        for w in ev.get("windows") or []:
            a, b = (w["t0"], w["t1"]) if isinstance(w, dict) else w
            out.append(("GNSS withheld (holdout scoring)", float(a), float(b)))
        return out


def open_run(path: str | Path) -> RunFolder:
    """Read a ``run`` output folder; a one-line ValueError when it is not one."""
    p = Path(path)
    if not p.is_dir():
        raise ValueError(f"{p}: not a run folder (no such directory)")
    sp = p / "summary.json"
    if not sp.is_file():
        raise ValueError(f"{p}: not a run folder (no summary.json; give the --out folder of "
                         "'vnav-graph run')")
    try:
        summary = json.loads(sp.read_text())
    except (OSError, ValueError) as exc:
        raise ValueError(f"{sp}: unreadable ({type(exc).__name__})") from None
    if not isinstance(summary, dict) or summary.get("schema") != SUMMARY_SCHEMA:
        raise ValueError(f"{sp}: not a vnav-graph run summary (schema "
                         f"{summary.get('schema') if isinstance(summary, dict) else None!r})")
    ip = p / DRIVE_INFO
    if not ip.is_file():
        raise ValueError(f"{p}: no {DRIVE_INFO} (written by 'vnav-graph run' since export "
                         "exists): run the drive again to export it")
    info = json.loads(ip.read_text())
    tables = {f.stem: f for f in sorted((p / "estimates").glob("*.parquet"))}
    if (p / TRUTH_TABLE).is_file():
        tables["truth"] = p / TRUTH_TABLE
    if not tables:
        raise ValueError(f"{p}: the run folder holds no estimates (estimates/*.parquet)")
    return RunFolder(p, summary, info, tables)


@dataclass
class ExportResult:
    written: list[Path] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)  # "<name>.<fmt>: why"


def export_run(run_dir: str | Path, formats: str | Sequence[str],
               estimators: Sequence[str] | None = None) -> ExportResult:
    """Write ``run_dir/export/<name>.<ext>`` for each estimator (and the truth) and format.

    ``estimators``: the names to export (default: every estimate in the folder, and the truth
    where there is one); an unknown name is a one-line ValueError. Files are written through
    ``outputs.publish`` (complete files only, never a half-written one under a final name).
    """
    from ..outputs import publish

    run = open_run(run_dir)
    fmts = parse_formats(formats)
    names = list(run.tables) if estimators is None else list(dict.fromkeys(estimators))
    for n in names:
        if n not in run.tables:
            raise ValueError(f"no estimate '{n}' in {run.path}{did_you_mean(n, run.tables)} "
                             f"(it has {', '.join(run.tables)})")
    tracks = [Track(n, pd.read_parquet(run.tables[n])) for n in names]
    res = ExportResult()

    def fill(tmp: Path) -> None:
        for fmt in fmts:
            writable = []
            for tr in tracks:
                why = _unsupported(tr, fmt)
                if why:
                    res.skipped.append(f"{tr.name}.{fmt}: {why}")
                    continue
                _WRITERS[fmt](tmp / f"{tr.name}.{fmt}", tr, run)
                writable.append(tr)
            if fmt == "kml" and len(writable) > 1:
                write_kml(tmp / "all.kml", writable, run)

    res.written = publish(run.path / EXPORT_DIR, fill)
    return res


def _unsupported(tr: Track, fmt: str) -> str | None:
    if fmt == "csv":
        return None
    if not tr.horizontal:
        return "vertical-only estimate (no horizontal track): CSV only"
    if fmt == "tum" and not tr.has_pose:
        return "no attitude or tangent-plane position in this estimate: no TUM pose"
    return None


# -- CSV ----------------------------------------------------------------------------------------

def _drive_line(run: RunFolder) -> str:
    s, info = run.summary, run.info
    what = info.get("source", "")
    if s.get("scenario") is not None:
        what += f", scenario {s['scenario']}, seed {s.get('seed')}"
    return f"drive: {info.get('name')} ({what}, {s['drive']['duration_s']:.1f} s)"


def _origin_text(info: dict[str, Any]) -> str:
    o = info["origin_lla"]
    return (f"lat {o['lat_deg']:.9f} deg, lon {o['lon_deg']:.9f} deg, "
            f"height {o['height_m']:.3f} m")


def write_csv(path: Path, tr: Track, run: RunFolder) -> None:
    """The track's table as CSV with ``#`` header lines (units, frames, datum, provenance)."""
    info = run.info
    head = [
        f"vnav_graph {run.summary.get('version')} trajectory export: "
        f"{'truth' if tr.name == 'truth' else 'estimator ' + tr.name}",
        _drive_line(run),
        f"time: {info['time_reference']}"
        + (f" (t0_unix_s = {info['t0_unix_s']:.3f})" if info.get("t0_unix_s") else ""),
        f"lat_rad, lon_rad: WGS-84 geodetic latitude and longitude [rad]; alt_m: "
        f"{info['height_datum']} [m], +up",
        f"pos_n_m, pos_e_m, pos_d_m: local tangent-plane NED position [m] from the origin "
        f"{_origin_text(info)}",
        "vel_*_mps: NED velocity [m/s]; roll_rad, pitch_rad, yaw_rad: z-y-x Euler angles of "
        "the body-to-NED rotation [rad]; bias_*: IMU biases in body axes",
        "baro_bias_m: baro Gauss-Markov bias [m]; baro_scale: scale-factor error [-]; "
        "baro_latency_s: latency [s]",
        "*_sd_*: one-sigma of the column of that name, same unit (att_*_sd_rad: tilt-error "
        "sigmas about the N, E, D axes; horiz_sd_m: sqrt(pos_n_sd^2 + pos_e_sd^2)); NaN where "
        "not estimated",
        "units: " + ", ".join(f"{c} [{column_unit(c)}]" for c in tr.table.columns),
    ]
    with open(path, "w", newline="") as f:
        f.write("".join(f"# {h}\n" for h in head))
        tr.table.to_csv(f, index=False, float_format=CSV_FLOAT, lineterminator="\n")


# -- KML ----------------------------------------------------------------------------------------

def _kml_color(hex_rgb: str, alpha: int = 255) -> str:
    r, g, b = (int(hex_rgb[i:i + 2], 16) for i in (1, 3, 5))
    return f"{alpha:02x}{b:02x}{g:02x}{r:02x}"  # KML: aabbggrr


def _lon_lat_alt(df: pd.DataFrame) -> np.ndarray:
    a = np.column_stack([np.degrees(df["lon_rad"].to_numpy()),
                         np.degrees(df["lat_rad"].to_numpy()), df["alt_m"].to_numpy()])
    return a[np.all(np.isfinite(a), axis=1)]


def write_kml(path: Path, tracks: Sequence[Track], run: RunFolder) -> None:
    """One line per track (absolute altitude), the drive's windows as separate placemarks."""
    import simplekml

    from ..report.palette import estimator_color

    kml = simplekml.Kml(name=f"vnav_graph: {run.info.get('name')}")
    kml.document.description = (
        f"{_drive_line(run)}. Altitudes: {run.info['height_datum']} (KML viewers read "
        "absolute altitudes as above mean sea level). " + run.info["time_reference"])
    for tr in tracks:
        color = _kml_color(estimator_color(tr.name))
        line = kml.newlinestring(name=tr.name, coords=[tuple(c) for c in _lon_lat_alt(tr.table)])
        line.altitudemode = simplekml.AltitudeMode.absolute
        line.style.linestyle.color = color
        line.style.linestyle.width = 2
        line.description = f"{tr.name}: {len(tr.table)} epochs, t = {tr.table['t_s'].iloc[0]:.2f}" \
                           f" .. {tr.table['t_s'].iloc[-1]:.2f} s"
        if not run.windows:
            continue
        folder = kml.newfolder(name=f"{tr.name}: GNSS windows")
        t = tr.table["t_s"].to_numpy()
        for label, a, b in run.windows:
            inside = tr.table[(t >= a) & (t <= b)]
            coords = _lon_lat_alt(inside)
            if len(coords) < 2:
                continue
            pm = folder.newlinestring(name=f"{label} {a:.1f}-{b:.1f} s",
                                      coords=[tuple(c) for c in coords])
            pm.altitudemode = simplekml.AltitudeMode.absolute
            pm.style.linestyle.color = _kml_color(estimator_color(tr.name), 160)
            pm.style.linestyle.width = 6
            pm.description = f"{label}: t = {a:.1f} .. {b:.1f} s ({b - a:.0f} s)"
    kml.save(str(path))


def _write_kml_one(path: Path, tr: Track, run: RunFolder) -> None:
    write_kml(path, [tr], run)


# -- GPX ----------------------------------------------------------------------------------------

def write_gpx(path: Path, tr: Track, run: RunFolder) -> None:
    """A GPX track with elevation; UTC time where the drive has an absolute time."""
    import xml.etree.ElementTree as ET

    import gpxpy.gpx

    t0 = run.info.get("t0_unix_s")
    gpx = gpxpy.gpx.GPX()
    gpx.creator = f"vnav_graph {run.summary.get('version')}"
    gpx.nsmap["vnav"] = GPX_NS
    trk = gpxpy.gpx.GPXTrack(name=tr.name)
    trk.description = (
        f"{_drive_line(run)}. Elevation: {run.info['height_datum']}. "
        + ("Time: UTC." if t0 is not None else
           "Time is relative: the drive has no absolute time, so the points have no <time>; "
           "vnav:t_s gives seconds on the drive's clock."))
    seg = gpxpy.gpx.GPXTrackSegment()
    df = tr.table
    ok = np.isfinite(df["lat_rad"]) & np.isfinite(df["lon_rad"]) & np.isfinite(df["alt_m"])
    lat = np.degrees(df["lat_rad"].to_numpy()[ok])
    lon = np.degrees(df["lon_rad"].to_numpy()[ok])
    alt = df["alt_m"].to_numpy()[ok]
    ts = df["t_s"].to_numpy()[ok]
    epoch = datetime(1970, 1, 1, tzinfo=UTC)
    for la, lo, h, t in zip(lat, lon, alt, ts, strict=True):
        when = None if t0 is None else epoch + timedelta(seconds=float(t0) + float(t))
        p = gpxpy.gpx.GPXTrackPoint(float(la), float(lo), elevation=float(h), time=when)
        el = ET.Element(f"{{{GPX_NS}}}t_s")
        el.text = f"{t:.6f}"
        p.extensions.append(el)
        seg.points.append(p)
    trk.segments.append(seg)
    gpx.tracks.append(trk)
    path.write_text(gpx.to_xml(version="1.1"))


# -- TUM ----------------------------------------------------------------------------------------

def tum_rows(df: pd.DataFrame) -> np.ndarray:
    """(N, 8) ``timestamp x y z qx qy qz qw`` in the local NED frame (finite rows only)."""
    from ..geo.frames import rph_to_quat

    pos = df[["pos_n_m", "pos_e_m", "pos_d_m"]].to_numpy()
    rph = df[["roll_rad", "pitch_rad", "yaw_rad"]].to_numpy()
    ok = np.all(np.isfinite(pos), axis=1) & np.all(np.isfinite(rph), axis=1)
    q = rph_to_quat(rph[ok])  # (w, x, y, z)
    return np.column_stack([df["t_s"].to_numpy()[ok], pos[ok], q[:, 1:], q[:, :1]])


def write_tum(path: Path, tr: Track, run: RunFolder) -> None:
    """TUM trajectory: drive-clock time, NED position and body-to-NED quaternion."""
    rows = tum_rows(tr.table)
    head = (f"# vnav_graph {run.summary.get('version')}: {tr.name}; {_drive_line(run)}\n"
            "# timestamp [s, drive clock] x y z [m, local NED: north east down from "
            f"{_origin_text(run.info)}] qx qy qz qw [body to NED]\n")
    with open(path, "w") as f:
        f.write(head)
        np.savetxt(f, rows, fmt=["%.6f"] + ["%.6f"] * 3 + ["%.9f"] * 4, delimiter=" ")


_WRITERS: dict[str, Callable[[Path, Track, RunFolder], None]] = {
    "csv": write_csv, "kml": _write_kml_one, "gpx": write_gpx, "tum": write_tum,
}
