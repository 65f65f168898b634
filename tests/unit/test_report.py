"""Report: error series against closed forms, PNGs written, HTML self-contained, its table
equal to summary.json number for number, true captions, clipping notes, the headline, and a
real-log-like run scored and drawn against withheld GNSS."""

from __future__ import annotations

import base64
import json
import re
from html.parser import HTMLParser

import numpy as np
import pytest

from vnav_graph.cli import main
from vnav_graph.evaluation.montecarlo import shorten_scenario
from vnav_graph.geo.earth import radii
from vnav_graph.io import save_npz
from vnav_graph.report import write_report
from vnav_graph.report.canvas import decimate
from vnav_graph.report.errors import altitude_errors, outage_windows
from vnav_graph.report.groups import group_names, robust_limits
from vnav_graph.report.html import COLUMNS
from vnav_graph.report.plots import baro_histories
from vnav_graph.run.pipeline import RunResult, format_table, summarize
from vnav_graph.simulation import simulate
from vnav_graph.types import BaroEstimate, Drive, Estimate, ParamEstimate, Trajectory
from vnav_graph.types.streams import GnssStream, ImuStream

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
OFFSET_M = 1.5
SD_M = 2.0


@pytest.fixture(scope="module")
def drive():
    return simulate(shorten_scenario("hill-drive", 60.0), 7)  # GNSS outage 30-45 s


def shifted_truth(drive, name="shifted", offset=OFFSET_M, spike=None):
    """Truth raised by ``offset`` with a constant altitude σ = SD_M, a baro bias history and
    final baro parameters; ``spike`` (m) is added to 3 samples around t = 20 s."""
    tr = drive.truth
    t = tr.t[::20]
    lla = tr.lla[::20].copy()
    lla[:, 2] += offset
    if spike is not None:
        k = int(np.searchsorted(t, 20.0))
        lla[k:k + 3, 2] += spike
    cov = np.full((t.size, 18, 18), np.nan)
    cov[:, 2, 2] = SD_M**2
    cov[:, 17, 17] = 0.5**2
    baro = BaroEstimate(ParamEstimate(0.0123, 0.001), ParamEstimate(0.21, 0.02),
                        ParamEstimate(-1.25, 0.4))
    hist = {"t": t, "scale": np.linspace(0, 0.0123, t.size), "scale_sd": np.full(t.size, 1e-3)}
    return Estimate(name, Trajectory(t, lla, tr.vel_n[::20], bias_baro=tr.bias_baro[::20] + 0.3),
                    frozenset({"alt", "vel_d", "baro", "cov"}), cov=cov, t_cov=t, baro=baro,
                    runtime_s=0.5, info={"baro_history": hist})


class _Table(HTMLParser):
    """Cells of ``<table id="comparison">``: header keys (``data-key``) and rows by name."""

    def __init__(self) -> None:
        super().__init__()
        self.inside, self.keys, self.rows, self.cell = False, [], {}, None
        self.row: list[str] = []

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "table" and a.get("id") == "comparison":
            self.inside = True
        elif self.inside and tag == "th" and "data-key" in a:
            self.keys.append(a["data-key"])
        elif self.inside and tag == "tr":
            self.row, self.name = [], a.get("data-name")
        elif self.inside and tag == "td":
            self.cell = ""

    def handle_data(self, data):
        if self.cell is not None:
            self.cell += data

    def handle_endtag(self, tag):
        if tag == "td" and self.cell is not None:
            self.row.append(self.cell.strip())
            self.cell = None
        elif tag == "tr" and self.inside and self.name:
            self.rows[self.name] = dict(zip(["estimator", *self.keys], self.row, strict=True))
        elif tag == "table":
            self.inside = False


def assert_table_matches_summary(page: str, summary: dict) -> int:
    """Every cell of the comparison table equals the summary value at its display precision
    ("—" exactly where the summary has null). Returns the number of numbers compared."""
    p = _Table()
    p.feed(page)
    assert p.keys == [k for k, _, _ in COLUMNS]
    assert set(summary["estimators"]) <= set(p.rows)
    n = 0
    for name, m in summary["estimators"].items():
        row = p.rows[name]
        for key, _, spec in COLUMNS:
            if key == "status":
                assert row[key] == m["status"]
                continue
            v = (m["nees_mean"] / m["nees_dof"] if key == "nees_per_dof" and m.get("nees_dof")
                 else None if key == "nees_per_dof" else m.get(key))
            if v is None:
                assert row[key] == "—", (name, key, row[key])
            else:
                decimals = int(spec[1])
                assert float(row[key]) == pytest.approx(v, abs=0.51 * 10**-decimals), (name, key)
                n += 1
    return n


