"""The bookkeeping of benchmarks/isam2_optimality.py: the cut drive (``Drive.until``) and the
RMS summary."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from vnav_graph.simulation import simulate

_P = Path(__file__).resolve().parents[2] / "benchmarks" / "isam2_optimality.py"
_spec = importlib.util.spec_from_file_location("isam2_optimality", _P)
opt = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(opt)


def test_until_ends_every_stream_and_the_truth_at_the_cut():
    d = simulate("hill-drive", 0, duration_s=40.0)
    t1 = float(d.imu.t[0]) + 25.0
    c = d.until(t1)
    for s in (c.imu, c.gnss, c.baro, c.truth):
        assert s.t[-1] <= t1 + 1e-9 and s.t[-1] > t1 - 1.0
    np.testing.assert_array_equal(c.gnss.t, d.gnss.t[d.gnss.t <= t1])


def test_summary_is_the_rms_over_cuts_and_seeds_skipping_failed_cuts():
    """Online errors 3 and 4 m over two seeds (one failed cut, one missing lag): RMS
    √((9 + 16)/2); the lag has one value, 2 m."""
    def row(h, lag):
        r = {k: None for k in opt.KEYS}
        r["online"] = {"horiz_m": h, "alt_m": 0.0}
        r["lag"] = None if lag is None else {"horiz_m": lag, "alt_m": 1.0}
        return r

    runs = [{"scenario": "s", "cuts": [row(3.0, 2.0), {"t_s": 9.0, "error": "x"}]},
            {"scenario": "s", "cuts": [row(4.0, None)]}]
    s = opt.summarise(runs)["s"]
    assert s["cuts"] == 2
    assert s["online_horiz_m"] == pytest.approx(np.sqrt(12.5))
    assert s["lag_horiz_m"] == pytest.approx(2.0) and s["lag_alt_m"] == pytest.approx(1.0)
    assert s["smoother_horiz_m"] is None
    assert "—" in opt.line("s", s)
