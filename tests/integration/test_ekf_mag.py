"""ekf / ekf-rts with a magnetometer (hill-drive-mag: simulated 3-axis field with hard iron).

The heading measurement model is ``sensors.magnetometer`` (its Jacobians are checked against
finite differences in tests/unit/test_magnetometer.py); here the filter that uses it.
"""

from __future__ import annotations

import numpy as np
import pytest

from vnav_graph.estimators.ekf.filter import EKF, EKFRTS, EkfConfig
from vnav_graph.evaluation.metrics import errors_vs_truth
from vnav_graph.evaluation.montecarlo import shorten_scenario
from vnav_graph.simulation import simulate


@pytest.fixture(scope="module")
def drive():
    return simulate(shorten_scenario("hill-drive-mag", 300.0), 2)


def _yaw_rms_deg(est, drive, t_from: float = 30.0) -> float:
    """RMS of the package's own heading error (``evaluation.metrics``) after ``t_from``."""
    e = errors_vs_truth(est, drive)
    return float(np.sqrt(np.mean(e.heading[e.t > t_from] ** 2)))


def test_magnetometer_acquires_heading_and_hard_iron(drive) -> None:
    with_mag = EKF().run(drive)
    info = with_mag.info
    # the magnetometer gives the heading from the start (acceleration matching needed 22 s)
    assert info["heading_source"] == "magnetometer"
    assert info["heading_time_s"] == drive.imu.t[0]  # compass alignment
    # the aligned heading is consistent with its σ (hard-iron prior 3 µT, noise, floor)
    yaw0_err = float(np.radians(errors_vs_truth(with_mag, drive).heading[0]))
    sd0 = float(np.sqrt(with_mag.cov[0][8, 8]))
    assert abs(yaw0_err) <= 3 * sd0 and sd0 < np.radians(30.0), (yaw0_err, sd0)
    assert info["mag_used"] >= 290 and info["mag_rejected"] <= 3
    truth = np.array(drive.meta["mag_truth"]["hard_iron_ut"])
    h0 = info["extra_variables"]["h0"]
    est, sd = np.array(h0["est"]), np.array(h0["sd"])
    assert np.all(np.abs(est - truth) <= 3 * sd), (est, sd, truth)
    # turns make the horizontal hard iron observable (prior σ 3 µT); on a level car the
    # body-z component moves the heading only through the tilt and stays near its prior
    assert np.all(sd[:2] < 0.5) and sd[2] > 1.0
    # simulated declination = the WMM's at the origin, as the simulator used
    decl = np.degrees(drive.meta["mag_truth"]["declination_rad"])
    assert info["mag_declination_deg"] == pytest.approx(decl, abs=0.2)
    # measured (seed 2): forward yaw RMS after 30 s 0.573° without → 0.350° with
    without = EKF(EkfConfig(use_mag=False)).run(drive)
    # without the compass the heading comes from motion: the GNSS course confirmed by the
    # acceleration matching
    assert without.info["heading_source"] in ("gnss-course", "accel-matching")
    assert _yaw_rms_deg(with_mag, drive, 30.0) < 0.8 * _yaw_rms_deg(without, drive, 30.0)


def test_smoother_with_magnetometer(drive) -> None:
    s = EKFRTS().run(drive)
    s0 = EKFRTS(EkfConfig(use_mag=False)).run(drive)
    # measured (seed 2): 0.207° → 0.148°
    assert _yaw_rms_deg(s, drive, 30.0) < _yaw_rms_deg(s0, drive, 30.0)
    assert s.info["extra_variables"]["h0"] == EKF().run(drive).info["extra_variables"]["h0"]


def test_drive_without_magnetometer_is_unchanged(drive) -> None:
    plain = drive.replace(mag=None)
    a = EKF().run(plain)
    b = EKF(EkfConfig(use_mag=False)).run(drive)
    np.testing.assert_array_equal(a.trajectory.lla, b.trajectory.lla)
    assert "mag_used" not in a.info