def test_altitude_errors_closed_form(drive):
    est = shifted_truth(drive)
    t, e, sd, ref = altitude_errors(est, drive)
    assert ref == "truth"
    # estimate = truth + 1.5 m at the truth's own epochs: only float round-off (~1e-13 m)
    np.testing.assert_allclose(e, OFFSET_M, atol=1e-9)
    np.testing.assert_allclose(sd, SD_M, rtol=1e-12)
    no_truth = drive.replace(truth=None, baro_truth=None)
    t, e, sd, ref = altitude_errors(est, no_truth)
    g = drive.gnss
    assert ref == "GNSS" and np.array_equal(t, g.t[g.t <= est.trajectory.t[-1]])
    expect = np.interp(t, drive.truth.t, drive.truth.alt) + OFFSET_M - g.lla[: t.size, 2]
    # the estimate is the 10 Hz-decimated truth, linearly interpolated to the GNSS epochs:
    # interpolation error over 0.1 s at vertical accelerations < 1 m/s² is < 1/8·a·dt² ≈ 1.3 mm
    np.testing.assert_allclose(e, expect, atol=2e-3)
    np.testing.assert_allclose(sd, np.sqrt(SD_M**2 + g.pos_sd[: t.size, 2] ** 2), rtol=1e-12)


def test_helpers(drive):
    assert len(range(10000)[decimate(10000)]) <= 1500
    assert outage_windows(drive) == [(30.0, 45.0)]
    # a window beyond the end of the drive is dropped
    assert outage_windows(simulate("hill-drive", 7, duration_s=60.0)) == []
    h = baro_histories(shifted_truth(drive))
    assert set(h) == {"scale", "bias_m"}
    np.testing.assert_allclose(h["bias_m"][2], 0.5)  # σ from cov[:, 17, 17]
    assert group_names(["loop2", "mine", "ekf", "graph-batch", "ekf-rts"]) == [
        ("smoothers", ["ekf-rts", "graph-batch"]), ("filters", ["ekf"]),
        ("loops and observers", ["loop2"]), ("other", ["mine"])]


def test_robust_limits_clip_only_outliers():
    rng = np.random.default_rng(1)
    base_err = rng.normal(0.0, 1.0, 2000)
    # three members of one scale: the limit fits them all, nothing is clipped
    lims = robust_limits({"loop2": base_err, "loop3": 1.2 * base_err, "observer1d": base_err})
    assert lims.clipped == {}
    assert lims.lim == pytest.approx(1.05 * np.max(np.abs(1.2 * base_err)))
    # one member with a −440 m excursion: the limit ignores it and a note names it
    bad = base_err.copy()
    bad[100:400] = -440.0
    lims = robust_limits({"loop2": base_err, "loop3": 1.2 * base_err, "observer1d": bad})
    assert lims.lim < 10.0
    assert lims.notes("m") == ["observer1d clipped: max |err| 440 m"]


def _results(drive):
    return [RunResult("shifted", shifted_truth(drive), None, 0.5),
            RunResult("broken", None, "RuntimeError: <b>boom</b>", 0.1)]


def test_write_report_files_and_html(drive, tmp_path):
    results = _results(drive)
    summary = summarize(drive, results)
    written = write_report(tmp_path, summary, results, drive)
    pngs = sorted(p.name for p in (tmp_path / "plots").iterdir())
    assert pngs == ["altitude_error.png", "baro_convergence.png", "baro_parameters.png",
                    "trajectory_map.png", "vertical_velocity_error.png"]
    assert {p.name for p in written} == set(pngs) | {"report.html"}
    for p in pngs:
        assert (tmp_path / "plots" / p).read_bytes()[:8] == PNG_MAGIC
    page = (tmp_path / "report.html").read_text(encoding="utf-8")
    embedded = re.findall(r'src="data:image/png;base64,([A-Za-z0-9+/=]+)"', page)
    # every written PNG is embedded byte for byte, and nothing else is referenced
    assert sorted(base64.b64decode(b) for b in embedded) == sorted(
        (tmp_path / "plots" / p).read_bytes() for p in pngs)
    assert "src=\"http" not in page and "<link" not in page
    assert summary["estimators"]["shifted"]["alt_rmse_m"] == pytest.approx(OFFSET_M, abs=1e-9)
    assert assert_table_matches_summary(page, summary) >= 4
    assert "1.230 ± 0.100" in page and "210 ± 20" in page and "-1.25 ± 0.40" in page
    assert f"{drive.baro_truth.scale * 100:.3f}" in page  # truth row of the baro table
    assert "&lt;b&gt;boom&lt;/b&gt;" in page and "<b>boom</b>" not in page  # escaped
    assert "hill-drive-seed7" in page and "[[30.0, 45.0]]" in page  # drive info
    # captions are true for a simulated drive: truth, and the outage shaded
    assert "against the simulation truth" in page and "the 1 simulated GNSS outage(s)" in page
    assert "withheld" not in page
    # run metadata (summary keys added for the report)
    assert (summary["version"], summary["scenario"], summary["seed"]) == (
        "0.1.0", "hill-drive", 7)
    assert summary["repairs"] == [] and 'id="repairs"' in page


