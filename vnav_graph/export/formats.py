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

from ..run.outputs import ONLINE_SUFFIX
from ..util.suggest import did_you_mean
from .run_info import DRIVE_INFO, TRUTH_TABLE
from .tables import ANSWERS, EXPORT_RATE_HZ, at_rate, csv_metadata, csv_table, rate_note

FORMATS = ("csv", "kml", "gpx", "tum")
EXPORT_DIR = "export"
SUMMARY_SCHEMA = "vnav_graph.summary/1"
GPX_NS = "https://github.com/vnav-graph/vnav_graph/gpx/1"
CSV_FLOAT = "%.12g"  # 12 significant digits: 5e-10 deg of longitude past 100 deg is 0.06 mm
CSV_META_SUFFIX = "-metadata.json"  # <file>.csv-metadata.json: CSV on the Web's side file


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


@dataclass
class Track:
    """One trajectory of a run folder: an estimator's final or online answer, or the truth.

    ``table``: the Parquet's layout (SI, radians) at the export's rate; ``answer``: a key of
    ``tables.ANSWERS``; ``rows``: ``tables.rate_note`` of the rate.
    """

    name: str
    table: pd.DataFrame
    answer: str = "final"
    rows: str = ""

    @property
    def stem(self) -> str:
        """The exported files' name without the format: ``<name>`` for a final answer and
        the truth, ``<name>.online`` for an online one."""
        return self.name + (ONLINE_SUFFIX if self.answer == "online" else "")

    @property
    def label(self) -> str:
        """The track's name in a viewer: ``ekf (online)``, ``ekf (final)``, ``truth``."""
        return self.name if self.answer == "truth" else f"{self.name} ({self.answer})"

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
    tables: dict[str, Path]  # estimator (and "truth") -> Parquet of its final answer
    online: dict[str, Path] = field(default_factory=dict)  # estimator -> its online Parquet

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
    tables, online = {}, {}
    for f in sorted((p / "estimates").glob("*.parquet")):
        if f.stem.endswith(ONLINE_SUFFIX):
            online[f.stem[: -len(ONLINE_SUFFIX)]] = f
        else:
            tables[f.stem] = f
    if (p / TRUTH_TABLE).is_file():
        tables["truth"] = p / TRUTH_TABLE
    if not tables:
        raise ValueError(f"{p}: the run folder holds no estimates (estimates/*.parquet)")
    return RunFolder(p, summary, info, tables, online)


@dataclass
class ExportResult:
    written: list[Path] = field(default_factory=list)
    skipped: list[tuple[str, str, str]] = field(default_factory=list)  # (track, format, why)

    def skipped_line(self) -> str | None:
        """Every skipped file in one line, grouped by reason, e.g. ``kml, gpx of loop2,
        loop3: vertical-only estimate (no horizontal track): CSV only``; None when none."""
        if not self.skipped:
            return None
        groups: dict[str, tuple[dict[str, None], dict[str, None]]] = {}
        for name, fmt, why in self.skipped:
            fmts, names = groups.setdefault(why, ({}, {}))
            fmts[fmt] = None
            names[name] = None
        return "; ".join(f"{', '.join(f)} of {', '.join(sorted(n))}: {why}"
                         for why, (f, n) in groups.items())


def export_run(run_dir: str | Path, formats: str | Sequence[str],
               estimators: Sequence[str] | None = None, online: bool = False,
               full_rate: bool = False) -> ExportResult:
    """Write ``run_dir/export/<name>.<ext>`` for each estimator (and the truth) and format.

    ``estimators``: the names to export (default: every estimate in the folder, and the truth
    where there is one); an unknown name is a one-line ValueError. ``online``: export the
    online answers (``estimates/<name>.online.parquet``) as ``<name>.online.<ext>`` instead of
    the final ones (the truth, where there is one, as ``truth.<ext>``); a name without an
    online answer is a one-line ValueError. Rows: the epochs on the ``tables.EXPORT_RATE_HZ``
    grid of the drive clock (``tables.at_rate``), every epoch with ``full_rate``. Files are
    written through ``outputs.publish`` (complete files only, never a half-written one under a
    final name).
    """
    from ..run.outputs import publish

    run = open_run(run_dir)
    fmts = parse_formats(formats)
    if online and not run.online:
        raise ValueError(f"{run.path}: no online estimates (estimates/*{ONLINE_SUFFIX}.parquet: "
                         "'vnav-graph run' writes one per causal estimator, e.g. ekf, "
                         "graph-isam2)")
    have = _sources(run, online)
    names = list(have) if estimators is None else list(dict.fromkeys(estimators))
    for n in names:
        if n not in have:
            raise ValueError(_missing(run, n, online, have))
    rate = None if full_rate else EXPORT_RATE_HZ
    tracks = [Track(n, at_rate(pd.read_parquet(path), rate), answer, rate_note(rate))
              for n, (path, answer) in ((n, have[n]) for n in names)]
    res = ExportResult()

    def fill(tmp: Path) -> None:
        for fmt in fmts:
            writable = []
            for tr in tracks:
                why = _unsupported(tr, fmt)
                if why:
                    res.skipped.append((tr.stem, fmt, why))
                    continue
                _WRITERS[fmt](tmp / f"{tr.stem}.{fmt}", tr, run)
                writable.append(tr)
            if fmt == "kml" and len(writable) > 1:
                write_kml(tmp / ("all.online.kml" if online else "all.kml"), writable, run)

    res.written = publish(run.path / EXPORT_DIR, fill)
    return res


