"""Trajectory exports (``vnav-graph export`` and ``run --export``): CSV, KML, GPX and TUM read
back with their own readers equal the run's Parquet at the export's rows (the 20 Hz grid of
the drive clock); evo's APE equals the RMSE computed from the Parquet; the skipped files are
one line; bad input ends with one line and exit 2."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
from datetime import UTC, datetime

import numpy as np
import pandas as pd
import pytest

from vnav_graph.cli import main
from vnav_graph.export import EXPORT_RATE_HZ, FORMATS, export_run
from vnav_graph.export.tables import at_rate
from vnav_graph.report.palette import estimator_color

pytestmark = pytest.mark.slow
KML_NS = {"k": "http://www.opengis.net/kml/2.2"}


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    """The default drive (240 s, a 60 s GNSS outage) through three full-state estimators and
    three vertical-only ones, exported in every format by ``run --export``."""
    out = tmp_path_factory.mktemp("export") / "run"
    assert main(["run", "--estimators", "ekf,ekf-rts,graph-batch,loop2,loop3,vkf4", "--out",
                 str(out),
                 "--no-progress", "--export", ",".join(FORMATS)]) == 0
    return out


def _parquet(run_dir, name, full_rate=False):
    """The run's table of ``name``, at the export's rows unless ``full_rate``."""
    p = run_dir / ("truth.parquet" if name == "truth" else f"estimates/{name}.parquet")
    return at_rate(pd.read_parquet(p), None if full_rate else EXPORT_RATE_HZ)


def _degrees(name):
    return name.replace("_radps", "_degps").replace("_rad", "_deg")


@pytest.mark.parametrize("name", ["ekf-rts", "loop3", "truth"])
def test_csv_round_trip_equals_parquet(run_dir, name):
    path = run_dir / "export" / f"{name}.csv"
    back = pd.read_csv(path)  # one header row, nothing above it
    ref = _parquet(run_dir, name)
    assert list(back.columns) == [_degrees(c) for c in ref.columns]
    assert back.columns[:4].tolist() == ["t_s", "lat_deg", "lon_deg", "alt_m"]
    want = ref.to_numpy().copy()
    angles = [i for i, c in enumerate(ref.columns) if c.endswith(("_rad", "_radps"))]
    want[:, angles] = np.degrees(want[:, angles])
    # printed with 12 significant digits: equal to that precision, NaN where NaN
    np.testing.assert_allclose(back.to_numpy(), want, rtol=6e-12, atol=1e-300, equal_nan=True)
    if name != "loop3":  # degrees within 1e-9 deg (0.1 mm) of the estimate's radians
        np.testing.assert_allclose(back["lat_deg"], np.degrees(ref["lat_rad"]), rtol=0,
                                   atol=1e-9)
    meta = json.loads((run_dir / "export" / f"{name}.csv-metadata.json").read_text())
    assert meta["url"] == f"{name}.csv"
    assert [c["name"] for c in meta["tableSchema"]["columns"]] == list(back.columns)
    assert any("WGS-84 ellipsoid" in c for c in meta["rdfs:comment"])  # the datum is named
    units = {c["name"]: c["schema:unitText"] for c in meta["tableSchema"]["columns"]}
    assert units["t_s"] == "s" and units["alt_m"] == "m"
    assert name == "loop3" or units["lat_deg"] == "deg"


def test_rows_at_the_output_rate_and_full_rate_on_request(run_dir, tmp_path):
    """240 s: the 200 Hz truth and the 20 Hz smoother export 4801 rows (one per 0.05 s), the
    50 Hz ekf-rts 2401 (its epochs on the grid); ``--full-rate`` every epoch."""
    exp = run_dir / "export"
    rows = {n: len(pd.read_csv(exp / f"{n}.csv")) for n in ("truth", "graph-batch", "ekf-rts")}
    assert rows == {"truth": 4801, "graph-batch": 4801, "ekf-rts": 2401}
    copy = tmp_path / "run"
    shutil.copytree(run_dir, copy, ignore=shutil.ignore_patterns("export"))
    assert main(["export", str(copy), "--format", "csv", "--full-rate"]) == 0
    full = copy / "export"
    assert len(pd.read_csv(full / "truth.csv")) == 48001 == len(_parquet(copy, "truth", True))
    assert len(pd.read_csv(full / "ekf-rts.csv")) == 12001
    # the truth's CSV at the output rate is a tenth of the full-rate one
    ratio = (exp / "truth.csv").stat().st_size / (full / "truth.csv").stat().st_size
    assert 0.09 < ratio < 0.11


def test_gpx_positions_equal_parquet(run_dir):
    import gpxpy

    gpx = gpxpy.parse((run_dir / "export" / "ekf-rts.gpx").read_text())
    pts = [p for trk in gpx.tracks for seg in trk.segments for p in seg.points]
    ref = _parquet(run_dir, "ekf-rts")
    assert len(pts) == len(ref) == 2401
    np.testing.assert_allclose([p.latitude for p in pts], np.degrees(ref["lat_rad"]),
                               rtol=0, atol=1e-12)
    np.testing.assert_allclose([p.longitude for p in pts], np.degrees(ref["lon_rad"]),
                               rtol=0, atol=1e-12)
    np.testing.assert_allclose([p.elevation for p in pts], ref["alt_m"], rtol=0, atol=1e-9)
    # a simulated drive has no absolute time: no <time>, said in the description
    assert all(p.time is None for p in pts)
    assert "Time is relative" in gpx.tracks[0].description


def test_gpx_utc_time_where_the_drive_has_one(run_dir, tmp_path):
    import gpxpy

    copy = tmp_path / "run"
    shutil.copytree(run_dir, copy, ignore=shutil.ignore_patterns("export"))
    info = json.loads((copy / "drive.json").read_text())
    t0 = 1_700_000_000.25  # 2023-11-14T22:13:20.25Z
    info["t0_unix_s"] = t0
    (copy / "drive.json").write_text(json.dumps(info))
    export_run(copy, "gpx", ["graph-batch"])
    gpx = gpxpy.parse((copy / "export" / "graph-batch.gpx").read_text())
    pts = gpx.tracks[0].segments[0].points
    t = _parquet(copy, "graph-batch")["t_s"].to_numpy()
    got = np.array([p.time.timestamp() for p in pts])
    assert pts[0].time.tzinfo is not None and pts[0].time.utcoffset().total_seconds() == 0
    np.testing.assert_allclose(got, t0 + t, rtol=0, atol=1e-3)
    assert datetime.fromtimestamp(got[0], UTC).year == 2023


def test_kml_one_line_per_track_in_the_report_colours(run_dir):
    root = ET.parse(run_dir / "export" / "all.kml").getroot()
    doc = root.find("k:Document", KML_NS)
    tracks = doc.findall("k:Placemark", KML_NS)  # the tracks; windows are in folders
    names = [pm.findtext("k:name", namespaces=KML_NS) for pm in tracks]
    # loop3: vertical only
    assert sorted(names) == ["ekf (final)", "ekf-rts (final)", "graph-batch (final)", "truth"]
    styles = {s.get("id"): s.findtext("k:LineStyle/k:color", namespaces=KML_NS)
              for s in doc.iter("{http://www.opengis.net/kml/2.2}Style")}
    for pm, label in zip(tracks, names, strict=True):
        name = label.split(" ")[0]
        assert pm.findtext("k:LineString/k:altitudeMode", namespaces=KML_NS) == "absolute"
        coords = pm.findtext("k:LineString/k:coordinates", namespaces=KML_NS).split()
        assert len(coords) == len(_parquet(run_dir, name))
        rgb = estimator_color(name)[1:]
        kml_color = styles[pm.findtext("k:styleUrl", namespaces=KML_NS).lstrip("#")]
        assert kml_color == "ff" + rgb[4:6] + rgb[2:4] + rgb[0:2]  # aabbggrr
    # the drive's GNSS outage (fixes stop at 119.9 s and resume at 180 s) as a placemark
    windows = [pm.findtext("k:name", namespaces=KML_NS)
               for f in doc.findall("k:Folder", KML_NS) for pm in f.findall("k:Placemark", KML_NS)]
    assert windows and all(w.startswith("GNSS outage 119.9-180.0 s") for w in windows)


def test_evo_ape_equals_parquet_rmse(run_dir):
    evo_fi = pytest.importorskip("evo.tools.file_interface")
    from evo.core import metrics, sync

    ref = evo_fi.read_tum_trajectory_file(str(run_dir / "export" / "truth.tum"))
    est = evo_fi.read_tum_trajectory_file(str(run_dir / "export" / "ekf-rts.tum"))
    n_est = len(est.timestamps)
    ref, est = sync.associate_trajectories(ref, est, max_diff=1e-3)
    assert len(est.timestamps) == n_est == 2401  # every exported row has its truth row
    ape = metrics.APE(metrics.PoseRelation.translation_part)
    ape.process_data((ref, est))  # no alignment
    rmse_evo = ape.get_statistic(metrics.StatisticsType.rmse)
    # the same from the Parquet files: truth rows at the estimate's epochs
    cols = ["pos_n_m", "pos_e_m", "pos_d_m"]
    e, t = _parquet(run_dir, "ekf-rts"), _parquet(run_dir, "truth")
    m = pd.merge_asof(e[["t_s", *cols]], t[["t_s", *cols]], on="t_s",
                      direction="nearest", tolerance=1e-3, suffixes=("", "_true")).dropna()
    d = m[cols].to_numpy() - m[[c + "_true" for c in cols]].to_numpy()
    rmse = float(np.sqrt(np.mean(np.sum(d**2, axis=1))))
    assert len(m) == len(ref.timestamps)
    assert rmse_evo == pytest.approx(rmse, rel=1e-6, abs=1e-6)


def test_vertical_only_is_csv_only(run_dir, capsys):
    assert main(["export", str(run_dir), "--format", "kml,tum", "--estimators", "loop3"]) == 0
    out = capsys.readouterr().out
    assert "export: skipped kml, tum of loop3: vertical-only" in out
    assert (run_dir / "export" / "loop3.csv").is_file()


def test_all_skipped_tracks_are_one_line(run_dir, capsys):
    """Every track in every format: the vertical-only estimators' nine skipped files are one
    line."""
    assert main(["export", str(run_dir)]) == 0  # default: every format
    out = capsys.readouterr().out.splitlines()
    assert [ln for ln in out if "skipped" in ln] == [
        "export: skipped kml, gpx, tum of loop2, loop3, vkf4: vertical-only estimate (no "
        "horizontal track): CSV only"]


def test_export_online_from_the_command_line(run_dir, tmp_path, capsys):
    copy = tmp_path / "run"
    shutil.copytree(run_dir, copy, ignore=shutil.ignore_patterns("export"))
    assert main(["export", str(copy), "--online", "--format", "csv,tum"]) == 0
    assert "skipped tum of loop2.online, loop3.online, vkf4.online" in capsys.readouterr().out
    files = sorted(p.name for p in (copy / "export").iterdir())
    assert files == sorted(["ekf.online.csv", "ekf.online.tum", "loop2.online.csv",
                            "loop3.online.csv", "vkf4.online.csv", "truth.csv", "truth.tum"]
                           + [f"{n}.online.csv-metadata.json" for n in ("ekf", "loop2",
                                                                        "loop3", "vkf4")]
                           + ["truth.csv-metadata.json"])
    # the ekf's online answer: its covariance epochs from its alignment on (5 Hz from 20 s)
    t = pd.read_csv(copy / "export" / "ekf.online.csv")["t_s"].to_numpy()
    np.testing.assert_allclose(t, 20.0 + 0.2 * np.arange(t.size), rtol=0, atol=1e-9)
    assert t[-1] == pytest.approx(240.0)


@pytest.mark.parametrize("argv, needle", [
    (["export", "{tmp}", "--format", "csv"], "not a run folder"),
    (["export", "{run}", "--format", "shp"], "unknown export format 'shp'"),
    (["export", "{run}", "--format", "cvs"], "did you mean 'csv'?"),
    (["export", "{run}", "--format", "csv", "--estimators", "ekf-rst"], "did you mean 'ekf-rts'?"),
    (["export", "{run}", "--online", "--estimators", "ekf-rts"], "'ekf-rts' has no online"),
    (["run", "--export", "xls", "--out", "{tmp}/o"], "unknown export format 'xls'"),
])
def test_bad_input_one_line_exit_2(run_dir, tmp_path, argv, needle):
    argv = [a.format(tmp=tmp_path, run=run_dir) for a in argv]
    r = subprocess.run([sys.executable, "-m", "vnav_graph", *argv], capture_output=True,
                       text=True, cwd=tmp_path)
    assert r.returncode == 2, r.stderr
    assert needle in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "o").exists()
