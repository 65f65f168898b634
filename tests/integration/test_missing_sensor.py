"""A drive without a barometer is a valid input: the estimators that need one are "skipped",
the others run, and ``run`` exits 0 when every estimator that could run succeeded."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from vnav_graph.cli import main
from vnav_graph.io import save_npz
from vnav_graph.run.pipeline import run_status
from vnav_graph.simulation import simulate
from vnav_graph.util.failures import MissingStream

NEED_BARO = ("loop2", "loop3", "loop3-adaptive", "vkf4", "vekf7")
NO_BARO_OK = ("observer1d", "ekf")


@pytest.fixture(scope="module")
def no_baro(tmp_path_factory) -> tuple[Path, Path]:
    """The simulated hill drive (120 s) with its baro stream removed: with truth, and
    without it (as a real log, scored by the holdout)."""
    d = simulate("hill-drive", 1, duration_s=120.0).replace(baro=None)
    root = tmp_path_factory.mktemp("no-baro")
    return (save_npz(d, root / "truth.npz"),
            save_npz(d.replace(truth=None), root / "log.npz"))


def test_run_skips_the_estimators_that_need_a_barometer(no_baro, tmp_path, capsys) -> None:
    out = tmp_path / "run"
    names = ",".join(NO_BARO_OK[:1] + NEED_BARO + NO_BARO_OK[1:])
    code = main(["run", str(no_baro[0]), "--estimators", names, "--out", str(out),
                 "--no-progress"])
    cap = capsys.readouterr()
    ests = json.loads((out / "summary.json").read_text())["estimators"]
    assert {n: b["status"] for n, b in ests.items()} == {
        **{n: "skipped" for n in NEED_BARO}, **{n: "ok" for n in NO_BARO_OK}}
    assert code == 0
    for n in NEED_BARO:
        assert ests[n]["error"] == "no barometer"
        assert ests[n]["alt_rmse_m"] is None and ests[n]["baro"]["scale"]["est"] is None
        assert f"{n} skipped: no barometer" in cap.out
        assert not (out / "estimates" / f"{n}.parquet").exists()
    for n in NO_BARO_OK:
        assert ests[n]["error"] is None and 0.0 < ests[n]["alt_rmse_m"] < 5.0
        assert (out / "estimates" / f"{n}.parquet").exists()
    assert "5 of 7 estimators skipped (loop2: no barometer)" in cap.err
    assert "failed" not in cap.err


def test_holdout_reports_skipped_estimators(no_baro, tmp_path, capsys) -> None:
    out = tmp_path / "holdout"
    assert main(["holdout", str(no_baro[1]), "--estimators", "vkf4,observer1d",
                 "--out", str(out), "--no-progress"]) == 0
    doc = json.loads((out / "holdout.json").read_text())["estimators"]
    assert doc["vkf4"]["status"] == "skipped" and doc["vkf4"]["error"] == "no barometer"
    assert doc["vkf4"]["n_scored"] == 0 and doc["vkf4"]["alt_rmse_m"] is None
    assert doc["observer1d"]["status"] == "ok" and doc["observer1d"]["n_scored"] > 0
    assert "| vkf4 | skipped: no barometer |" in capsys.readouterr().out


def _summary(**status: str) -> dict:
    return {"estimators": {n: {"status": s, "error": None if s == "ok" else
                               ("no barometer" if s == "skipped" else "RuntimeError: x")}
                           for n, s in status.items()}}


def test_exit_code_counts_failures_among_the_estimators_that_could_run() -> None:
    assert run_status(_summary(a="ok", b="skipped")) == (
        0, "1 of 2 estimators skipped (b: no barometer)")
    assert run_status(_summary(a="ok", b="skipped", c="failed")) == (
        3, "1 of 3 estimators failed (c: RuntimeError: x)")
    assert run_status(_summary(b="skipped", c="failed")) == (
        4, "every estimator failed (c: RuntimeError: x)")
    assert run_status(_summary(b="skipped", d="skipped")) == (
        4, "no estimator could run on this drive (b: no barometer)")
    assert run_status(_summary(a="ok")) == (0, None)


def test_phone_folder_without_barometer_csv(tmp_path, capsys) -> None:
    """The reader's path: a Sensor Logger folder with its Barometer.csv removed."""
    folder = tmp_path / "phone"
    shutil.copytree(Path(__file__).resolve().parents[1] / "data" / "sensorlogger_ski_cut", folder)
    (folder / "Barometer.csv").unlink()
    out = tmp_path / "out"
    code = main(["run", str(folder), "--estimators", "loop3,vekf7,observer1d,ekf-rts",
                 "--out", str(out), "--no-progress"])
    cap = capsys.readouterr()
    ests = json.loads((out / "summary.json").read_text())["estimators"]
    assert {n: (b["status"], b["error"]) for n, b in ests.items()} == {
        "loop3": ("skipped", "no barometer"), "vekf7": ("skipped", "no barometer"),
        "observer1d": ("ok", None), "ekf-rts": ("ok", None)}
    assert code == 0 and "2 of 4 estimators skipped" in cap.err


class _NeedsBaro:
    name = "needs-baro"

    def run(self, drive):
        raise MissingStream("barometer", "needs-baro: the drive has no barometer stream")


def test_bench_rows_of_a_missing_stream_are_skipped_not_failed(monkeypatch) -> None:
    from vnav_graph.evaluation.montecarlo import aggregate, failure_summary, format_bench_md
    from vnav_graph.run import runner
    from vnav_graph.run.bench import BenchTask, run_tasks

    monkeypatch.setattr(runner, "create", lambda name, config=None: _NeedsBaro())
    rows = run_tasks([BenchTask("hill-drive", 0, "needs-baro", 30.0)], workers=1)
    assert [(r["status"], r["error"], r["alt_rmse_m"]) for r in rows] == [
        ("skipped", "no barometer", None)]
    doc = {"config": {"scenarios": ["hill-drive"], "seeds": [0], "duration_s": 30.0,
                      "executor": "local", "wall_s": 1.0},
           "runs": rows, "aggregate": aggregate(rows)}
    assert failure_summary(doc) is None
    md = format_bench_md(doc)
    assert "## Skipped runs" in md and "| hill-drive | 0 | needs-baro | no barometer |" in md
    assert "## Failed runs" not in md
