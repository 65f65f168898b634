"""benchmarks/truth_logs.py: the source repository's simulated outages (15 s windows every
45 s, from 40 s / 25 s after the first reference epoch to 30 s / 45 s before the last) are
11 windows on the car drive and 2 on the walk."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

_P = Path(__file__).resolve().parents[2] / "benchmarks" / "truth_logs.py"
_spec = importlib.util.spec_from_file_location("truth_logs", _P)
tl = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(tl)


def test_source_outage_windows() -> None:
    # car: .pos epochs 19:34:18.499 .. 19:43:27.499 (549 s); walk: 17:30:39.749 .. 17:32:53.5
    car = tl.source_windows(0.0, 549.0, *tl.DRIVES["car_drive_0708"]["source_outages"])
    walk = tl.source_windows(0.0, 133.75, *tl.DRIVES["walk_0827"]["source_outages"])
    assert len(car) == 11 and len(walk) == 2
    assert car[0] == (40.0, 55.0) and car[1][0] == pytest.approx(85.0)
    assert car[-1][1] <= 549.0 - 30.0
    assert walk == [(25.0, 40.0), (70.0, 85.0)]


def _case(horiz_max, horiz_rms, alt_max, alt_rms, windows=2):
    return {"windows": [[0.0, 15.0]] * windows, "estimators": {"ekf-rts": {
        "status": "ok", "horiz_max_m": horiz_max, "horiz_rmse_m": horiz_rms,
        "alt_max_abs_m": alt_max, "alt_rmse_m": alt_rms}}}


def test_peer_goals_are_checked_cell_by_cell() -> None:
    vm = tl.PEER["peer forward with velocity matching"]
    # at the peer's values everywhere (equal counts as at or below): met
    peer = {rec: _case(*vm[(rec, "horizontal")], *vm[(rec, "vertical")])
            for rec in ("walk", "car")}
    lines = tl.render_peer(peer, ["ekf-rts"])
    assert "- ekf-rts against peer forward with velocity matching: met" in lines
    assert any(ln.startswith("| ekf-rts | 0.55 / 0.29 | 0.10 / 0.04 |") for ln in lines)
    # one cell above: missed, and only that cell is named
    peer["car"] = _case(1.16, vm[("car", "horizontal")][1], *vm[("car", "vertical")])
    miss = next(ln for ln in tl.render_peer(peer, ["ekf-rts"]) if ln.startswith("- ekf-rts"))
    assert miss.endswith("missed: car horizontal max 1.16 > 0.68 m")
    # an estimator without a score is a miss, not a pass
    gone = {"walk": {"windows": [], "estimators": {}}, "car": peer["car"]}
    miss = next(ln for ln in tl.render_peer(gone, ["ekf-rts"]) if ln.startswith("- ekf-rts"))
    assert "walk horizontal: no score" in miss
