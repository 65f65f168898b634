"""The filter-vs-graph gains behind the forest plot (``evaluation.gains``), the figure itself
(``report.forest``) and the results page's provenance stamps (``benchmarks/provenance.py``)."""

from __future__ import annotations

import gzip
import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

from vnav_graph.evaluation.gains import gain_lines, gain_rows
from vnav_graph.report.forest import XMIN, forest_png

REPO = Path(__file__).resolve().parents[2]


def _row(est, seed, horiz, online=None):
    return {"scenario": "s", "seed": seed, "estimator": est, "status": "ok",
            "alt_rmse_m": 1.0 + 0.1 * seed, "horiz_rmse_m": horiz, "runtime_s": 1.0,
            "nees_mean": 6.0, "nees_dof": 6, "baro": {}, "online": online}


def _online(horiz):
    return {"alt_rmse_m": 2.0, "horiz_rmse_m": horiz, "heading_rmse_deg": None,
            "heading_known_rmse_deg": None, "vel_down_rmse_mps": 0.1, "nees_mean": 6.0,
            "nees_dof": 6, "from_s": 1.0}


def _runs():
    base = np.array([1.0, 2.0, 3.0, 4.0, 5.0])
    runs = [_row("ekf-rts", i, x) for i, x in enumerate(base)]
    runs += [_row("graph-batch", i, 0.7 * x) for i, x in enumerate(base)]  # 30 % lower
    # real time: the online blocks, not the final trajectories, are compared
    runs += [_row("ekf", i, 0.1, _online(x)) for i, x in enumerate(base)]
    runs += [_row("graph-isam2", i, 0.1, _online(x * (1.0 + (0.1 if i % 2 else -0.1))))
             for i, x in enumerate(base)]
    return runs


def test_a_uniform_30_percent_gain_is_a_counted_win_with_a_zero_width_interval():
    rows = {(r["comparison"], r["key"]): r for r in gain_rows(_runs())}
    off = rows[("offline", "horiz_rmse_m")]
    assert (off["a"], off["b"], off["n"]) == ("ekf-rts", "graph-batch", 5)
    assert off["gain"] == pytest.approx(0.3)
    assert off["gain_ci95"] == pytest.approx([0.3, 0.3])
    assert off["verdict"] == "win" and off["counts"] is True
    # identical altitudes: no win either way
    assert rows[("offline", "alt_rmse_m")]["verdict"] == "identical"


def test_real_time_gains_come_from_the_online_blocks():
    rows = {(r["comparison"], r["key"]): r for r in gain_rows(_runs())}
    rt = rows[("real time", "horiz_rmse_m")]
    assert (rt["a"], rt["b"]) == ("ekf", "graph-isam2")
    # ±10 % alternating around the ekf's values: mean gain (0.1·(1+3+5) − 0.1·(2+4))/15
    assert rt["gain"] == pytest.approx((0.1 * 9 - 0.1 * 6) / 15.0)
    assert rt["verdict"] == "not resolved"
    assert ("real time", "heading_rmse_deg") not in rows  # no heading scores: not compared
    assert any("gain +30.0 % [+30.0 %, +30.0 %] over 5 seeds, win" in s
               for s in gain_lines(gain_rows(_runs())))


def test_a_gain_ci_that_excludes_zero_on_an_unresolved_difference_says_why():
    # differences that scale with the filter's error, but one seed the other way: the t
    # interval of d contains 0, the delta-method interval of the gain does not
    a = [2.92, 3.56, 1.46, 2.79, 1.88]
    b = [1.59, 2.27, 1.64, 1.86, 1.38]
    runs = [_row("ekf-rts", i, x) for i, x in enumerate(a)]
    runs += [_row("graph-batch", i, x) for i, x in enumerate(b)]
    row = next(r for r in gain_rows(runs) if r["key"] == "horiz_rmse_m")
    assert row["diff_ci95"][0] < 0 < row["diff_ci95"][1]
    assert row["gain_ci95"][0] > 0 and row["verdict"] == "not resolved"
    d = np.subtract(a, b)
    line = next(s for s in gain_lines([row]))
    assert f"d = {d.mean():.3g} [{row['diff_ci95'][0]:+.3g}, " in line
    assert "contains 0" in line and "excludes it" in line
    # a resolved or a zero-straddling gain needs no such clause
    assert not any("contains 0" in s for s in gain_lines(gain_rows(_runs())))
    assert forest_png([row]) is not None


def test_forest_png_is_wide_and_none_without_gains():
    import io

    from PIL import Image

    png = forest_png(gain_rows(_runs()), "t")
    im = Image.open(io.BytesIO(png))
    assert im.size[0] >= 1600
    assert forest_png([]) is None
    # a loss beyond the axis is drawn at its edge (no error, still a figure)
    big = [{**gain_rows(_runs())[0], "gain": 2 * XMIN / 100, "gain_ci95": [-5.0, -1.0]}]
    assert forest_png(big) is not None


def _provenance():
    spec = importlib.util.spec_from_file_location("provenance",
                                                  REPO / "benchmarks" / "provenance.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_provenance_records_the_step_and_stamps_its_section(tmp_path, monkeypatch):
    prov = _provenance()
    monkeypatch.setattr(prov, "_git", lambda *a: "0123456789abcdef" if a[0] == "rev-parse"
                        else "")
    rc = prov.record(tmp_path, "bench", ["/usr/bin/python3", "-m", "vnav_graph", "bench"],
                     lambda: 1)
    assert rc == 1
    entry = json.loads((tmp_path / "provenance.json").read_text())["bench"]
    assert entry["cmd"] == "python3 -m vnav_graph bench" and entry["returncode"] == 1
    assert entry["commit"] == "0123456789abcdef" and entry["dirty"] is False
    j = tmp_path / "bench.json"
    j.write_text(json.dumps({"x": 1}))
    kept = prov.keep(j, tmp_path / "results_data", "bench.json")
    assert (tmp_path / "results_data" / "bench.json").read_text() == j.read_text()
    line = prov.stamp(tmp_path, "bench", kept, "seeds 3")
    assert "`python3 -m vnav_graph bench`" in line and "`0123456789`" in line
    assert "exit 1" in line and prov.sha256(j)[:16] in line
    # a step never recorded says so instead of inventing a commit
    assert "were not recorded" in prov.stamp(tmp_path, "hard", kept, "seeds 3")


def test_a_large_json_is_kept_gzipped(tmp_path, monkeypatch):
    prov = _provenance()
    monkeypatch.setattr(prov, "KEEP_MAX_BYTES", 1000)
    j = tmp_path / "big.json"
    j.write_text(json.dumps({"runs": [{"a": 1.0}] * 500}))
    kept = prov.keep(j, tmp_path / "results_data", "big.json")
    assert kept.startswith("JSON `docs/results_data/big.json.gz`")
    assert gzip.decompress((tmp_path / "results_data" / "big.json.gz").read_bytes()) == \
        j.read_bytes()
