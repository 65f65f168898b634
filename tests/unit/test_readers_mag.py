"""Log readers: the magnetometer stream (units, body axes, the phones' mounting, PX4's
topics) checked against each log's own attitude, and the date of the Earth's field.

Synthetic logs come from the fuzz corpus's writers (``tests/fuzz/writers.py``); tests on the
full shared logs skip when the logs are absent.
"""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from fuzz.writers import ulog_bytes

from vnav_graph.io.readers import read_log

DATA = Path(__file__).resolve().parent.parent / "data"
SKI_CUT = DATA / "sensorlogger_ski_cut"
CAR_CUT = DATA / "sensorlogger_car_1hz_cut.csv"
G0 = 9.80665
DEG = np.pi / 180



# ------------------------------------------------------------------------ magnetometer
def _heading_deg(field_b: np.ndarray, roll: np.ndarray, pitch: np.ndarray) -> np.ndarray:
    """Tilt-compensated magnetic heading [deg] of a body-FRD field [µT] at roll/pitch [rad]."""
    bx, by, bz = field_b.T
    xh = bx * np.cos(pitch) + (by * np.sin(roll) + bz * np.cos(roll)) * np.sin(pitch)
    yh = by * np.cos(roll) - bz * np.sin(roll)
    return np.degrees(np.arctan2(-yh, xh))


def _wrap_deg(a: np.ndarray) -> np.ndarray:
    return (np.asarray(a) + 180.0) % 360.0 - 180.0


def _ardupilot_att(path: Path) -> np.ndarray:
    """ATT records of a DataFlash log: boot time [s], roll, pitch, yaw [rad]."""
    import io
    from contextlib import redirect_stdout

    from pymavlink import DFReader

    with redirect_stdout(io.StringIO()):
        r = DFReader.DFReader_binary(str(path), zero_time_base=True)
    rows = []
    while (m := r.recv_match(type=["ATT"])) is not None:
        rows.append((m.TimeMS * 1e-3, m.Roll * DEG, m.Pitch * DEG, m.Yaw * DEG))
    r.filehandle.close()
    return np.array(rows)


def _mag_vs_att(d, att: np.ndarray) -> np.ndarray:
    """Tilt-compensated MAG heading − ATT.Yaw [deg], ATT re-stamped onto the drive's clock
    with the reader's boot → GPS-time rescaling."""
    clk = d.meta["clock"]
    t_att = clk["t_ref_s"] + (att[:, 0] - clk["t_ref_s"]) / d.meta["boot_clock_per_gps_second"]
    roll, pitch = (np.interp(d.mag.t, t_att, att[:, j]) for j in (1, 2))
    yaw = np.degrees(np.interp(d.mag.t, t_att, np.unwrap(att[:, 3])))
    return _wrap_deg(_heading_deg(d.mag.field_b, roll, pitch) - yaw)


def test_ardupilot_218_mag_heading_matches_att_yaw(shared_log: Callable[[str], Path]) -> None:
    p = shared_log("erle_pxf_218/218.BIN")
    d = read_log(p)
    m = d.mag
    assert len(m) == 3350 and m.sd_ut == 5.0 and "mag" not in d.meta["dropped"]
    # first record MagX/Y/Z = (−142, 45, 258) mG → µT; |B| = 30.86 µT (Earth field, offsets
    # applied by ArduPilot: the magnitude stays within 2 µT while the copter turns)
    np.testing.assert_allclose(m.field_b[0], [-14.2, 4.5, 25.8], atol=1e-12)
    b = np.linalg.norm(m.field_b, axis=1)
    assert np.median(b) == pytest.approx(30.86, abs=0.05) and np.std(b) < 1.0
    # 10 Hz on the boot clock, rescaled like the IMU: 9.23 Hz in GPS time, inside the IMU span
    assert 1 / np.median(np.diff(m.t)) == pytest.approx(10.0 * 0.9232, rel=0.01)
    assert d.imu.t[0] <= m.t[0] and m.t[-1] <= d.imu.t[-1] + 0.2
    # heading from the field with ATT roll/pitch agrees with ATT.Yaw (measured: median 0.24°,
    # sd 5.0°). A wrong axis, sign or clock (MAG left on boot time while ATT is mapped: up to
    # 28 s apart at the end) breaks it.
    dh = _mag_vs_att(d, _ardupilot_att(p))
    assert abs(np.median(dh)) < 1.0 and np.std(dh) < 7.0


