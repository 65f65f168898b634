"""Online answers taken out of a run: ``estimates/<name>.online.parquet`` holds exactly a causal
estimator's online epochs (ekf, graph-isam2) and no pure smoother has one; ``export --online``
writes ``<name>.online.<ext>`` files that say "online"; the CSV has one header row and
latitude/longitude in degrees equal to the estimate's within 1e-9 deg."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from vnav_graph.export import export_run, write_run_info
from vnav_graph.run.pipeline import online_table, run_estimators, summarize, write_outputs
from vnav_graph.simulation import simulate

pytestmark = pytest.mark.slow
NAMES = ["ekf", "graph-isam2", "ekf-rts", "graph-batch"]


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """The default drive's first 60 s through two causal estimators and two smoothers,
    written as ``vnav-graph run`` writes it; the estimates kept for comparison."""
    out = tmp_path_factory.mktemp("online") / "run"
    drive = simulate("default", 0, duration_s=60.0)
    results = run_estimators(drive, NAMES, progress=False)
    assert all(r.estimate is not None for r in results), [r.error for r in results]
    write_outputs(out, summarize(drive, results), results, drive, [write_run_info])
    return out, {r.name: r.estimate for r in results}


def test_online_parquet_holds_only_the_online_epochs(run):
    out, est = run
    for name in ("ekf", "graph-isam2"):
        e = est[name]
        back = pd.read_parquet(out / "estimates" / f"{name}.online.parquet")
        np.testing.assert_array_equal(back["t_s"], e.online.t)
        np.testing.assert_array_equal(back["alt_m"], e.online.alt)
        np.testing.assert_array_equal(back["lat_rad"], e.online.lla[:, 0])
        # the sigmas are the online covariance's, at its own epochs
        np.testing.assert_allclose(back["alt_sd_m"], np.sqrt(e.online_cov[:, 2, 2]), rtol=1e-15)
        # a whole-drive calibration is not an online answer
        assert "baro_scale" not in back and "baro_latency_s" not in back
        final = pd.read_parquet(out / "estimates" / f"{name}.parquet")
        # the ekf's online answer is at its covariance epochs, graph-isam2's real-time output
        # at the output rate (its keyframes and the IMU propagation between them)
        assert len(back) < len(final) if name == "ekf" else len(back) <= len(final)
        pd.testing.assert_frame_equal(back, online_table(e, e.origin_lla))
    # the ekf is online once aligned (summary's online from_s), at its covariance epochs
    ekf = pd.read_parquet(out / "estimates" / "ekf.online.parquet")["t_s"].to_numpy()
    assert ekf[0] == est["ekf"].info["online_from_s"] > 0
    np.testing.assert_array_equal(ekf, est["ekf"].t_cov[est["ekf"].t_cov >= ekf[0]])
    for name in ("ekf-rts", "graph-batch"):
        assert not (out / "estimates" / f"{name}.online.parquet").exists()


def test_export_online_writes_files_named_online(run):
    out, est = run
    res = export_run(out, "csv,tum,kml", online=True)
    names = sorted(p.name for p in res.written)
    assert names == ["all.online.kml", "ekf.online.csv", "ekf.online.csv-metadata.json",
                     "ekf.online.kml", "ekf.online.tum", "graph-isam2.online.csv",
                     "graph-isam2.online.csv-metadata.json", "graph-isam2.online.kml",
                     "graph-isam2.online.tum", "truth.csv", "truth.csv-metadata.json",
                     "truth.kml", "truth.tum"]
    exp = out / "export"
    meta = json.loads((exp / "ekf.online.csv-metadata.json").read_text())
    assert meta["dc:description"].startswith("online (real-time) estimate")
    assert any("from t = 20 s" in c for c in meta["rdfs:comment"])
    head = [ln for ln in (exp / "graph-isam2.online.tum").read_text().splitlines()
            if ln.startswith("#")]
    assert head[0].endswith("graph-isam2 (online)")
    assert any("online (real-time) estimate" in ln for ln in head)
    # evo reads it (its reader skips the # lines); the poses are the online epochs'
    evo_fi = pytest.importorskip("evo.tools.file_interface")
    tum = evo_fi.read_tum_trajectory_file(str(exp / "graph-isam2.online.tum"))
    t_online = est["graph-isam2"].online.t
    assert set(np.round(tum.timestamps, 6)) <= set(np.round(t_online, 6))


def test_final_files_say_final(run):
    out, _ = run
    export_run(out, "csv,tum,gpx", ["graph-batch"])
    exp = out / "export"
    meta = json.loads((exp / "graph-batch.csv-metadata.json").read_text())
    assert meta["dc:description"].startswith("final trajectory")
    assert (exp / "graph-batch.tum").read_text().startswith("# vnav_graph ")
    assert "graph-batch (final)" in (exp / "graph-batch.tum").read_text().splitlines()[0]
    assert "final trajectory" in (exp / "graph-batch.gpx").read_text()


@pytest.mark.parametrize("name, online", [("ekf", False), ("graph-isam2", False),
                                          ("ekf", True), ("graph-isam2", True)])
def test_csv_one_header_row_and_degrees_of_the_estimate(run, name, online):
    out, est = run
    export_run(out, "csv", [name], online=online, full_rate=True)
    stem = f"{name}.online" if online else name
    path = out / "export" / f"{stem}.csv"
    assert path.read_text().splitlines()[0].startswith("t_s,lat_deg,lon_deg,alt_m,")
    back = pd.read_csv(path)  # no options: one header row, no comment lines
    assert all(np.issubdtype(back[c].dtype, np.number) for c in back.columns)  # no text row
    tr = est[name].online if online else est[name].trajectory
    np.testing.assert_array_equal(np.round(back["t_s"], 6), np.round(tr.t, 6))
    np.testing.assert_allclose(back["lat_deg"], np.degrees(tr.lla[:, 0]), rtol=0, atol=1e-9)
    np.testing.assert_allclose(back["lon_deg"], np.degrees(tr.lla[:, 1]), rtol=0, atol=1e-9)
    np.testing.assert_allclose(back["alt_m"], tr.alt, rtol=1e-11, atol=0)
    np.testing.assert_allclose(back["yaw_deg"], np.degrees(tr.to_rph()[:, 2]), rtol=0,
                               atol=1e-9)


def test_export_online_of_a_smoother_is_one_line(run):
    out, _ = run
    with pytest.raises(ValueError) as err:
        export_run(out, "csv", ["graph-batch"], online=True)
    msg = str(err.value)
    assert "'graph-batch' has no online estimate" in msg and "ekf, graph-isam2" in msg
    assert "\n" not in msg
