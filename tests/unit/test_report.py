"""Report: altitude errors/σ against closed forms, PNGs written, HTML self-contained and
carrying the table, the baro parameters, the failures and exactly the written images."""

from __future__ import annotations

import base64
import re

import numpy as np
import pytest

from vnav_graph.cli import main
from vnav_graph.estimators import base
from vnav_graph.evaluation.montecarlo import shorten_scenario
from vnav_graph.pipeline import RunResult, summarize
from vnav_graph.report import write_report
from vnav_graph.report.plots import altitude_errors, baro_histories, decimate, outage_windows
from vnav_graph.simulation import simulate
from vnav_graph.types import BaroEstimate, Estimate, ParamEstimate, Trajectory

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
OFFSET_M = 1.5
SD_M = 2.0


@pytest.fixture(scope="module")
def drive():
    return simulate(shorten_scenario("hill-drive", 60.0), 7)  # GNSS outage 30-45 s


def shifted_truth(drive, name="shifted"):
    """Truth raised by OFFSET_M with a constant altitude σ = SD_M, a baro bias history and
    final baro parameters."""
    tr = drive.truth
    t = tr.t[::20]
    lla = tr.lla[::20].copy()
    lla[:, 2] += OFFSET_M
    cov = np.full((t.size, 18, 18), np.nan)
    cov[:, 2, 2] = SD_M**2
    cov[:, 17, 17] = 0.5**2
    baro = BaroEstimate(ParamEstimate(0.0123, 0.001), ParamEstimate(0.21, 0.02),
                        ParamEstimate(-1.25, 0.4))
    hist = {"t": t, "scale": np.linspace(0, 0.0123, t.size), "scale_sd": np.full(t.size, 1e-3)}
    return Estimate(name, Trajectory(t, lla, tr.vel_n[::20], bias_baro=tr.bias_baro[::20] + 0.3),
                    frozenset({"alt", "vel_d", "baro", "cov"}), cov=cov, t_cov=t, baro=baro,
                    runtime_s=0.5, info={"baro_history": hist})


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


def _results(drive):
    return [RunResult("shifted", shifted_truth(drive), None, 0.5),
            RunResult("broken", None, "RuntimeError: <b>boom</b>", 0.1)]


def test_write_report_files_and_html(drive, tmp_path):
    results = _results(drive)
    summary = summarize(drive, results)
    written = write_report(tmp_path, summary, results, drive)
    pngs = sorted(p.name for p in (tmp_path / "plots").iterdir())
    assert pngs == ["altitude_error.png", "baro_convergence.png", "baro_parameters.png",
                    "vertical_velocity_error.png"]
    assert {p.name for p in written} == set(pngs) | {"report.html"}
    for p in pngs:
        assert (tmp_path / "plots" / p).read_bytes()[:8] == PNG_MAGIC
    page = (tmp_path / "report.html").read_text(encoding="utf-8")
    embedded = re.findall(r'src="data:image/png;base64,([A-Za-z0-9+/=]+)"', page)
    # every written PNG is embedded byte for byte, and nothing else is referenced
    assert sorted(base64.b64decode(b) for b in embedded) == sorted(
        (tmp_path / "plots" / p).read_bytes() for p in pngs)
    assert "src=\"http" not in page and "<link" not in page
    m = summary["estimators"]["shifted"]
    assert m["alt_rmse_m"] == pytest.approx(OFFSET_M, abs=1e-9)
    assert f"<td>{m['alt_rmse_m']:.3f}</td>" in page  # the comparison table row
    assert "1.230 ± 0.100" in page and "210 ± 20" in page and "-1.25 ± 0.40" in page
    assert f"{drive.baro_truth.scale * 100:.3f}" in page  # truth row of the baro table
    assert "&lt;b&gt;boom&lt;/b&gt;" in page and "<b>boom</b>" not in page  # escaped
    assert "hill-drive-seed7" in page and "[[30.0, 45.0]]" in page  # drive info


def test_report_without_truth_compares_with_gnss(drive, tmp_path):
    no_truth = drive.replace(truth=None, baro_truth=None)
    results = _results(drive)
    summary = summarize(no_truth, results)
    write_report(tmp_path, summary, results, no_truth)
    page = (tmp_path / "report.html").read_text(encoding="utf-8")
    assert "errors against GNSS fixes" in page
    assert (tmp_path / "plots" / "altitude_error.png").read_bytes()[:8] == PNG_MAGIC


def test_cli_run_writes_report(tmp_path, monkeypatch):
    monkeypatch.setitem(base._REGISTRY, "shifted", lambda: _Shifted())
    out = tmp_path / "out"
    assert main(["run", "--scenario", "default", "--duration", "30", "--estimators", "shifted",
                 "--out", str(out), "--no-progress"]) == 0
    page = (out / "report.html").read_text(encoding="utf-8")
    assert page.count("data:image/png;base64,") == len(list((out / "plots").glob("*.png"))) == 4
    assert not list(out.glob(".vnav-tmp-*"))  # the temporary directory is gone


class _Shifted:
    name = "shifted"

    def run(self, drive):
        return shifted_truth(drive)
