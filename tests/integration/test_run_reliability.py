"""``run`` on short logs, partial failures and non-finite numbers.

- The optional holdout scoring never sinks a run: a log too short for one outage window keeps
  its results and says in ``summary.json`` and the table that scoring was skipped, and why.
- Exit codes: 0 all ok, 3 some estimators failed, 4 every estimator failed (README).
- ``summary.json`` is strict JSON (no NaN literals).
- numpy RuntimeWarnings inside an estimator become that estimator's warnings.
"""

from __future__ import annotations

import json
import re
import warnings
from pathlib import Path

import numpy as np
import pytest

from vnav_graph.cli import main
from vnav_graph.io import save_npz
from vnav_graph.io.jsonout import dumps_strict
from vnav_graph.run import pipeline, runner
from vnav_graph.simulation import simulate


def _strict_load(p: Path):
    def bad(c):
        raise AssertionError(f"non-JSON literal {c}")
    return json.loads(p.read_text(), parse_constant=bad)


def _short_real_drive(tmp_path: Path) -> Path:
    """A 40 s simulated drive without truth: scored like a real log, too short for holdout."""
    d = simulate("hill-drive", 2, duration_s=40.0)
    d = d.replace(truth=None, baro_truth=None, meta={**d.meta, "source": "log"})
    return save_npz(d, tmp_path / "short.npz")


def test_short_log_skips_holdout_and_still_writes_results(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["run", str(_short_real_drive(tmp_path)), "--estimators", "loop3",
                 "--out", str(out)]) == 0
    s = _strict_load(out / "summary.json")
    assert "too short" in s["evaluation"]["skipped"]
    assert s["estimators"]["loop3"]["status"] == "ok"
    assert "holdout scoring skipped: GNSS span" in capsys.readouterr().out


def test_real_ulog_run_exits_0_with_holdout_skipped(data_dir, tmp_path):
    out = tmp_path / "out"
    log = data_dir / "px4_ulog_samples" / "sample_px4_events.ulg"
    assert main(["run", str(log), "--estimators", "loop3,vkf4", "--out", str(out)]) == 0
    s = _strict_load(out / "summary.json")
    assert s["evaluation"]["skipped"].startswith("GNSS span 21 s is too short")
    assert any("9 of 31" in w for w in s["drive"]["warnings"])


def _failing(monkeypatch, names):
    real = runner.run_captured

    def fake(name, drive, config=None):
        if name in names:
            raise RuntimeError(f"{name} exploded")
        return real(name, drive, config)
    monkeypatch.setattr(runner, "run_captured", fake)


@pytest.mark.parametrize(("fail", "code"), [({"vkf4"}, 3), ({"vkf4", "loop3"}, 4)])
def test_failures_are_not_successes(tmp_path, monkeypatch, capsys, fail, code):
    _failing(monkeypatch, fail)
    out = tmp_path / "out"
    assert main(["run", "--scenario", "hill-drive", "--duration", "30", "--estimators",
                 "loop3,vkf4", "--out", str(out)]) == code
    # progress lines (no tty): the estimators' and a slow step's announcement (a loaded
    # machine takes over 1 s to write the outputs)
    err = [line for line in capsys.readouterr().err.strip().splitlines()
           if not line.startswith("vnav-graph: estimators [")
           and not re.search(r"( \.\.\.|: done in [0-9.]+ s)$", line)]
    assert len(err) == 1 and "RuntimeError: " in err[0]
    assert ("every estimator failed" in err[0]) == (code == 4)
    assert _strict_load(out / "summary.json")["estimators"]["vkf4"]["status"] == "failed"


def test_summary_json_is_strict(tmp_path, monkeypatch):
    real = pipeline.evaluate

    def nan_metrics(est, drive, *args, **kwargs):
        b = real(est, drive, *args, **kwargs)
        b["alt_rmse_m"] = float("nan")
        b["alt_max_abs_m"] = np.float64(np.inf)
        return b
    monkeypatch.setattr(pipeline, "evaluate", nan_metrics)
    out = tmp_path / "out"
    assert main(["run", "--scenario", "hill-drive", "--duration", "30", "--estimators",
                 "loop3", "--out", str(out)]) == 0
    m = _strict_load(out / "summary.json")["estimators"]["loop3"]
    assert m["alt_rmse_m"] is None and m["alt_max_abs_m"] is None
    with pytest.raises(ValueError):
        json.dumps({"x": float("nan")}, allow_nan=False)
    assert dumps_strict({"x": [np.nan, 1.0, np.float32(2.5)]}, None) == '{"x": [null, 1.0, 2.5]}'


def test_runtime_warnings_become_estimator_warnings(monkeypatch):
    d = simulate("hill-drive", 2, duration_s=20.0)

    class Noisy:
        def run(self, drive):
            from vnav_graph.estimators.base import create

            est = create("loop3").run(drive)
            np.log(np.zeros(3))  # RuntimeWarning: divide by zero
            return est

    monkeypatch.setattr(runner, "create", lambda name, config=None: Noisy())
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # nothing may escape to the caller
        est = runner.run_captured("loop3", d)
    w = est.info["warnings"]
    assert any(x.startswith("RuntimeWarning: divide by zero encountered in log") for x in w)
