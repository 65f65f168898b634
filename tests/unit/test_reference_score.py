"""Holdout windows scored against a reference (``evaluation.reference_score``): an estimate
that is off by known amounts inside and outside the windows."""

from __future__ import annotations

import numpy as np
import pytest

from vnav_graph.evaluation.reference_score import reference_block
from vnav_graph.geo.frames import lla_to_ned, ned_to_lla
from vnav_graph.types import Drive, Estimate, Trajectory
from vnav_graph.types.streams import ImuStream

ORIGIN = np.array([np.radians(40.0967), np.radians(-105.1472), 1600.0])


def _case() -> tuple[Drive, Estimate, list[tuple[float, float]]]:
    t = np.arange(0.0, 100.0, 0.25)
    ned = np.column_stack([5.0 * t, np.zeros_like(t), np.zeros_like(t)])
    vel = np.tile([5.0, 0.0, 0.0], (t.size, 1))
    truth = Trajectory(t, ned_to_lla(ned, ORIGIN), vel)
    windows = [(20.0, 30.0), (60.0, 75.0)]
    inside = np.zeros(t.size, dtype=bool)
    for a, b in windows:
        inside |= (t >= a) & (t <= b)
    # inside: 2 m east, 0.5 m high, 0.1 m/s down too fast; outside: 10 m off (not scored)
    off = np.where(inside[:, None], [0.0, 2.0, -0.5], [10.0, 0.0, 0.0])
    vel_e = vel + np.where(inside[:, None], [0.0, 0.0, 0.1], [0.0, 0.0, 0.0])
    est = Estimate("x", Trajectory(t, ned_to_lla(ned + off, ORIGIN), vel_e),
                   frozenset({"alt", "vel_d", "pos_h", "vel_h"}))
    ti = np.arange(0.0, 100.0, 0.01)
    imu = ImuStream(ti, np.zeros((ti.size, 3)), np.tile([0.0, 0.0, -9.8], (ti.size, 1)))
    return Drive(imu, None, None, ORIGIN, truth=truth), est, windows


def test_errors_inside_the_windows_only() -> None:
    drive, est, windows = _case()
    b = reference_block(est, drive, windows)
    assert b is not None
    assert b["n_scored"] == 41 + 61  # 4 Hz epochs in [20, 30] and [60, 75]
    assert b["horiz_rmse_m"] == pytest.approx(2.0, abs=1e-3)
    assert b["horiz_max_m"] == pytest.approx(2.0, abs=1e-3)
    assert b["alt_rmse_m"] == pytest.approx(0.5, abs=1e-6)
    assert b["vel_down_rmse_mps"] == pytest.approx(0.1)
    assert [w["n"] for w in b["per_window"]] == [41, 61]
    assert b["nees_mean"] is None  # no covariance
    assert lla_to_ned(drive.truth.lla[:1], ORIGIN)[0] == pytest.approx([0, 0, 0], abs=1e-6)


def test_no_reference_or_no_epoch_in_a_window() -> None:
    drive, est, _ = _case()
    assert reference_block(est, drive.replace(truth=None), [(20.0, 30.0)]) is None
    assert reference_block(est, drive, [(200.0, 230.0)]) is None
