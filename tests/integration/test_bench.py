"""``vnav-graph bench``: files and schema, bench rows == ``vnav-graph run`` metrics, exit codes.

The full ``bench --quick`` (every estimator) runs in ``.ci/run``; here the CLI is driven on a
single short scenario so the test stays within seconds.
"""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from vnav_graph.cli import main
from vnav_graph.estimators import base
from vnav_graph.evaluation.montecarlo import QUICK_DURATION_S, shorten_scenario
from vnav_graph.run.bench import BenchTask, run_task
from vnav_graph.run.pipeline import run_estimators, summarize
from vnav_graph.simulation import simulate
from vnav_graph.types import Estimate, Trajectory

FAST = ("vkf4", "vekf7", "loop3", "observer1d", "ekf")


class TruthPlusOne:
    """Truth raised by 1 m: altitude RMSE exactly 1 m."""

    name = "truth-plus-one"

    def run(self, drive):
        tr = drive.truth
        lla = tr.lla.copy()
        lla[:, 2] += 1.0
        return Estimate(self.name, Trajectory(tr.t, lla, tr.vel_n), frozenset({"alt", "vel_d"}),
                        runtime_s=1e-3)


class Broken:
    name = "broken"

    def run(self, drive):
        raise ValueError("broken on purpose")


@pytest.fixture
def fake(monkeypatch, registry):
    registry("truth-plus-one", TruthPlusOne)
    registry("broken", Broken)


def test_bench_cli_writes_schema(tmp_path, fake, capsys):
    out = tmp_path / "b"
    rc = main(["bench", "--quick", "--scenarios", "hill-drive,sortie", "--seeds", "2",
               "--estimators", "truth-plus-one", "--workers", "2", "--out", str(out)])
    assert rc == 0
    doc = json.loads((out / "bench.json").read_text())
    assert doc["schema"] == "vnav_graph.run.bench/1" and set(doc) >= {"runs", "aggregate"}
    assert len(doc["runs"]) == 4
    for r in doc["runs"]:
        assert set(r) >= {"scenario", "seed", "estimator", "status", "error", "alt_rmse_m",
                          "alt_max_abs_m", "vel_down_rmse_mps", "nees_mean", "runtime_s",
                          "realtime_factor", "baro", "online", "lag"}
        assert r["online"] is None  # an estimator outside base.CAUSAL without an online one
        assert r["duration_s"] == pytest.approx(QUICK_DURATION_S)  # --quick drive length
        assert r["alt_rmse_m"] == pytest.approx(1.0, abs=1e-9)  # +1 m offset, float round-off
    for sc in ("hill-drive", "sortie"):
        cell = doc["aggregate"][sc]["truth-plus-one"]
        assert cell["alt_rmse_m"]["mean"] == pytest.approx(1.0, abs=1e-9)
        lo, hi = cell["alt_rmse_m"]["ci95"]
        assert hi - lo < 1e-8  # identical values over seeds: a zero-width interval
        assert set(cell) >= {"alt_rmse_m", "nees_mean", "runtime_s", "vel_down_rmse_mps"}
    md = (out / "bench.md").read_text()
    assert "## hill-drive" in md and "## sortie" in md and "| truth-plus-one | 2/2 |" in md
    # no filter and graph pair among the estimators: no gains section, no figure
    assert "paired gains" not in md and not (out / "forest.png").exists()


def test_bench_failed_run_exit_1_after_writing(tmp_path, fake, capsys):
    out = tmp_path / "b"
    rc = main(["bench", "--quick", "--scenarios", "hill-drive", "--seeds", "1",
               "--estimators", "truth-plus-one,broken", "--workers", "1", "--out", str(out)])
    assert rc == 1
    err = capsys.readouterr().err.strip().splitlines()
    # a progress line per finished run (stderr is not a terminal here), then the one verdict
    assert [line.split(" (elapsed")[0] for line in err[:-1]] == [
        "vnav-graph: bench [1/2] hill-drive seed 0 truth-plus-one",
        "vnav-graph: bench [2/2] hill-drive seed 0 broken"]
    assert "1 of 2 runs failed (broken)" in err[-1]
    doc = json.loads((out / "bench.json").read_text())
    bad = [r for r in doc["runs"] if r["estimator"] == "broken"]
    assert bad[0]["status"] == "failed" and "broken on purpose" in bad[0]["error"]


@pytest.mark.parametrize("argv, needle", [
    (["--seeds", "0"], "--seeds must be >= 1"),
    (["--scenarios", "nope"], "unknown scenario"),
    (["--estimators", "nope"], "unknown estimator"),
    (["--workers", "0"], "--workers must be >= 1"),
])
def test_bench_bad_input_exit_2(tmp_path, argv, needle):
    r = subprocess.run([sys.executable, "-m", "vnav_graph", "bench", *argv, "--out",
                        str(tmp_path / "o")], capture_output=True, text=True)
    assert r.returncode == 2 and needle in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "o").exists()  # nothing written


