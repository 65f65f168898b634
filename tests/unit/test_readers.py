"""Log readers: content detection, units, axes, clock, and the drop/repair report.

Fixtures in tests/data (cut from the MIT-licensed Sensor Logger data, see tests/data/README.md)
make these tests run anywhere; tests on the full shared logs skip when the logs are absent.
A PX4 ULog is synthesised byte by byte (ULog spec: docs.px4.io "ULog File Format").
"""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from fuzz.writers import ulog_bytes

from vnav_graph.io.readers import detect_format, read_log
from vnav_graph.io.readers.phone_streams import mounting_rotation

DATA = Path(__file__).resolve().parent.parent / "data"
SKI_CUT = DATA / "sensorlogger_ski_cut"
CAR_CUT = DATA / "sensorlogger_car_1hz_cut.csv"
G0 = 9.80665
DEG = np.pi / 180



# ------------------------------------------------------------------- detection by content
def test_detection_uses_content_not_name(tmp_path: Path) -> None:
    disguised = tmp_path / "flight.bin"  # a CSV under a DataFlash-like name
    shutil.copy(CAR_CUT, disguised)
    assert detect_format(disguised) == "sensorlogger-merged-1hz"
    junk = tmp_path / "log.ulg"
    junk.write_bytes(b"\x00\x01garbage" * 100)
    with pytest.raises(ValueError, match="unknown log format"):
        read_log(junk)
    empty = tmp_path / "e.csv"
    empty.write_bytes(b"")
    with pytest.raises(ValueError, match="empty"):
        read_log(empty)
    assert detect_format(SKI_CUT) == "sensorlogger-folder"


# ------------------------------------------------------------------ phone mounting frame
def test_mounting_rotation_flat_phone_is_the_fixed_axis_map() -> None:
    # phone flat, screen up: f_d = (0, 0, +g) → x_b = y_d, y_b = x_d, z_b = −z_d exactly
    r = mounting_rotation(np.array([0.0, 0.0, G0]))
    np.testing.assert_allclose(r, [[0, 1, 0], [1, 0, 0], [0, 0, -1]], atol=1e-15)
    # upright in a car mount (top up): forward is the back of the phone (−z_d)
    r = mounting_rotation(np.array([0.0, G0, 0.0]))
    np.testing.assert_allclose(r @ [0, 0, -1.0], [1, 0, 0], atol=1e-15)
    np.testing.assert_allclose(r @ [0, G0, 0], [0, 0, -G0], atol=1e-12)
    assert np.linalg.det(r) == pytest.approx(1.0, abs=1e-12)  # proper rotation (FRD right-handed)


def test_merged_1hz_fixture_static_rows_read_minus_g() -> None:
    d = read_log(CAR_CUT)
    assert d.meta["format"] == "sensorlogger-merged-1hz" and d.meta["averaged_1s"] is True
    np.testing.assert_allclose(np.diff(d.imu.t), 1.0)  # exactly 1 s rows
    assert d.imu.t[0] == 0.5  # bin centre of the first 1 s mean
    static = d.imu.accel_b[:7]  # the car stands still for the first 7 rows (speed 0)
    # the mounting levels the 200-row mean (driving included), not the parking spot: a parked
    # car may stand on a slope of up to 5° → ≤ 0.86 m/s² horizontal (measured here: 3.7°);
    # |f| of a 1 s mean at rest is g within 0.2 m/s² (phone accelerometer bias)
    assert np.all(np.abs(static[:, :2]) < 0.86)
    np.testing.assert_allclose(np.linalg.norm(static, axis=1), G0, atol=0.2)
    np.testing.assert_allclose(static[:, 2], -G0, atol=0.2)
    # pressure hPa → Pa; baro datum aligned to the first 10 s of GNSS heights (44 m)
    assert 1.0e5 < d.baro.pressure.min() < 1.02e5
    k = d.gnss.t <= d.gnss.t[0] + 10
    assert np.median(np.interp(d.gnss.t[k], d.baro.t, d.baro.alt) - d.gnss.lla[k, 2]) == (
        pytest.approx(0.0, abs=1e-9))
    assert d.origin_lla[0] == pytest.approx(40.03230318892747 * DEG, abs=1e-12)


