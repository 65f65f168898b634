"""Validation of the data model: bad input raises ValueError naming stream and field."""

import numpy as np
import pytest

from vnav_graph.types import Drive, Trajectory
from vnav_graph.types.streams import BaroStream, GnssStream, ImuStream


def _imu(n=10):
    t = np.arange(n) * 0.01
    return ImuStream(t, np.zeros((n, 3)), np.tile([0, 0, -9.81], (n, 1)))


def test_valid_streams_are_immutable():
    imu = _imu()
    with pytest.raises(ValueError):
        imu.t[0] = 5.0  # read-only array
    with pytest.raises(AttributeError):
        imu.t = np.zeros(3)  # frozen dataclass


@pytest.mark.parametrize(
    "t, match",
    [([0.0, 0.01, 0.01, 0.03], "imu.t: duplicated"), ([0.0, 0.02, 0.01, 0.03], "imu.t: not mono"),
     ([0.0, np.nan, 0.02, 0.03], "imu.t: contains NaN")],
)
def test_bad_time_axes(t, match):
    with pytest.raises(ValueError, match=match):
        ImuStream(np.array(t), np.zeros((4, 3)), np.zeros((4, 3)))


def test_shapes_nan_and_units():
    t = np.arange(4) * 0.01
    with pytest.raises(ValueError, match=r"imu.gyro_b: expected shape \(4, 3\)"):
        ImuStream(t, np.zeros((4, 2)), np.zeros((4, 3)))
    acc = np.zeros((4, 3))
    acc[2, 1] = np.inf
    with pytest.raises(ValueError, match="imu.accel_b: contains 1 NaN or inf"):
        ImuStream(t, np.zeros((4, 3)), acc)
    with pytest.raises(ValueError, match="degrees/s passed as rad/s"):
        ImuStream(t, np.full((4, 3), 90.0), np.zeros((4, 3)))
    with pytest.raises(ValueError, match="hPa passed as Pa"):
        BaroStream(t, pressure=np.full(4, 1013.25))
    with pytest.raises(ValueError, match="degrees passed as radians"):
        GnssStream(t, np.tile([47.0, 11.0, 500.0], (4, 1)), np.ones((4, 3)))
    with pytest.raises(ValueError, match="gnss.vel_sd"):
        GnssStream(t, np.tile([0.8, 0.2, 500.0], (4, 1)), np.ones((4, 3)), np.zeros((4, 3)))
    with pytest.raises(ValueError, match="baro: needs pressure or alt"):
        BaroStream(t)


def test_drive_checks_overlap_and_origin():
    imu = _imu()
    baro = BaroStream(np.array([5.0, 6.0]), alt=np.array([1.0, 2.0]))
    with pytest.raises(ValueError, match="drive.baro: stream does not overlap"):
        Drive(imu, None, baro, np.array([0.8, 0.2, 100.0]))
    with pytest.raises(ValueError, match="drive.origin_lla"):
        Drive(imu, None, None, np.array([47.0, 11.0, 100.0]))


def test_trajectory_interpolation_is_linear_and_slerps():
    t = np.array([0.0, 1.0])
    q = np.array([[1.0, 0, 0, 0], [np.cos(0.5), 0, 0, np.sin(0.5)]])  # 1 rad yaw at t = 1
    tr = Trajectory(t, np.array([[0.1, 0.2, 10.0], [0.1, 0.2, 20.0]]), np.zeros((2, 3)), q)
    mid = tr.at(np.array([0.5]))
    assert mid.alt[0] == pytest.approx(15.0)
    assert mid.to_rph()[0, 2] == pytest.approx(0.5, abs=1e-12)
    with pytest.raises(ValueError, match="outside the trajectory span"):
        tr.at(np.array([2.0]))


def test_gnss_alt_and_the_drive_height_datum():
    from vnav_graph.report.html import drive_rows
    from vnav_graph.simulation import simulate

    drive = simulate("default", 0, duration_s=20.0)
    np.testing.assert_array_equal(drive.gnss.alt, drive.gnss.lla[:, 2])
    assert drive.height_reference == "ellipsoid"
    assert drive.height_datum == "height above the WGS-84 ellipsoid"
    msl = drive.replace(meta={**drive.meta, "height_reference": "msl"})
    assert msl.height_datum.startswith("height above mean sea level")
    assert ("heights", msl.height_datum) in drive_rows(msl)


def test_report_drive_table_explains_a_log_time_axis():
    from vnav_graph.report.html import drive_rows
    from vnav_graph.simulation import simulate

    drive = simulate("default", 0, duration_s=20.0)
    log = drive.replace(meta={**drive.meta, "clock": {
        "basis": "GPS time [s] (boot clock rescaled)", "boot_clock_per_gps_second": 0.92315}})
    rows = dict(drive_rows(log))
    assert rows["clock"] == ("GPS time [s] (boot clock rescaled) (the boot clock ran -7.68 % "
                             "against GPS time)")
    assert rows["duration"].startswith("20.0 s (t = 0.00 … 20.00 s")
    assert "clock" not in dict(drive_rows(drive))