def test_table_and_headline_agree_with_summary(drive, tmp_path):
    """Three stand-ins 0.5 / 1.5 / 2.5 m off truth: the table shows the summary's numbers,
    and the headline, in the HTML and in the terminal table alike, says that 2 time blocks
    cannot rank them and what would."""
    results = [RunResult(n, shifted_truth(drive, n, off), None, 0.5)
               for n, off in (("ekf", 1.5), ("graph-batch", 0.5), ("loop3", 2.5))]
    summary = summarize(drive, results)
    h = summary["comparison"]["metrics"]["alt_rmse_m"]
    assert (h["best"], h["runner_up"]) == ("graph-batch", "ekf")
    assert h["diff"] == pytest.approx(1.0, abs=1e-6)
    # the offset is the same in every block: the paired interval collapses onto +1 m
    assert h["ci95"] == pytest.approx([1.0, 1.0], abs=1e-6) and h["verdict"] == "better"
    write_report(tmp_path, summary, results, drive)
    page = (tmp_path / "report.html").read_text(encoding="utf-8")
    assert assert_table_matches_summary(page, summary) == 3 * 6
    # a drive of 2 time blocks cannot rank: one line says so and what would, in both places
    assert h["n_blocks"] == 2
    (line,) = summary["comparison"]["headline"]
    assert line.startswith("Not resolved: 2 paired time block(s) cannot rank the estimators")
    assert line.endswith("; a drive of at least 120 s (--duration 120) gives 4 time blocks.")
    assert f'<p class="headline">{line}</p>' in page
    text = format_table(summary)
    assert f"HEADLINE {line}" in text
    assert "OFFLINE" not in text and "CI [" not in text  # no ranking, no CI
    assert "No ranking: too few paired blocks or windows" in page
    head = next(x for x in text.splitlines() if x.startswith("estimator"))
    for unit in ("alt RMSE m", "horiz RMSE m", "vD RMSE m/s", "scale %", "latency ms",
                 "bias m", "run s"):
        assert unit in head


def test_clipping_note_in_caption(drive, tmp_path):
    """A loop with a 440 m spike is clipped and named in the caption; without the spike the
    same family draws unclipped."""
    def run(spike):
        results = [RunResult(n, shifted_truth(drive, n, off, spike if n == "observer1d"
                                              else None), None, 0.5)
                   for n, off in (("observer1d", 1.0), ("loop2", 1.2), ("loop3", 0.8))]
        summary = summarize(drive, results)
        write_report(tmp_path, summary, results, drive)
        return (tmp_path / "report.html").read_text(encoding="utf-8")

    assert "observer1d clipped: max |err| 441 m" in run(440.0)
    assert "clipped" not in run(None)


# ---- a log without truth: scored and drawn against withheld GNSS ----------------------------

def _flat_log(tmp_path):
    """600 s, GNSS 1 Hz with velocity, climbing 0.05 m/s and moving north 2 m/s, saved as a
    log (no truth), with a reader note."""
    t_imu = np.arange(0.0, 600.0, 0.1)
    # sensor noise: an IMU repeating one value exactly is a stuck logger (io.sanity removes it)
    noise = np.random.default_rng(3).normal(0.0, 1e-3, (2, t_imu.size, 3))
    imu = ImuStream(t_imu, noise[0], np.tile([0, 0, -9.8], (t_imu.size, 1)) + noise[1])
    t = np.arange(0.0, 600.0)
    rn, _ = radii(0.8)
    lla = np.column_stack([0.8 + 2.0 * t / (rn + 500.0), np.full(t.size, 0.2),
                           500.0 + 0.05 * t])
    vel = np.tile([2.0, 0.0, -0.05], (t.size, 1))
    gnss = GnssStream(t, lla, np.tile([1.0, 1.0, 2.0], (t.size, 1)), vel,
                      np.full((t.size, 3), 0.1))
    # the autopilot's own height: the true path, 0.7 m high inside the holdout windows
    from vnav_graph.evaluation.holdout import choose_windows, in_windows

    high = 0.7 * in_windows(t, choose_windows(t))
    onboard = {"t": t.tolist(), "alt": (lla[:, 2] + high).tolist(),
               "name": "ctun.alt (planted)", "offset_m": 0.0, "reference": "msl"}
    d = Drive(imu, gnss, None, lla[0], meta={
        "name": "flat", "source": "log", "notes": ["CLOCK REPAIRED: planted note"],
        "onboard": onboard})
    path = tmp_path / "flat.npz"
    save_npz(d, path)
    return path


