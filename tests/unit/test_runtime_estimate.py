"""The run-time hint: the cost model's terms, the line it prints, and where ``run`` says it."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from vnav_graph.cli import main
from vnav_graph.estimators.base import available
from vnav_graph.run import runtime_estimate as rt
from vnav_graph.simulation import simulate

DATA = Path(os.environ.get("VNAV_DATA", Path(__file__).resolve().parents[3] / "shared" / "data"))
LOG_218 = DATA / "erle_pxf_218" / "218.BIN"


def test_features_count_samples_keyframes_and_heading_factors():
    d = simulate("hill-drive-mag", 0, duration_s=120.0)
    n_imu, kf, kf_mag = rt.features(d)
    assert n_imu == pytest.approx(len(d.imu) / 1e4)
    assert kf == pytest.approx(1.20)  # one keyframe per second
    assert kf_mag == pytest.approx(120 * 120 / 1e5)  # 120 keyframes × 120 heading factors
    plain = rt.features(simulate("hill-drive", 0, duration_s=120.0))
    assert plain[2] == 0.0
    t_mag, t_plain = (rt.predict(x, ["graph-isam2"])["graph-isam2"] for x in
                      (d, simulate("hill-drive", 0, duration_s=120.0)))
    assert t_mag - t_plain == pytest.approx(rt.COST["graph-isam2"][2] * kf_mag)
    assert rt.predict(d, ["my-plugin"]) == {"my-plugin": None}


def test_default_drive_needs_no_hint():
    assert rt.run_hint(simulate("default", 0), available(), holdout=False) is None


@pytest.mark.skipif(not LOG_218.exists(), reason=f"shared real log not found: {LOG_218}")
def test_real_log_hint_names_graph_isam2_and_how_to_skip_it():
    from vnav_graph.io import load_drive

    d = load_drive(LOG_218)
    names = available()
    line = rt.run_hint(d, names, holdout=True)
    times = rt.predict(d, names)
    total = 2 * sum(times.values())
    assert line.startswith(f"this run will take about {total / 60:.1f} min (the run and the "
                           "holdout run; --no-holdout: one), graph-isam2 ")
    rest = [n for n in names if n != "graph-isam2"]
    assert line.endswith(f"--estimators {','.join(rest)} skips it")
    assert max(times, key=times.get) == "graph-isam2"


@pytest.mark.parametrize("quiet", [False, True])
def test_run_prints_it_on_stderr(tmp_path, capsys, monkeypatch, quiet):
    monkeypatch.setattr(rt, "LONG_RUN_S", 0.0)  # every run is "long"
    rc = main(["run", "--duration", "30", "--estimators", "loop3,vkf4", "--out",
               str(tmp_path / "o"), *(["--no-progress"] if quiet else [])])
    err = capsys.readouterr().err
    assert rc == 0
    hints = [line for line in err.splitlines() if line.startswith("vnav-graph: hint: ")]
    assert len(hints) == (0 if quiet else 1), err
    if not quiet:
        d = simulate("default", 0, duration_s=30.0)
        times = rt.predict(d, ["loop3", "vkf4"])
        slow, rest = sorted(times, key=times.get, reverse=True)
        assert hints[0].endswith(f", {slow} 0 s of it; --estimators {rest} skips it")
