"""CLI contracts: simulate/run outputs, and bad input → one line on stderr, exit 2."""

import json
import subprocess
import sys

import pytest

from vnav_graph.cli import main
from vnav_graph.estimators.base import available


def test_simulate_then_run_writes_summary(tmp_path, capsys):
    drv = tmp_path / "d.npz"
    assert main(["simulate", "--scenario", "hill-drive", "--seed", "3", "--duration", "40",
                 "-o", str(drv)]) == 0
    out = tmp_path / "out"
    names = [n for n in available() if n in ("loop3", "ekf", "vkf4")]
    args = ["run", str(drv), "--out", str(out)]
    if names:
        args += ["--estimators", ",".join(names)]
    else:
        args += ["--estimators", ""]
    assert main(args) == 0
    s = json.loads((out / "summary.json").read_text())
    assert s["schema"] == "vnav_graph.summary/1"
    assert s["drive"] == {"name": "hill-drive-seed3", "source": "simulated",
                          "duration_s": pytest.approx(40.0)}
    for m in s["estimators"].values():
        assert set(m) >= {"status", "error", "alt_rmse_m", "alt_max_abs_m", "vel_down_rmse_mps",
                          "nees_mean", "runtime_s", "realtime_factor", "baro", "online", "lag"}
        assert set(m["baro"]) == {"scale", "latency_s", "bias_m"}
        # every causal estimator is scored online too; none of these has a fixed-lag answer
        assert set(m["online"]) >= {"alt_rmse_m", "horiz_rmse_m", "heading_rmse_deg",
                                    "vel_down_rmse_mps", "nees_mean", "nees_dof"}
        assert m["online"]["alt_rmse_m"] > 0 and m["lag"] is None
    if "vkf4" in s["estimators"]:  # a filter's online estimate is its trajectory
        m = s["estimators"]["vkf4"]
        assert m["online"]["nees_mean"] == pytest.approx(m["nees_mean"], rel=1e-12)
    assert set(s["rankings"]) == {"real_time", "offline"}


@pytest.mark.parametrize(
    "argv, needle",
    [(["run", "missing.npz"], "no such file"),
     (["run", "--estimators", "nope"], "unknown estimator"),
     (["run", "--scenario", "nope"], "unknown scenario"),
     (["simulate", "--scenario", "nope", "-o", "x.npz"], "unknown scenario"),
     (["run", "--seed", "abc"], "invalid int value")],
)
def test_bad_input_one_line_exit_2(tmp_path, argv, needle):
    r = subprocess.run([sys.executable, "-m", "vnav_graph", *argv, "--out", str(tmp_path / "o")]
                       if argv[0] == "run" else [sys.executable, "-m", "vnav_graph", *argv],
                       capture_output=True, text=True, cwd=tmp_path)
    assert r.returncode == 2
    assert needle in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1  # one line, no traceback
    assert not (tmp_path / "o" / "summary.json").exists()  # nothing written


def test_corrupt_drive_exit_2(tmp_path):
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"PK\x03\x04 this is not a zip")
    r = subprocess.run([sys.executable, "-m", "vnav_graph", "run", str(bad), "--out",
                        str(tmp_path / "o")], capture_output=True, text=True)
    assert r.returncode == 2 and "bad.npz" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "o").exists()


def test_run_on_real_log_scores_against_withheld_gnss(tmp_path):
    """A real log has no truth: run fills alt metrics from a holdout run and says so."""
    from pathlib import Path

    avail = available()
    if "vkf4" not in avail:
        pytest.skip("vkf4 not in this build")
    log = Path(__file__).resolve().parents[1] / "data" / "sensorlogger_car_1hz_cut.csv"
    out = tmp_path / "o"
    assert main(["run", str(log), "--estimators", "vkf4", "--out", str(out)]) == 0
    s = json.loads((out / "summary.json").read_text())
    assert s["drive"]["source"] == "log"
    assert s["evaluation"]["basis"].startswith("withheld GNSS")
    m = s["estimators"]["vkf4"]
    assert m["status"] == "ok"
    # 200 s car cut, 1 Hz GNSS: the score is a real number of metres, not null or fake zero
    # (measured 5.65 m against the one 60 s window of withheld phone fixes)
    assert m["alt_rmse_m"] is not None and 0.0 < m["alt_rmse_m"] < 10.0
    assert m["nees_mean"] is None  # no reference for NEES on a real log
    assert s["estimators"]["vkf4"]["baro"]["bias_m"]["truth"] is None


def test_run_takes_the_holdout_windows_like_holdout(tmp_path):
    """``run --outage / --spacing`` on a real log set the withheld-GNSS windows it is scored
    in, as ``holdout`` does (the hint for a log too short names ``--outage``)."""
    from pathlib import Path

    log = Path(__file__).resolve().parents[1] / "data" / "sensorlogger_car_1hz_cut.csv"
    out = tmp_path / "o"
    code = main(["run", str(log), "--estimators", "vkf4", "--outage", "30", "--out", str(out),
                 "--no-progress"])
    assert code == 0
    ev = json.loads((out / "summary.json").read_text())["evaluation"]
    assert ev["outage_s"] == 30.0
    assert all(abs((w["t1"] - w["t0"]) - 30.0) < 1e-9 if isinstance(w, dict)
               else abs((w[1] - w[0]) - 30.0) < 1e-9 for w in ev["windows"])


def test_help_explains_itself(capsys):
    """``--help`` and ``run --help``: no raw markup; run's help lists every estimator and
    scenario with its line, the outputs and the exit codes."""
    from vnav_graph.estimators.base import DESCRIPTIONS

    for argv in (["--help"], ["run", "--help"]):
        with pytest.raises(SystemExit) as e:
            main(argv)
        assert e.value.code == 0
        text = capsys.readouterr().out
        assert "``" not in text and "exit codes:" in text
    assert "default: vnav-graph-out" in text and "summary.json" in text
    for name, line in DESCRIPTIONS.items():
        assert any(ln.split()[:1] == [name] and line in ln for ln in text.splitlines()), name
    assert "urban" in text and "seed of the simulated scenario" in text


def test_run_baseline_leads_the_headline(tmp_path):
    out = tmp_path / "o"
    assert main(["run", "--estimators", "loop3,vkf4", "--baseline", "vkf4", "--duration", "60",
                 "--out", str(out), "--no-progress"]) == 0
    s = json.loads((out / "summary.json").read_text())
    assert s["comparison"]["baseline"]["name"] == "vkf4"
    assert s["comparison"]["headline"][0].startswith("Altitude RMSE against vkf4")
    assert "loop3" in s["comparison"]["baseline"]["metrics"]["alt_rmse_m"]
    r = subprocess.run([sys.executable, "-m", "vnav_graph", "run", "--estimators", "vkf4",
                        "--baseline", "vkf5", "--out", str(tmp_path / "x")],
                       capture_output=True, text=True)
    assert r.returncode == 2 and "did you mean 'vkf4'?" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