def test_ardupilot_181_mag_is_noisier(shared_log: Callable[[str], Path]) -> None:
    p = shared_log("erle_pxf_181_gps_glitch/181.BIN")
    d = read_log(p)
    assert len(d.mag) == 1245
    b = np.linalg.norm(d.mag.field_b, axis=1)
    assert np.median(b) == pytest.approx(37.21, abs=0.05)  # 21 % above 218's: interference
    dh = _mag_vs_att(d, _ardupilot_att(p))
    # measured: median −1.6°, sd 18° (motor interference in the 50 m climb)
    assert abs(np.median(dh)) < 5.0 and 10.0 < np.std(dh) < 30.0


def test_px4_real_mag_heading_matches_attitude(shared_log: Callable[[str], Path]) -> None:
    from pyulog import ULog

    p = shared_log("px4_ulog_samples/sample_px4_events.ulg")
    d = read_log(p)
    assert len(d.mag) == 459 and d.mag.sd_ut == 5.0  # vehicle_magnetometer, not sensor_mag
    # Gauss → µT: Zurich's field is 48 µT
    assert np.median(np.linalg.norm(d.mag.field_b, axis=1)) == pytest.approx(48.07, abs=0.05)
    a = ULog(str(p), ["vehicle_attitude"]).data_list[0].data
    t = a["timestamp_sample"] * 1e-6
    w, x, y, z = (a[f"q[{i}]"] for i in range(4))
    roll = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2 * (w * y - z * x), -1, 1))
    yaw = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    rp = [np.interp(d.mag.t, t, v) for v in (roll, pitch)]
    dh = _wrap_deg(_heading_deg(d.mag.field_b, *rp)
                   - np.degrees(np.interp(d.mag.t, t, np.unwrap(yaw))))
    # magnetic minus true heading = −declination (Zurich ≈ +3.4°); measured −3.43° ± 1.0°
    assert np.median(dh) == pytest.approx(-3.4, abs=1.0) and np.std(dh) < 2.0


def _static_raw(seconds: float = 20.0):
    """Level, motionless 100 Hz IMU, 5 Hz GNSS, 10 Hz baro starting at t = 1 s (fuzz Raw)."""
    from fuzz.writers import Raw

    from vnav_graph.geo.atmosphere import isa_pressure

    t = 1.0 + np.arange(int(seconds * 100)) * 0.01
    tg = 1.0 + np.arange(int(seconds * 5)) * 0.2
    tb = 1.0 + np.arange(int(seconds * 10)) * 0.1
    m = tg.size
    alt = 500.0 + 0.1 * np.arange(tb.size)
    return Raw(t, np.zeros((t.size, 3)), np.tile([0.0, 0.0, -G0], (t.size, 1)), tg,
               np.full(m, 47.5), np.full(m, 8.25), np.full(m, 500.0), np.zeros((m, 3)),
               np.full(m, 1.0), np.full(m, 2.0), tb, np.asarray(isa_pressure(alt)), alt)


def _turning_field(t: np.ndarray) -> np.ndarray:
    """Body-FRD field [µT] of a level vehicle yawing at 10°/s in a (21.5, 0.5, 42.5) µT NED
    field (Zurich)."""
    psi = np.radians(10.0 * t)
    bn = np.array([21.5, 0.5, 42.5])
    return np.column_stack([np.cos(psi) * bn[0] + np.sin(psi) * bn[1],
                            -np.sin(psi) * bn[0] + np.cos(psi) * bn[1], np.full(t.size, bn[2])])


def test_dataflash_synthetic_mag(tmp_path: Path) -> None:
    from fuzz.writers import write_dataflash

    raw = _static_raw()
    t_mag = 1.05 + np.arange(190) * 0.1
    field = _turning_field(t_mag)
    field[[5, 6]] = 0.0  # compass not yet delivering: logged as (0, 0, 0)
    raw.extra["mag"] = (t_mag, field)
    d = read_log(write_dataflash(raw, tmp_path / "mag.bin"))
    m = d.mag
    assert d.meta["dropped"]["mag"] == {"all-zero sample (no compass)": 2}
    keep = np.ones(t_mag.size, bool)
    keep[[5, 6]] = False
    np.testing.assert_allclose(m.t, t_mag[keep], atol=1e-6)  # boot clock (GPS ratio 1)
    # int16 milligauss: 0.1 µT resolution
    np.testing.assert_allclose(m.field_b, field[keep], atol=0.05 + 1e-9)
    psi = _heading_deg(m.field_b, 0.0, 0.0)  # heading follows the 10°/s turn
    np.testing.assert_allclose(_wrap_deg(psi - 10.0 * m.t + np.degrees(np.arctan2(0.5, 21.5))),
                               0.0, atol=0.3)
    raw.extra["mag"] = (t_mag, np.zeros((t_mag.size, 3)))  # a log without a compass
    d = read_log(write_dataflash(raw, tmp_path / "nomag.bin"))
    assert d.mag is None and d.meta["dropped"]["mag"] == {"all-zero sample (no compass)": 190}