def test_bench_row_equals_run_summary():
    """A bench row holds exactly the metrics ``vnav-graph run`` reports for that drive."""
    name = next((n for n in FAST if n in base.available()), None)
    if name is None:
        pytest.skip(f"none of {FAST} in this build yet")
    row = run_task(BenchTask("sortie", 4, name, 60.0))
    drive = simulate(shorten_scenario("sortie", 60.0), 4)
    ref = summarize(drive, run_estimators(drive, [name], progress=False))["estimators"][name]
    assert row["status"] == ref["status"] == "ok"
    for k, v in ref.items():
        if k in ("runtime_s", "realtime_factor", "jit_s"):  # timings (bench warms up first)
            continue
        if isinstance(v, float):
            # deterministic estimator, same drive: identical up to summation order (none)
            assert row[k] == pytest.approx(v, rel=1e-12, abs=0), k
        else:
            assert row[k] == v, k
    assert np.isfinite(row["runtime_s"])


def test_make_results_page_from_numbers(tmp_path):
    """The results page states a win exactly when the paired CI excludes zero (the accuracy
    win rule), with the loser's calibration beside it, and "not resolved" otherwise."""
    import importlib.util
    from pathlib import Path

    from vnav_graph.evaluation.montecarlo import aggregate

    spec = importlib.util.spec_from_file_location(
        "make_results", Path(__file__).resolve().parents[2] / "benchmarks" / "make_results.py")
    mr = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mr)

    def row(est, seed, rmse):
        return {"scenario": "s", "seed": seed, "estimator": est, "status": "ok",
                "alt_rmse_m": rmse, "runtime_s": 1.0, "nees_mean": None, "nees_dof": None,
                "baro": {}}

    # ekf-rts is better than ekf by exactly 0.5 m on every seed (zero-width paired CI);
    # graph-batch differs from ekf-rts by ±0.1 m alternating (paired CI contains 0)
    base_ = [1.0, 2.0, 3.0, 4.0]
    runs = ([row("ekf", i, x + 0.5) for i, x in enumerate(base_)]
            + [row("ekf-rts", i, x) for i, x in enumerate(base_)]
            + [row("graph-batch", i, x + (0.1 if i % 2 else -0.1)) for i, x in enumerate(base_)])
    doc = {"schema": "vnav_graph.run.bench/1", "runs": runs, "aggregate": aggregate(runs),
           "config": {"scenarios": ["s"], "seeds": [0, 1, 2, 3], "duration_s": None,
                      "executor": "local", "wall_s": 1.0}}
    (tmp_path / "bench.json").write_text(json.dumps(doc))
    page = mr.render(tmp_path)
    # gain 0.5/3 = 17 %, its delta-method CI from the spread of the ekf's values
    assert ("altitude RMSE: d = 0.500 [0.500, 0.500] m, gain 17 [5, 28] %, n = 4: "
            "**ekf-rts wins**") in page
    assert "Why" not in page  # no mechanism the run did not measure
    assert "**ekf-rts → graph-batch (ekf-rts vs graph-batch).**" in page  # offline, like for like
    # ±0.1 m alternating over 4 seeds: mean 0, s = 0.11547, t_{0.975,3} = 3.182 → |d| ≤ 0.184
    assert ("altitude RMSE: d = 0.000 [-0.184, 0.184] m, gain 0 [-7, 7] %, n = 4: not "
            "resolved (the 95 % CI of the difference contains 0)") in page
    assert "**Win rule:** a paired difference over seeds" in page
    # the same 0.5 m against an ekf whose σ covers its error (NEES/dof 1): still a win, its
    # calibration beside it (these rows carry only the 6-dof NEES: said so)
    for r in runs:
        if r["estimator"] == "ekf":
            r["nees_mean"], r["nees_dof"] = 6.0, 6
    (tmp_path / "bench.json").write_text(json.dumps({**doc, "aggregate": aggregate(runs)}))
    page = mr.render(tmp_path)
    assert ("altitude RMSE: d = 0.500 [0.500, 0.500] m, gain 17 [5, 28] %, n = 4: "
            "**ekf-rts wins**; NEES/dof (position+velocity, 6 dof: the runs carry no per-axis "
            "NEES): ekf 1.00, ekf-rts —") in page
    assert "reproductions.json` missing" in page
    (tmp_path / "reproductions.json").write_text(json.dumps(
        {"seed003_steady_sd_m": 1.1, "seed001_rmse_m": {"vekf7": 4.0}}))
    page = mr.render(tmp_path)
    assert "| `seed003_steady_sd_m` | 1.1 | 1.2 |" in page
    assert "| `seed001_rmse_m.vekf7` | 4 | 5.7 |" in page
    # every section names where it comes from: the forest of gains, the bench's JSON
    docs = tmp_path / "docs"
    page = mr.render(tmp_path, docs)
    assert "## Filter vs graph at a glance" in page
    assert (docs / "img" / "results-forest.png").is_file()
    assert "offline (ekf-rts → graph-batch), altitude RMSE: gain" in page
    assert page.count("*Provenance:*") == 2  # the bench and the reproductions
    assert (docs / "results_data" / "bench.json").read_text() == \
        (tmp_path / "bench.json").read_text()