def test_sensorlogger_folder_fixture(tmp_path: Path) -> None:
    d = read_log(SKI_CUT)
    m = d.meta
    assert m["format"] == "sensorlogger-folder" and m["platform"] == "ios"
    drops = m["dropped"]["gnss"]
    assert drops["stale fix from before the recording start (seconds_elapsed < 0)"] == 1
    assert drops["repeated fix (all fields identical to the previous row)"] == 1
    assert d.gnss.t[0] > 0 and len(d.gnss) == 12  # 14 rows ≤ 12 s, 2 dropped
    # iOS uncalibrated accel is in g with the inertial-force sign: after conversion the mean
    # specific force is +up, i.e. (0, 0, −|mean|) in b by construction of the mounting frame
    f_mean = d.imu.accel_b.mean(axis=0)
    np.testing.assert_allclose(f_mean[:2], 0.0, atol=1e-9)
    assert f_mean[2] < 0
    # g → m/s²: the median |f| of a phone on a skier is g within 10 % (README: 1.02 g)
    assert np.median(np.linalg.norm(d.imu.accel_b, axis=1)) == pytest.approx(G0, rel=0.1)
    assert 70000 < d.baro.pressure.min() and d.baro.pressure.max() < 71000  # 703 hPa
    assert d.meta["height_reference"] == "ellipsoid"
    import pandas as pd

    loc = pd.read_csv(SKI_CUT / "Location.csv")
    assert d.gnss.lla[0, 2] == loc["altitude"][2]  # ellipsoidal (not altitudeAboveMeanSeaLevel)
    assert loc["altitude"][2] - loc["altitudeAboveMeanSeaLevel"][2] == pytest.approx(50, abs=1)
    # σ: horizontalAccuracy/1.5 floored at 0.5, verticalAccuracy floored at 1
    assert np.all(d.gnss.pos_sd[:, :2] >= 0.5) and np.all(d.gnss.pos_sd[:, 2] >= 1.0)
    assert d.mag is None and any("no Magnetometer.csv" in n for n in m["notes"])
    # without Metadata the Android convention is assumed and said so
    bare = tmp_path / "ski"
    shutil.copytree(SKI_CUT, bare)
    (bare / "Metadata.csv").unlink()
    d2 = read_log(bare)
    assert any("Android sign convention assumed" in n for n in d2.meta["notes"])


def test_phone_gyro_sign_matches_gravity_rotation() -> None:
    """A vector fixed in n seen from b obeys dg_b/dt = −ω_b × g_b. iOS's own gravity estimate
    (Gravity.csv, pointing down in device axes with standardisation off) is rotated into b with
    the reader's mounting matrix; the reader's gyro_b must then satisfy the equation."""
    import pandas as pd

    d = read_log(SKI_CUT)
    r_bd = np.array(d.meta["imu_mounting"]["mat_bd"])
    grav = pd.read_csv(SKI_CUT / "Gravity.csv")
    t = grav["seconds_elapsed"].to_numpy()
    g_b = grav[["x", "y", "z"]].to_numpy() @ r_bd.T
    m = (t > d.imu.t[0]) & (t < d.imu.t[-1])
    t, g_b = t[m], g_b[m]
    w_b = np.column_stack([np.interp(t, d.imu.t, d.imu.gyro_b[:, j]) for j in range(3)])
    dg = np.gradient(g_b, t, axis=0)
    pred = -np.cross(w_b, g_b)
    corr = np.sum(dg * pred) / np.sqrt(np.sum(dg**2) * np.sum(pred**2))
    # 0.999 on the full log with the calibrated gyro; the uncalibrated gyro's bias and the
    # finite difference at 100 Hz leave it above 0.95. A wrong sign or axis map gives < 0.
    assert corr > 0.95