def test_px4_ulog_synthetic_mag(tmp_path: Path) -> None:
    n = 300
    imu = [(1_000_000 + k * 10_000, 0.0, 0.0, 0.0, 0.0, 0.0, -9.8) for k in range(n)]
    gps = [(1_000_000 + k * 200_000, int(47.5e7), int(8.25e7), 500_000, 550_000, 0.8, 1.2,
            0.2, 0.0, 0.0, 0.0, 1, 3) for k in range(15)]
    t_mag = 1.0 + np.arange(100) * 0.02
    ga = _turning_field(t_mag) / 100.0  # µT → Gauss
    ga[3] = 0.0
    ga[4] = np.nan
    base = {
        "sensor_combined": ("uint64_t timestamp;float[3] gyro_rad;float[3] accelerometer_m_s2;",
                            imu),
        "vehicle_gps_position": (
            "uint64_t timestamp;int32_t lat;int32_t lon;int32_t alt;int32_t alt_ellipsoid;"
            "float eph;float epv;float s_variance_m_s;float vel_n_m_s;float vel_e_m_s;"
            "float vel_d_m_s;uint8_t vel_ned_valid;uint8_t fix_type;", gps),
    }
    rows = [(int(round(t * 1e6)), *g) for t, g in zip(t_mag, ga, strict=True)]
    vm = ("uint64_t timestamp;float[3] magnetometer_ga;", rows)
    # sensor_mag of old firmware carries x, y, z in Gauss; here a different value, to show
    # that vehicle_magnetometer wins when both are logged
    sm = ("uint64_t timestamp;float x;float y;float z;", [(r[0], 0.3, 0.0, 0.4) for r in rows])
    p = tmp_path / "mag.ulg"
    p.write_bytes(ulog_bytes({**base, "vehicle_magnetometer": vm, "sensor_mag": sm}))
    d = read_log(p)
    keep = np.ones(t_mag.size, bool)
    keep[[3, 4]] = False
    assert d.meta["dropped"]["mag"] == {"non-finite sample": 1,
                                        "all-zero sample (no compass)": 1}
    np.testing.assert_allclose(d.mag.t, t_mag[keep], atol=1e-9)
    np.testing.assert_allclose(d.mag.field_b, _turning_field(t_mag)[keep], rtol=1e-6)
    assert d.mag.sd_ut == 5.0
    p.write_bytes(ulog_bytes({**base, "sensor_mag": sm}))  # old firmware: sensor_mag only
    d = read_log(p)
    np.testing.assert_allclose(d.mag.field_b, np.tile([30.0, 0.0, 40.0], (100, 1)), rtol=1e-6)
    p.write_bytes(ulog_bytes(base))
    assert read_log(p).mag is None


def test_fuzz_writer_ulog_mag_round_trip(tmp_path: Path) -> None:
    from fuzz.writers import write_ulog

    raw = _static_raw(5.0)
    t_mag = 1.0 + np.arange(50) * 0.1
    raw.extra["mag"] = (t_mag, _turning_field(t_mag))
    d = read_log(write_ulog(raw, tmp_path / "w.ulg"))
    np.testing.assert_allclose(d.mag.field_b, _turning_field(t_mag), rtol=1e-6)


