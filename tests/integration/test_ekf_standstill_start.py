"""ekf-rts knows at t0 the heading it acquires after a long opening standstill.

A car stands still for 40 s, then drives off at 1 m/s² (hill-drive kind, no magnetometer):
the heading is unobservable until it moves and the forward ekf acquires it by acceleration
matching at 44 s. The IMU is given the real-log gyro prior (0.5 °/s turn-on bias, τ of
120 000 s, ``sensors.model``), under which the bias's prior drift over 44 s is 22°: with
that as the σ of the heading carried back, ``ekf.carry`` refused it (above ``CARRY_SD_MAX``)
and ekf-rts stayed 140° off graph-batch until 44 s. The smoothed bias (0.012 °/s on the down
axis) carries it with σ 0.86°: ekf-rts is then within 0.13° of graph-batch from t0.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from vnav_graph.config import DEG
from vnav_graph.geo.frames import quat_to_rph
from vnav_graph.run.runner import run_estimators
from vnav_graph.simulation.scenario import load_scenario, simulate

pytestmark = pytest.mark.slow


def _standstill_drive():
    sc = load_scenario("hill-drive", duration_s=240.0)
    sc = replace(sc, imu=replace(sc.imu, gyro_bias_sd=0.5 * DEG, gyro_bias_tau=120000.0),
                 params={**sc.params, "static_s": 40.0, "accel_mps2": 1.0},
                 gnss=replace(sc.gnss, outages=()))
    return simulate(sc, 0)


def _wrap_deg(a):
    return np.degrees((a + np.pi) % (2 * np.pi) - np.pi)


def test_ekf_rts_carries_a_late_heading_back_over_the_standstill() -> None:
    drive = _standstill_drive()
    est = {r.name: r.estimate for r in run_estimators(drive, ["ekf-rts", "graph-batch"],
                                                         progress=False, desc="test")}
    rts, gb = est["ekf-rts"], est["graph-batch"]
    info = rts.info
    # the heading is learnt once the car moves, not during the standstill
    assert info["heading_time_s"] > 40.0
    assert info["heading_source"].endswith("carried back")
    assert info["heading_carried_back"]["sd_deg"] < 2.0
    t = np.arange(0.5, 120.0, 0.5)
    yaw_r = quat_to_rph(rts.trajectory.at(t).q_nb)[:, 2]
    yaw_g = quat_to_rph(gb.trajectory.at(t).q_nb)[:, 2]
    yaw_t = quat_to_rph(drive.truth.at(t).q_nb)[:, 2]
    # measured: 0.13° at most between the two smoothers, 0.16° against the truth
    assert np.max(np.abs(_wrap_deg(yaw_r - yaw_g))) < 2.0
    assert np.max(np.abs(_wrap_deg(yaw_r - yaw_t))) < 2.0