def test_truncated_csv_rejected_or_reported(tmp_path: Path) -> None:
    text = CAR_CUT.read_text()
    cut = tmp_path / "cut.csv"
    cut.write_text(text[: len(text.splitlines()[0]) + 300])  # header + < 2 rows
    with pytest.raises(ValueError, match="truncated"):
        read_log(cut)
    mid = tmp_path / "mid.csv"
    mid.write_text(text[: len(text) // 2])  # cut in the middle of a row
    d = read_log(mid)  # the partial last row lacks GNSS/IMU fields: dropped and counted
    assert sum(sum(v.values()) for v in d.meta["dropped"].values()) >= 1


# ---------------------------------------------------------------------------- PX4 ULog
def test_px4_ulog_synthetic(tmp_path: Path) -> None:
    n = 200  # 2 s of 100 Hz IMU
    t_us = (1_000_000 + np.arange(n) * 10_000).tolist()
    t_us[50] = t_us[49]  # one duplicated stamp
    imu = [(t, 0.01, -0.02, 0.03, 0.1, -0.2, -9.8) for t in t_us]
    gps = []
    for k in range(12):
        fix = 2 if k == 0 else 3  # first fix 2-D → dropped
        gps.append((1_000_000 + k * 200_000, int(47.5e7) + k, int(8.25e7), 512_300 + k * 100,
                    560_300 + k * 100, 0.8, 1.2, 0.2, 0.1, 0.2, -0.5, 1, fix))
    air = [(1_000_000 + k * 50_000, 95_000.0 - k) for k in range(40)]
    lpos = [(1_000_000 + k * 100_000, -1.5, 1) for k in range(20)]
    topics = {
        "sensor_combined": ("uint64_t timestamp;float[3] gyro_rad;float[3] accelerometer_m_s2;",
                            [(r[0], *r[1:]) for r in imu]),
        "vehicle_gps_position": (
            "uint64_t timestamp;int32_t lat;int32_t lon;int32_t alt;int32_t alt_ellipsoid;"
            "float eph;float epv;float s_variance_m_s;float vel_n_m_s;float vel_e_m_s;"
            "float vel_d_m_s;uint8_t vel_ned_valid;uint8_t fix_type;", gps),
        "vehicle_air_data": ("uint64_t timestamp;float baro_pressure_pa;", air),
        "vehicle_local_position": ("uint64_t timestamp;float z;uint8_t z_valid;", lpos),
    }
    p = tmp_path / "flight.dat"  # name says nothing: detection by the ULog magic
    p.write_bytes(ulog_bytes(topics))
    d = read_log(p)
    assert d.meta["format"] == "px4-ulog"
    assert len(d.imu) == n - 1 and d.meta["dropped"]["imu"]["duplicated time stamp"] == 1
    np.testing.assert_allclose(d.imu.accel_b[0], [0.1, -0.2, -9.8], rtol=1e-6)  # float32
    assert d.meta["dropped"]["gnss"]["no 3-D fix (fix_type < 3)"] == 1
    assert len(d.gnss) == 11 and d.gnss.t[0] == pytest.approx(1.2)
    assert d.meta["height_reference"] == "ellipsoid"
    assert d.gnss.lla[0, 2] == pytest.approx(560.4)  # alt_ellipsoid mm → m
    assert d.gnss.lla[0, 0] == pytest.approx((47.5 + 1e-7) * DEG, rel=1e-12)
    np.testing.assert_allclose(d.gnss.vel_n[0], [0.1, 0.2, -0.5], rtol=1e-6)
    np.testing.assert_allclose(d.gnss.pos_sd[0], [0.8, 0.8, 1.2], rtol=1e-6)
    assert d.baro.pressure[0] == pytest.approx(95_000.0)
    ob = d.meta["onboard"]  # −z = 1.5 m + offset to the GNSS fixes inside its time span
    k = d.gnss.t <= ob["t"][-1]
    assert np.median(ob["alt"]) == pytest.approx(np.median(d.gnss.lla[k, 2]), abs=1e-4)
    assert ob["offset_m"] == pytest.approx(np.median(d.gnss.lla[k, 2]) - 1.5, abs=1e-4)
    p.write_bytes(p.read_bytes()[:150])  # truncated inside the definitions
    with pytest.raises(ValueError):
        read_log(p)


# --------------------------------------------------------------------- shared real logs
def test_ardupilot_218(shared_log: Callable[[str], Path]) -> None:
    import gc
    import warnings

    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        d = read_log(shared_log("erle_pxf_218/218.BIN"))
        gc.collect()  # an unclosed log file warns when collected (it landed in a report)
    assert not [w for w in rec if issubclass(w.category, ResourceWarning)]
    m = d.meta
    assert m["format"] == "ardupilot-dataflash" and m["height_reference"] == "msl"
    assert m["vehicle"] == "multirotor"  # "ArduCopter V3.3-dev", "Frame: QUAD"
    assert (len(d.imu), len(d.gnss), len(d.baro)) == (16750, 1816, 3350)  # README counts
    # 50 Hz on the boot clock, which runs 0.9232 s per GPS second: 46.2 Hz in GPS time
    assert d.imu.rate_hz == pytest.approx(50.0 * 0.9232, rel=0.01)
    # on the ground before take-off: FRD, level → (≈0, ≈0, −g); 0.5 m/s² covers tilt + bias
    f0 = d.imu.accel_b[:50].mean(axis=0)
    assert abs(f0[0]) < 0.5 and abs(f0[1]) < 0.5 and f0[2] == pytest.approx(-9.9, abs=0.2)
    # VZ positive down: −VZ correlates with the baro climb rate
    vz_up = -d.gnss.vel_n[:, 2]
    rate = np.gradient(np.convolve(d.baro.alt, np.ones(9) / 9, "same"), d.baro.t)
    assert np.corrcoef(vz_up[20:-20], np.interp(d.gnss.t, d.baro.t, rate)[20:-20])[0, 1] > 0.5
    assert 515.0 < d.gnss.lla[:, 2].min() and d.gnss.lla[:, 2].max() < 530.0  # README range
    assert m["boot_clock_per_gps_second"] == pytest.approx(335.0 / 363.0, abs=2e-3)
    assert m["onboard"]["name"].startswith("ctun.alt")  # AHRS_EKF_USE = 0 in this log
    # onboard alt in the drive's reference: within 3 m of GNSS over the first 10 s
    k = d.gnss.t < d.gnss.t[0] + 10
    ob = np.interp(d.gnss.t[k], m["onboard"]["t"], m["onboard"]["alt"])
    assert np.median(np.abs(ob - d.gnss.lla[k, 2])) < 3.0


def test_ardupilot_vehicle_type_from_the_banner() -> None:
    from vnav_graph.io.readers.ardupilot import vehicle_kind

    quad = [{"Message": "Frame: QUAD"}]
    assert vehicle_kind("ArduCopter V3.3-dev (834f90e8)", quad, {}) == "multirotor"
    assert vehicle_kind("ArduCopter V4.5.7 (1234)", [], {"FRAME_CLASS": 1.0}) == "multirotor"
    assert vehicle_kind("ArduCopter V4.5.7 (1234)", [], {"FRAME_CLASS": 6.0}) == "helicopter"
    assert vehicle_kind("ArduCopter V3.2.1", [{"Message": "Frame: HELI"}], {}) == "helicopter"
    assert vehicle_kind("ArduPlane V4.3.0", [], {}) == "fixed-wing"
    assert vehicle_kind("ArduRover V4.2.0", [], {}) == "ground"
    assert vehicle_kind(None, [], {}) == "unknown"


def test_px4_vehicle_type_from_mav_type() -> None:
    from vnav_graph.io.readers.px4 import vehicle_of_mav_type

    assert [vehicle_of_mav_type(m) for m in (2, 13, 14, 1, 4, 10, 22)] == [
        "multirotor", "multirotor", "multirotor", "fixed-wing", "helicopter", "ground", "vtol"]
    assert vehicle_of_mav_type(None) == "unknown" and vehicle_of_mav_type(99) == "unknown"


def test_ardupilot_loiter_rtl_repairs(shared_log: Callable[[str], Path]) -> None:
    d = read_log(shared_log("erle_pxf_loiter_rtl/Loiter_RTL.bin"))
    drop = d.meta["dropped"]["gnss"]
    assert drop["no 3-D fix (Status < 3)"] == 2  # README: first two without a 3-D fix
    assert drop["duplicated time stamp"] == 111  # same GPS time logged twice
    gap = d.meta["gaps"]["imu"]
    # logging gap of 22.245 s on the boot clock = 22.245 / 0.92326 = 24.094 GPS seconds
    assert len(gap) == 1 and gap[0][1] == pytest.approx(22.245 / 0.92326, abs=2e-3)
    assert np.all(np.diff(d.gnss.t) > 0)
    # no compass: every MAG record is (0, 0, 0) → dropped and counted, no MagStream
    assert d.mag is None
    assert d.meta["dropped"]["mag"] == {"all-zero sample (no compass)": 2355}
    assert any("drive has no magnetometer" in n for n in d.meta["notes"])


def test_ardupilot_glitch_log_keeps_gnss_for_the_estimators(
        shared_log: Callable[[str], Path]) -> None:
    d = read_log(shared_log("erle_pxf_181_gps_glitch/181.BIN"))
    h = d.gnss.lla[:, 2]
    # the reader does not gate: the bad heights (README 317.9 … 826.5 m) reach the estimators
    assert h.min() == pytest.approx(317.93, abs=0.01) and h.max() == pytest.approx(826.49,
                                                                                 abs=0.01)
    assert len(d.gnss) == 675
    # baro alt is the ISA altitude of the logged pressure plus one constant (ArduPilot's own
    # BARO.Alt, temperature-corrected, spans 49.8 m; ISA gives 47.9 m: a 4 % scale the
    # estimators' baro scale factor absorbs)
    from vnav_graph.geo.atmosphere import isa_altitude

    assert np.ptp(d.baro.alt - isa_altitude(d.baro.pressure)) < 1e-9
    assert np.ptp(d.baro.alt) == pytest.approx(47.9, abs=0.1)


def test_truncated_dataflash(shared_log: Callable[[str], Path], tmp_path: Path) -> None:
    src = shared_log("erle_pxf_218/218.BIN").read_bytes()
    tiny = tmp_path / "cut.bin"
    tiny.write_bytes(src[:3000])  # format records only
    with pytest.raises(ValueError, match="no IMU data"):
        read_log(tiny)
    half = tmp_path / "half.bin"
    half.write_bytes(src[: len(src) // 2 + 7])  # ends inside a record
    d = read_log(half)
    assert d.meta["dropped"]["log"]["incomplete last record (file truncated)"] == 1
    assert d.duration_s < 200  # about half of the 335 s
    from vnav_graph.cli import main

    assert main(["holdout", str(tiny), "--out", str(tmp_path / "o")]) == 2
    assert not (tmp_path / "o" / "holdout.json").exists()


def test_ski_full_and_car_full(shared_log: Callable[[str], Path]) -> None:
    ski = read_log(shared_log("ski_iphone_100hz"))
    assert ski.mag is None  # the ski export has no Magnetometer.csv
    assert len(ski.gnss) == 362 and ski.imu.rate_hz == pytest.approx(100.5, abs=0.5)
    assert ski.gnss.lla[:, 2].max() - ski.gnss.lla[:, 2].min() > 390  # 412 m descent
    car = read_log(shared_log("car_phone_1hz_2025-07-18/2025-07-18_23-13-43.csv"))
    assert car.meta["dropped"]["gnss"]["missing position"] == 37  # README: 37 rows
    assert len(car.imu) == 5563 and car.meta["averaged_1s"] is True
    # mag_x/y/z on the same 1 s rows; a phone in a car: |B| 88 µT (hard iron of the car and
    # mount on top of the 52 µT Earth field), σ default 3 µT
    assert len(car.mag) == 5563 and car.mag.sd_ut == 5.0
    np.testing.assert_array_equal(car.mag.t, car.imu.t)
    assert np.median(np.linalg.norm(car.mag.field_b, axis=1)) == pytest.approx(88.0, abs=1.0)