class _Planted:
    """The true path + 3 m (datum offset, removed by scoring); inside the withheld windows
    ``alt`` m higher, 1 m north and v_D 0.3 m/s off. ``alt`` may differ per window."""

    def __init__(self, name, alt):
        self.name, self.alt = name, alt

    def run(self, drive):
        t = drive.imu.t
        rn, _ = radii(0.8)
        dh = np.zeros(t.size)
        inside = np.zeros(t.size, bool)
        for k, (a, b) in enumerate(drive.meta.get("gnss_holdout_windows", [])):
            m = (t >= a) & (t <= b)
            inside |= m
            dh[m] = self.alt[k % len(self.alt)]
        lla = np.column_stack([0.8 + (2.0 * t + inside) / (rn + 500.0),
                               np.full(t.size, 0.2), 500.0 + 0.05 * t + 3.0 + dh])
        vel = np.column_stack([np.full(t.size, 2.0), np.zeros(t.size), -0.05 + 0.3 * inside])
        return Estimate(self.name, Trajectory(t, lla, vel), frozenset({"alt", "pos_h", "vel_d"}),
                        runtime_s=0.01)


def test_log_run_is_scored_and_drawn_against_withheld_gnss(tmp_path, monkeypatch, registry):
    registry("ekf-rts", lambda: _Planted("ekf-rts", [2.0]))
    # per window 3, 1, 3, 1 m: RMSE sqrt(5) = 2.24 m overall, paired differences +1, −1, +1, −1
    registry("graph-batch", lambda: _Planted("graph-batch", [3, 1]))
    out = tmp_path / "out"
    assert main(["run", str(_flat_log(tmp_path)), "--estimators", "ekf-rts,graph-batch",
                 "--out", str(out), "--no-progress"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    a, b = summary["estimators"]["ekf-rts"], summary["estimators"]["graph-batch"]
    # exact planted errors (linear interpolation of linear paths; windows hold whole epochs)
    assert a["alt_rmse_m"] == pytest.approx(2.0, abs=1e-9)
    assert a["horiz_rmse_m"] == pytest.approx(1.0, abs=1e-3)  # tangent plane vs arc: < 1 mm
    assert a["vel_down_rmse_mps"] == pytest.approx(0.3, abs=1e-9)
    assert b["alt_rmse_m"] == pytest.approx(np.sqrt(5.0), abs=1e-9)
    per_window = summary["comparison"]["per_block"]["graph-batch"]
    assert [w["alt_rmse_m"] for w in per_window] == pytest.approx([3, 1, 3, 1])
    h = summary["comparison"]["metrics"]["alt_rmse_m"]
    assert (h["best"], h["verdict"], h["n_blocks"]) == ("ekf-rts", "tied", 4)
    assert summary["seed"] is None and summary["scenario"] is None
    assert "CLOCK REPAIRED: planted note" in summary["repairs"]
    page = (out / "report.html").read_text(encoding="utf-8")
    assert assert_table_matches_summary(page, summary) == 2 * 6
    assert "CLOCK REPAIRED: planted note" in page
    # d = +1, −1, +1, −1 over 4 windows: not resolved, said with its measured reason
    assert ("Altitude RMSE: ekf-rts lowest at 2.00 m; graph-batch (2.24 m) not resolved from "
            "it: the paired 95 % CI [-1.84, +1.84] m contains 0.") in page
    assert "tied" not in page and "not separated" not in page
    assert "withheld from it, at those fixes only" in page and "shaded: the withheld" in page
    assert "simulation truth" not in page
    text = (out / "summary.txt").read_text()
    assert "HEADLINE Altitude RMSE: ekf-rts lowest at 2.00 m; graph-batch (2.24 m) not " in text
    assert "tied" not in text
    # the onboard estimate: no offset on the given fixes, +0.7 m at every withheld one
    ob = summary["evaluation"]["onboard"]
    assert ob["alt_rmse_m"] == pytest.approx(0.7, abs=1e-9)
    assert re.search(r"onboard\*\s+ok\s+0\.70\s+0\.70", text)
    assert "<td>0.700</td>" in page
    assert 'data-name="onboard"><td>onboard: ctun.alt (planted)*</td>' in page


def test_log_run_without_holdout_claims_no_score(tmp_path, monkeypatch, registry):
    registry("ekf-rts", lambda: _Planted("ekf-rts", [2.0]))
    out = tmp_path / "out"
    assert main(["run", str(_flat_log(tmp_path)), "--estimators", "ekf-rts", "--no-holdout",
                 "--out", str(out), "--no-progress"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["comparison"] is None and summary["estimators"]["ekf-rts"]["alt_rmse_m"] is None
    page = (out / "report.html").read_text(encoding="utf-8")
    assert assert_table_matches_summary(page, summary) == 2  # runtime and × real time only
    assert "No headline: a log without truth is scored only by the holdout run" in page
    assert "a fit residual, not a score" in page and "RMSE" in page
    assert "withheld from it" not in page


def test_plotted_errors_are_the_scored_ones(tmp_path, monkeypatch, registry):
    """The series the report draws for a log are the holdout errors at the withheld fixes:
    their RMS is the summary's number (the old report drew residuals against the GNSS the
    estimator had been given: 0.0 m here)."""
    from vnav_graph.io import load_drive
    from vnav_graph.report.errors import error_set
    from vnav_graph.run.pipeline import apply_holdout, run_estimators
    from vnav_graph.run.runner import run_holdout

    registry("ekf-rts", lambda: _Planted("ekf-rts", [2.0, 4.0]))
    drive = load_drive(_flat_log(tmp_path))
    results = run_estimators(drive, ["ekf-rts"], progress=False)
    hold = run_holdout(drive, ["ekf-rts"])
    summary = apply_holdout(summarize(drive, results), hold.doc)
    es = error_set(drive, results, hold)
    (s,) = es.series
    assert es.basis == "withheld GNSS" and es.windows_only
    assert np.sqrt(np.mean(s.alt**2)) == pytest.approx(
        summary["estimators"]["ekf-rts"]["alt_rmse_m"], abs=1e-12)
    assert np.sqrt(np.mean(s.vd**2)) == pytest.approx(
        summary["estimators"]["ekf-rts"]["vel_down_rmse_mps"], abs=1e-12)
    assert np.sqrt(np.mean(s.alt**2)) == pytest.approx(np.sqrt(10.0), abs=1e-9)
    # the horizontal error drawn is the scored one (1 m north in every window)
    assert np.sqrt(np.mean(s.horiz**2)) == pytest.approx(
        summary["estimators"]["ekf-rts"]["horiz_rmse_m"], abs=1e-12)
    assert s.horiz_sd is None and s.heading is None
    assert set(hold.trajectories) == {"ekf-rts"}  # the map draws the holdout run's track


def test_cli_run_writes_report(tmp_path, monkeypatch, registry):
    registry("shifted", lambda: _Shifted())
    out = tmp_path / "out"
    assert main(["run", "--scenario", "default", "--duration", "30", "--estimators", "shifted",
                 "--out", str(out), "--no-progress"]) == 0
    page = (out / "report.html").read_text(encoding="utf-8")
    assert page.count("data:image/png;base64,") == len(list((out / "plots").glob("*.png"))) == 5
    assert not list(out.glob(".vnav-tmp-*"))  # the temporary directory is gone


class _Shifted:
    name = "shifted"

    def run(self, drive):
        return shifted_truth(drive)


def test_reader_lines_say_each_fact_once():
    from vnav_graph.run.pipeline import reader_repairs

    meta = {"notes": ["CLOCK REPAIRED: the boot clock advanced 0.92315 s per GPS second"],
            "repaired": {"clock": {"boot-clock stamps rescaled to GPS seconds": 1}},
            "dropped": {"log": {"incomplete last record (file truncated)": 1},
                        "gnss": {"zero fix": 3}},
            "warnings": ["log: 1 incomplete last record (file truncated)"]}
    assert reader_repairs(meta) == [
        "CLOCK REPAIRED: the boot clock advanced 0.92315 s per GPS second",
        "gnss: dropped 3: zero fix"]


def test_real_log_baro_convergence_caption_says_it_shows_the_whole_log():
    from vnav_graph.report import captions
    from vnav_graph.report.errors import WITHHELD, ErrorSet

    es = ErrorSet(WITHHELD, [], [(100.0, 160.0), (250.0, 310.0)], True)
    cap = captions(es, {"evaluation": {"outage_s": 60.0}})
    assert "time axis shows only them" in cap["altitude_error.png"]
    assert "time axis shows only them" not in cap["baro_convergence.png"]
    assert "whole log" in cap["baro_convergence.png"]
