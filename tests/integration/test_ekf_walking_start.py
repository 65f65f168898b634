"""The forward ekf takes its heading from the GNSS course at walking speed.

A simulated straight walk (hill-drive kind, 20 s standstill, then 0.1 m/s² to 1.2–1.5 m/s,
velocity noise 0.05 m/s): the acceleration is too small for acceleration matching to reach
its 15° σ soon (alone it acquires 12 s after the start and is still 49° off at 15 s), while
the course is a heading within ``nav.course``'s σ as soon as the speed is 5 σ_v. With the
course confirmed by the matching (``heading.confirmed_course``, "auto") the ekf acquires it
4.9 s after the start and is within 10° of the truth from 8 s on, 6° from 12 s on.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from vnav_graph.estimators.ekf.filter import EKF, EkfConfig
from vnav_graph.geo.frames import quat_to_rph
from vnav_graph.simulation.scenario import load_scenario, simulate


def _walk():
    sc = load_scenario("hill-drive", duration_s=120.0)
    sc = replace(sc, params={**sc.params, "static_s": 20.0, "accel_mps2": 0.1,
                             "speed_range_mps": (1.2, 1.5)},
                 gnss=replace(sc.gnss, outages=(), vel_sd=0.05))
    return simulate(sc, 0)


def _yaw_err_deg(est, truth, t):
    d = quat_to_rph(est.trajectory.at(t).q_nb)[:, 2] - quat_to_rph(truth.at(t).q_nb)[:, 2]
    return np.degrees((d + np.pi) % (2 * np.pi) - np.pi)


@pytest.mark.slow
def test_heading_from_the_course_within_seconds_of_walking() -> None:
    drive = _walk()
    tr = drive.truth
    t_move = float(tr.t[np.argmax(np.hypot(tr.vel_n[:, 0], tr.vel_n[:, 1]) > 0.05)])
    est = EKF().run(drive)
    assert est.info["heading_source"] == "gnss-course"
    # measured 5.9 s after the start
    assert est.info["heading_time_s"] - t_move < 8.0
    t = np.arange(t_move + 8.0, tr.t[-1], 0.5)
    err = _yaw_err_deg(est, tr, t)
    # measured 9.8° at most from 8 s (the zero-velocity updates of the standstill, which last
    # until 0.8 s into the walk, leave a transient; without them 5.0°) and 6.0° from 12 s
    assert np.max(np.abs(err)) < 12.0
    assert np.max(np.abs(err[t >= t_move + 12.0])) < 7.0
    # the σ it claims covers it: |error| ≤ 3σ wherever the heading is known
    sd = np.degrees(np.sqrt(np.interp(t, est.t_cov, est.cov[:, 8, 8])))
    assert np.all(np.abs(err) <= 3.0 * sd)
    # acceleration matching alone is far off at 15 s (measured 49°): the check can fail
    acc = EKF(EkfConfig(heading_source="accel")).run(drive)
    assert abs(_yaw_err_deg(acc, tr, np.array([t_move + 15.0]))[0]) > 20.0