def test_sensorlogger_folder_mag_uses_the_imu_mounting(tmp_path: Path) -> None:
    """A field fixed in n, fed as Magnetometer.csv in device axes, comes out in b as the same
    vector for every pose: 40 µT straight down (iOS Gravity.csv points down in device axes,
    so 40 µT × its unit vector is a vertical field at the magnetic pole). The reader must map
    it with the accelerometer's mounting matrix and without the iOS acceleration sign flip."""
    import pandas as pd

    folder = tmp_path / "ski"
    shutil.copytree(SKI_CUT, folder)
    grav = pd.read_csv(SKI_CUT / "Gravity.csv")
    g = grav[["x", "y", "z"]].to_numpy()
    b_d = 40.0 * g / np.linalg.norm(g, axis=1, keepdims=True)
    b_d[10] = 0.0
    b_d[11, 1] = np.nan
    mag = grav[["time", "seconds_elapsed"]].copy()
    mag["z"], mag["y"], mag["x"] = b_d[:, 2], b_d[:, 1], b_d[:, 0]
    mag.to_csv(folder / "Magnetometer.csv", index=False)
    d = read_log(folder)
    r_bd = np.array(d.meta["imu_mounting"]["mat_bd"])
    keep = np.ones(len(mag), bool)
    keep[[10, 11]] = False
    assert d.meta["dropped"]["mag"] == {"non-finite sample": 1, "all-zero sample (no compass)": 1}
    np.testing.assert_allclose(d.mag.t, grav["seconds_elapsed"].to_numpy()[keep])
    np.testing.assert_allclose(d.mag.field_b, b_d[keep] @ r_bd.T, atol=1e-12)
    assert d.mag.sd_ut == 5.0
    np.testing.assert_allclose(np.linalg.norm(d.mag.field_b, axis=1), 40.0)
    # z_b is the mean gravity direction: the mean field points down in b (the skier's phone
    # tumbles, so the mean of the unit vectors is shorter than 1: measured (0.8, 0.7, 24.1))
    mean = d.mag.field_b.mean(axis=0)
    assert abs(mean[0]) < 2.0 and abs(mean[1]) < 2.0 and mean[2] > 20.0
    # and it turns with the gyro: dB_b/dt = −ω_b × B_b for a field fixed in n
    t = d.mag.t
    w_b = np.column_stack([np.interp(t, d.imu.t, d.imu.gyro_b[:, j]) for j in range(3)])
    db = np.gradient(d.mag.field_b, t, axis=0)
    pred = -np.cross(w_b, d.mag.field_b)
    assert np.sum(db * pred) / np.sqrt(np.sum(db**2) * np.sum(pred**2)) > 0.95


def test_merged_csv_mag_mapped_like_the_accelerometer(tmp_path: Path) -> None:
    import pandas as pd

    d = read_log(CAR_CUT)
    df = pd.read_csv(CAR_CUT)
    r_bd = np.array(d.meta["imu_mounting"]["mat_bd"])
    acc_d = df[["acc_x", "acc_y", "acc_z"]].to_numpy()
    np.testing.assert_allclose(d.imu.accel_b, acc_d @ r_bd.T, atol=1e-12)  # the same map
    mag_d = df[["mag_x", "mag_y", "mag_z"]].to_numpy()
    np.testing.assert_allclose(d.mag.field_b, mag_d @ r_bd.T, atol=1e-12)
    np.testing.assert_array_equal(d.mag.t, d.imu.t)  # the same 1 s rows, bin centres
    assert d.mag.sd_ut == 5.0
    assert np.median(np.linalg.norm(d.mag.field_b, axis=1)) == pytest.approx(76.0, abs=1.0)
    no_mag = tmp_path / "nomag.csv"
    df.drop(columns=["mag_x", "mag_y", "mag_z"]).to_csv(no_mag, index=False)
    d2 = read_log(no_mag)
    assert d2.mag is None and any("no mag_x/y/z" in n for n in d2.meta["notes"])


@pytest.mark.parametrize(("rel", "year"), [
    ("erle_pxf_218/218.BIN", 2014.93),  # GPS week of the first fix
    ("px4_ulog_samples/sample_px4_events.ulg", 2024.21),  # sensor_gps time_utc_usec
    ("car_phone_1hz_2025-07-18/2025-07-18_23-13-43.csv", 2025.545),  # ISO time, 18 July
    ("ski_iphone_100hz", 2025.916),  # Location.csv Unix ns, 1 December
])
def test_logs_carry_their_date(shared_log: Callable[[str], Path], rel: str, year: float) -> None:
    """The date of the Earth's field (World Magnetic Model epoch) comes from the log."""
    d = read_log(shared_log(rel))
    assert d.meta["decimal_year"] == pytest.approx(year, abs=0.005)


def test_decimal_year_unix() -> None:
    from vnav_graph.io.readers._common import decimal_year_unix

    assert decimal_year_unix([np.nan, 0.0, 1735689600.0]) == pytest.approx(2025.0)  # 2025-01-01
    assert decimal_year_unix([12.5, 300.0]) is None  # boot seconds, not a date
