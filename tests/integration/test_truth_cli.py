"""``vnav-graph run FOLDER --map MAP --truth FILE`` on the cut of rtk/walk_0827
(tests/data/rtk_walk_cut, BSD-3): scored against the reference, said so in summary.json and
the table; bad .pos / NMEA input ends in one line and exit code 2."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from vnav_graph.cli import main

REPO = Path(__file__).resolve().parents[2]
CUT = REPO / "tests" / "data" / "rtk_walk_cut"
WALK_MAP = REPO / "examples" / "maps" / "walk_0827.toml"


def _cli(*argv: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "vnav_graph", *argv], capture_output=True,
                          text=True, cwd=cwd)


@pytest.mark.slow
def test_run_with_map_and_truth(tmp_path: Path) -> None:
    out = tmp_path / "o"
    code = main(["run", str(CUT), "--map", str(WALK_MAP), "--truth",
                 str(CUT / "gnss_1730_sf.pos"), "--estimators", "ekf", "--out", str(out),
                 "--no-progress"])
    assert code == 0
    s = json.loads((out / "summary.json").read_text())
    assert s["reference"]["basis"] == "against the reference gnss_1730_sf.pos"
    assert "N = -21.387 m" in s["reference"]["height"]
    ekf = s["estimators"]["ekf"]
    # single-point input (σ ≈ 3 m, biased ≈ 8 m): errors against RTK are metres, not zero
    assert 0.5 < ekf["horiz_rmse_m"] < 30 and ekf["nees_dof"] is not None
    txt = (out / "summary.txt").read_text()
    assert "errors against the reference gnss_1730_sf.pos" in txt
    assert "errors: none" not in txt and "One simulated run" not in txt
    assert "against the reference" in (out / "report.html").read_text()


@pytest.mark.parametrize("what", ["garbage_pos", "pos_file_alone", "bad_nmea", "no_map",
                                  "truth_no_datum"])
def test_bad_input_one_line_exit_2(tmp_path: Path, what: str) -> None:
    folder = tmp_path / "walk"
    shutil.copytree(CUT, folder)
    text = WALK_MAP.read_text()
    argv = ["run", str(folder), "--map", str(tmp_path / "m.toml")]
    needle = {"garbage_pos": "not an RTKLIB solution", "pos_file_alone": "GNSS only",
              "bad_nmea": "no readable GGA", "no_map": "no column map",
              "truth_no_datum": "does not state the height datum"}[what]
    if what == "garbage_pos":
        (folder / "gnss_1730_spp.pos").write_text("% nothing here\n1 2 3\n")
    elif what == "pos_file_alone":
        argv = ["run", str(folder / "gnss_1730_spp.pos")]
    elif what == "bad_nmea":
        text = text.replace('file = "gnss_1730_spp.pos"\nformat = "rtklib-pos"',
                            'file = "g.nmea"\nformat = "nmea"')
        (folder / "g.nmea").write_text("$GPGGA,123519,4807.038,N,01131.000,E,1,08*00\n")
    elif what == "no_map":
        argv = ["run", str(folder)]
    else:
        argv += ["--truth", str(folder / "gnss_1730_sf.pos")]
        text = text.replace('height_datum = "msl"', "")
    (tmp_path / "m.toml").write_text(text)
    r = _cli(*argv, "--out", str(tmp_path / "o"), "--no-progress", cwd=tmp_path)
    assert r.returncode == 2, r.stderr
    assert needle in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert not (tmp_path / "o" / "summary.json").exists()