def _sources(run: RunFolder, online: bool) -> dict[str, tuple[Path, str]]:
    """The tracks ``export_run`` can write: name -> (Parquet, answer)."""
    truth = {"truth": (run.tables["truth"], "truth")} if "truth" in run.tables else {}
    if not online:
        return {n: (p, "final") for n, p in run.tables.items() if n != "truth"} | truth
    return {n: (p, "online") for n, p in run.online.items()} | truth


def _missing(run: RunFolder, name: str, online: bool,
             have: dict[str, tuple[Path, str]]) -> str:
    """The one-line error for a name ``export_run`` cannot export."""
    if online and name in run.tables:
        causal = [n for n in have if n != "truth"]
        return (f"'{name}' has no online estimate in {run.path} (no estimates/"
                f"{name}{ONLINE_SUFFIX}.parquet: a pure smoother has none); online estimates: "
                f"{', '.join(causal) or 'none'}")
    return (f"no estimate '{name}' in {run.path}{did_you_mean(name, have)} "
            f"(it has {', '.join(have)})")


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


def _notes(tr: Track, run: RunFolder) -> list[str]:
    """The lines every export of ``tr`` states: the drive, the answer, time, heights,
    origin and rows."""
    info = run.info
    answer = ANSWERS[tr.answer]
    frm = ((run.summary.get("estimators") or {}).get(tr.name) or {}).get("online") or {}
    if tr.answer == "online" and frm.get("from_s"):
        answer += f"; from t = {frm['from_s']:g} s (before it the estimator is not aligned)"
    return [
        _drive_line(run),
        f"{tr.label}: {answer}",
        f"time: {info['time_reference']}"
        + (f" (t0_unix_s = {info['t0_unix_s']:.3f})" if info.get("t0_unix_s") else ""),
        f"heights: {info['height_datum']}, +up",
        f"local tangent-plane NED origin: {_origin_text(info)}",
        tr.rows,
    ]


def write_csv(path: Path, tr: Track, run: RunFolder) -> None:
    """The track's table as CSV with one header row (the column names carry the units; angles
    in degrees: ``tables.csv_table``) and its side file ``<file>-metadata.json``
    (``tables.csv_metadata``: the answer, drive, datum, time, origin and each column)."""
    table = csv_table(tr.table)
    with open(path, "w", newline="") as f:
        table.to_csv(f, index=False, float_format=CSV_FLOAT, lineterminator="\n")
    notes = _notes(tr, run)
    notes.append("angles in degrees, every other quantity in SI units (the unit ends each "
                 "column name); *_sd_*: one-sigma of the column of that name; empty where not "
                 "estimated")
    meta = csv_metadata(path.name, list(table.columns), f"{tr.label}: {path.name}",
                        tr.answer, notes, f"vnav_graph {run.summary.get('version')}",
                        run.info["height_datum"])
    path.with_name(path.name + CSV_META_SUFFIX).write_text(json.dumps(meta, indent=1) + "\n")


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
        "absolute altitudes as above mean sea level). " + run.info["time_reference"] + ". "
        + "; ".join(dict.fromkeys(f"{tr.label}: {ANSWERS[tr.answer]}" for tr in tracks)))
    for tr in tracks:
        color = _kml_color(estimator_color(tr.name))
        line = kml.newlinestring(name=tr.label,
                                 coords=[tuple(c) for c in _lon_lat_alt(tr.table)])
        line.altitudemode = simplekml.AltitudeMode.absolute
        line.style.linestyle.color = color
        line.style.linestyle.width = 2
        t = tr.table["t_s"].to_numpy()
        line.description = (f"{tr.label}: {ANSWERS[tr.answer]}. {len(t)} epochs, t = "
                            f"{t[0]:.2f} .. {t[-1]:.2f} s; {tr.rows}")
        if not run.windows:
            continue
        folder = kml.newfolder(name=f"{tr.label}: GNSS windows")
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
    trk = gpxpy.gpx.GPXTrack(name=tr.label)
    trk.description = (
        f"{tr.label}: {ANSWERS[tr.answer]}. {_drive_line(run)}. Elevation: "
        f"{run.info['height_datum']}. "
        + ("Time: UTC." if t0 is not None else
           "Time is relative: the drive has no absolute time, so the points have no <time>; "
           "vnav:t_s gives seconds on the drive's clock.") + f" {tr.rows}.")
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
    """TUM trajectory: drive-clock time, NED position and body-to-NED quaternion, after ``#``
    lines (evo's reader skips them) that say which answer it is, the drive and the rows."""
    rows = tum_rows(tr.table)
    head = [f"vnav_graph {run.summary.get('version')}: {tr.label}",
            *(n for n in _notes(tr, run) if not n.startswith(("heights", "local"))),
            "timestamp [s, drive clock] x y z [m, local NED: north east down from "
            f"{_origin_text(run.info)}] qx qy qz qw [body to NED]"]
    with open(path, "w") as f:
        f.write("".join(f"# {h}\n" for h in head))
        np.savetxt(f, rows, fmt=["%.6f"] + ["%.6f"] * 3 + ["%.9f"] * 4, delimiter=" ")


_WRITERS: dict[str, Callable[[Path, Track, RunFolder], None]] = {
    "csv": write_csv, "kml": _write_kml_one, "gpx": write_gpx, "tum": write_tum,
}
