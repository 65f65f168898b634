"""One test per input defect (the corpus runs them all; these name them)."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest

from vnav_graph.io import load_drive
from vnav_graph.io.sanity import check_drive
from vnav_graph.types.streams import BaroStream, GnssStream, ImuStream

from .mutations import SEMANTIC
from .writers import (
    G0,
    npz_arrays,
    sim_raw,
    write_dataflash,
    write_merged_csv,
    write_npz,
    write_npz_arrays,
    write_ulog,
)

RAW, SIM = sim_raw()


def _mut(name: str):
    return SEMANTIC[name][0](RAW, np.random.default_rng(0))


# ------------------------------------------------------------------ DataFlash
def test_dataflash_fmt_names_swapped_is_a_one_line_rejection(tmp_path):
    p = write_dataflash(RAW, tmp_path / "swap.bin", names={"IMU": "BARO", "BARO": "IMU"})
    with pytest.raises(ValueError, match="IMU records are usable") as e:  # was IndexError
        load_drive(p)
    assert "\n" not in str(e.value)


def test_dataflash_all_accz_nan_is_a_one_line_rejection(tmp_path):
    p = write_dataflash(_mut("accz-all-nan"), tmp_path / "nan.bin")
    with pytest.raises(ValueError, match="non-finite"):
        load_drive(p)


def test_pymavlink_chatter_never_reaches_the_terminal(tmp_path, capfd):
    b = bytearray(write_dataflash(RAW, tmp_path / "ok.bin").read_bytes())
    for k in range(20_000, len(b), 37_000):  # break a few record headers
        b[k] ^= 0xFF
    p = tmp_path / "flipped.bin"
    p.write_bytes(bytes(b))
    try:
        d = load_drive(p)
        assert any("suppressed" in w or "dropped" in w for w in d.meta["warnings"])
    except ValueError:
        pass
    out, err = capfd.readouterr()
    assert out == "" and err == ""  # "bad header" lines come from pymavlink's C indexer


# ------------------------------------------------------------------------ .npz
def test_npz_byte_damage_inside_a_member_is_a_value_error(tmp_path):
    p = write_npz(RAW, tmp_path / "d.npz", SIM)
    b = bytearray(p.read_bytes())
    b[len(b) // 3] ^= 0x55
    p.write_bytes(bytes(b))
    with pytest.raises(ValueError, match="not a readable .npz drive"):  # was zlib.error
        load_drive(p)


@pytest.mark.parametrize(("change", "match"), [
    ({"meta": [1, 2]}, "'meta' is a list"),
    ({"meta": None}, "'meta' is null"),
    ({"imu_spec": [1, 2]}, "not a sensor spec"),
    ({"baro_spec": "BaroSpec"}, "not a sensor spec"),
    ({"baro_truth": {"scale": 0.01}}, "baro_truth"),
    ({"imu_spec": {"type": "ImuSpec", "fields": {"gyro_noise_density": "lots"}}},
     "expected a number"),
])
def test_npz_header_with_wrong_types_is_a_value_error(tmp_path, change, match):
    arrays, header = npz_arrays(RAW, SIM)
    header.update(change)
    p = write_npz_arrays(arrays, header, tmp_path / "h.npz")
    with pytest.raises(ValueError, match=match):  # was TypeError
        load_drive(p)


def test_npz_without_truth_arrays_reads_as_a_real_drive(tmp_path):
    arrays, header = npz_arrays(RAW, SIM)
    arrays = {k: v for k, v in arrays.items() if not k.startswith("truth_")}
    d = load_drive(write_npz_arrays(arrays, header, tmp_path / "nt.npz"))
    assert d.truth is None and d.baro_truth is None and d.source == "log"


def test_npz_sizes_are_checked_before_decompressing(tmp_path, monkeypatch):
    import zipfile

    import vnav_graph.io.drive_io as dio

    p = write_npz(RAW, tmp_path / "bomb.npz", SIM)
    with zipfile.ZipFile(p, "a", compression=zipfile.ZIP_DEFLATED) as zf, \
            zf.open("pad.npy", "w", force_zip64=True) as fh:
        for _ in range(300):
            fh.write(bytes(2**20))

    def no_load(*a, **k):
        raise AssertionError("np.load called on a hostile archive")

    monkeypatch.setattr(dio.np, "load", no_load)
    with pytest.raises(ValueError, match="hostile archive"):
        load_drive(p)


def test_npz_int64_millisecond_stamps_are_refused_at_once(tmp_path):
    arrays, header = npz_arrays(RAW, SIM)
    arrays["imu_t"] = np.round(arrays["imu_t"] * 1e3).astype(np.int64)
    t0 = time.perf_counter()
    with pytest.raises(ValueError, match="integer dtype"):  # was a hang in the estimators
        load_drive(write_npz_arrays(arrays, header, tmp_path / "ms.npz"))
    assert time.perf_counter() - t0 < 10.0


def test_npz_bool_baro_is_refused(tmp_path):
    arrays, header = npz_arrays(RAW, SIM)
    arrays["baro_alt"] = arrays["baro_alt"] > np.median(arrays["baro_alt"])
    with pytest.raises(ValueError, match="dtype bool"):
        load_drive(write_npz_arrays(arrays, header, tmp_path / "b.npz"))


# ------------------------------------------------------------------ merged CSV
def test_merged_csv_row_with_a_missing_field_is_dropped_and_counted(tmp_path):
    good = write_merged_csv(RAW, tmp_path / "good.csv")
    lines = good.read_text().splitlines()
    parts = lines[50].split(",")
    parts[4] = parts[4] + parts.pop(5)  # one comma lost: pandas would pad the row
    lines[50] = ",".join(parts)
    bad = tmp_path / "bad.csv"
    bad.write_text("\n".join(lines) + "\n")
    d, c = load_drive(bad), load_drive(good)
    assert d.meta["dropped"]["rows"] == {"malformed CSV line (wrong field count)": 1}
    assert any("malformed" in w for w in d.meta["warnings"])
    assert len(d.gnss) == len(c.gnss) - 1
    assert np.max(np.abs(d.gnss.lla[:, 0] - c.gnss.lla[0, 0])) < 1e-3  # no fix 8,500 km away


@pytest.mark.parametrize("style", ["s", "ms", "us", "ns"])
def test_merged_csv_epoch_unit_told_by_magnitude(tmp_path, style):
    ref = load_drive(write_merged_csv(RAW, tmp_path / "iso.csv"))
    d = load_drive(write_merged_csv(RAW, tmp_path / f"{style}.csv", time_style=style))
    np.testing.assert_allclose(d.imu.t, ref.imu.t, atol=1e-6)  # µs were read as ns before


# ------------------------------------------------------------------ reader drops
def test_shuffled_imu_stamps_are_refused_not_run(tmp_path):
    p = write_ulog(_mut("imu-time-shuffled"), tmp_path / "shuf.ulg")
    with pytest.raises(ValueError, match="reader dropped .* of 12001"):
        load_drive(p)


def test_a_few_dropped_samples_are_reported(tmp_path):
    d = load_drive(write_ulog(_mut("acc-nan-10pct"), tmp_path / "nan.ulg"))
    assert any("imu: reader dropped 1200 of 12001" in w for w in d.meta["warnings"])


# ---------------------------------------------------------------- sanity checks
def _drive(gyro=None, acc=None, t=None, baro_alt=None, gnss_h=None):
    imu = SIM.imu
    d = SIM.replace(imu=ImuStream(imu.t if t is None else t,
                                  imu.gyro_b if gyro is None else gyro,
                                  imu.accel_b if acc is None else acc, imu.spec))
    if baro_alt is not None:
        d = d.replace(baro=BaroStream(d.baro.t, None, baro_alt, d.baro.spec))
    if gnss_h is not None:
        g = d.gnss
        lla = g.lla.copy()
        lla[:, 2] = gnss_h
        d = d.replace(gnss=GnssStream(g.t, lla, g.pos_sd, g.vel_n, g.vel_sd, g.lever_arm_b,
                                      g.spec))
    return d


def test_specific_force_in_g_and_g_squared_are_converted():
    for scale, word in ((1 / G0, "g units"), (G0, "g^2")):
        d = check_drive(_drive(acc=SIM.imu.accel_b * scale))
        np.testing.assert_allclose(d.imu.accel_b, SIM.imu.accel_b, rtol=1e-12)
        assert word in d.meta["warnings"][0]
        assert sum(d.meta["repaired"]["imu"].values()) == len(SIM.imu)


def test_specific_force_far_from_g_is_refused():
    with pytest.raises(ValueError, match="not about g"):
        check_drive(_drive(acc=SIM.imu.accel_b * 3.0))


def test_gyro_in_degrees_per_second_is_converted():
    d = check_drive(_drive(gyro=np.degrees(SIM.imu.gyro_b)))
    np.testing.assert_allclose(d.imu.gyro_b, SIM.imu.gyro_b, rtol=1e-12)
    assert "deg/s" in d.meta["warnings"][0]


AIR, _ = sim_raw("sortie", 400.0)


def _units_first(case: Path, ctrl: Path) -> None:
    """``case`` (gyro in deg/s) reads in full, converted, with one warning saying so."""
    d, c = load_drive(case), load_drive(ctrl)
    assert len(d.imu) == len(c.imu)  # no sample screened as "outside physical range"
    assert "imu" not in (d.meta.get("dropped") or {}) or not sum(
        d.meta["dropped"]["imu"].values())
    np.testing.assert_allclose(d.imu.gyro_b, c.imu.gyro_b, rtol=1e-5, atol=1e-5)
    assert sum("deg/s" in w for w in d.meta["warnings"]) == 1
    assert "gyro in deg/s: multiplied by pi/180" in d.meta["repaired"]["imu"]


@pytest.mark.parametrize("fmt", ["dataflash", "ulog", "npz", "sl-folder"])
def test_slow_turning_gyro_in_degrees_is_converted(fmt, tmp_path):
    """The sortie aircraft never turns faster than 8 deg/s for a second, so its deg/s gyro
    passes the block-rate test; the GNSS course (57 times less turn than the gyro's) decides."""
    from .corpus import WRITERS

    deg = SEMANTIC["gyro-deg-s"][0](AIR, np.random.default_rng(0))
    suffix = {"dataflash": ".bin", "ulog": ".ulg", "npz": ".npz", "sl-folder": ""}[fmt]
    if fmt == "npz":
        case, ctrl = write_npz(deg, tmp_path / "deg.npz"), write_npz(AIR, tmp_path / "c.npz")
    else:
        case = WRITERS[fmt](deg, tmp_path / f"deg{suffix}")
        ctrl = WRITERS[fmt](AIR, tmp_path / f"c{suffix}")
    _units_first(case, ctrl)


@pytest.mark.parametrize("log", ["erle_pxf_181_gps_glitch/181.BIN", "erle_pxf_218/218.BIN"])
def test_shared_dataflash_gyro_in_degrees_reads_in_full(log, shared_log, tmp_path):
    """Multirotor logs with the gyro rewritten in deg/s: 31 % of 181.BIN's samples and 4.5 %
    of 218.BIN's turn faster than 50 deg/s; the reader's range screen (|gyro| <= 50) must see
    them in rad/s, after the unit is decided on the raw samples."""
    from .mutations import df_scale_fields

    src = shared_log(log)
    p = tmp_path / "deg.bin"
    p.write_bytes(df_scale_fields(src.read_bytes(), "IMU", ("GyrX", "GyrY", "GyrZ"),
                                  180.0 / np.pi))
    _units_first(p, src)


def test_swapped_accelerometer_axes_are_refused():
    with pytest.raises(ValueError, match="swapped"):
        check_drive(_drive(acc=SIM.imu.accel_b[:, [2, 1, 0]]))
    with pytest.raises(ValueError, match="mirrored"):  # x/y: gravity stays on z
        check_drive(_drive(acc=SIM.imu.accel_b[:, [1, 0, 2]]))


def test_clipping_is_removed_as_a_gap_and_counted():
    acc = SIM.imu.accel_b.copy()
    k = slice(8000, 8400)  # 2 s at 200 Hz
    acc[k, 2] = np.clip(acc[k, 2] + 300.0 * np.sin(np.linspace(0, 20, 400)), -16 * G0, 16 * G0)
    d = check_drive(_drive(acc=acc))
    clip = d.meta["clipping"]["imu"]
    assert clip["accel_samples"] == int(np.sum(np.abs(acc[:, 2]) >= 16 * G0 * 0.998))
    assert clip["accel_limit_m_s2"] == pytest.approx(16 * G0)
    assert clip["episodes"] == 1  # one 2 s event, removed whole: one gap
    gap = np.diff(d.imu.t).max()
    assert 1.9 < gap < 2.2 and len(d.imu) == len(SIM.imu) - clip["samples_removed"]
    assert np.max(np.abs(d.imu.accel_b)) < 16 * G0 * 0.998


def test_accelerometer_that_loses_specific_force_is_reported():
    """A log (no IMU spec) whose accelerometer reads 2.5 m/s² short for a third of the drive
    (vibration rectification): reported with the bias walk; the same log intact is not."""
    imu = SIM.imu
    as_log = SIM.replace(imu=ImuStream(imu.t, imu.gyro_b, imu.accel_b, None))
    ok = check_drive(as_log)
    assert not any("less specific force" in w for w in ok.meta.get("warnings") or [])
    assert ok.meta["sanity"]["specific_force_deficit_mps2"] > -0.5
    acc = imu.accel_b.copy()
    n = acc.shape[0]
    acc[n // 3: 2 * n // 3, 2] += 2.5  # f_z is ≈ −g: 2.5 m/s² less specific force
    bad = check_drive(as_log.replace(imu=ImuStream(imu.t, imu.gyro_b, acc, None)))
    w = [x for x in bad.meta["warnings"] if "less specific force" in x]
    assert len(w) == 1 and "random walk" in w[0]
    assert bad.meta["sanity"]["specific_force_deficit_mps2"] == pytest.approx(-2.5, abs=0.3)
    # a simulated IMU keeps its spec: nothing inferred, nothing reported
    assert "specific_force_deficit_mps2" not in check_drive(
        SIM.replace(imu=ImuStream(imu.t, imu.gyro_b, acc, imu.spec))).meta["sanity"]


def test_baro_in_feet_step_and_constant():
    alt = SIM.baro.altitude
    d = check_drive(_drive(baro_alt=alt / 0.3048))
    assert "feet" in d.meta["warnings"][0]
    # feet → metres, datum re-aligned to GNSS: within the baro's own error model (< 10 m)
    assert np.max(np.abs(d.baro.altitude - alt)) < 10.0
    step = alt.copy()
    step[1500:] += 100.0
    d = check_drive(_drive(baro_alt=step))
    assert np.ptp(d.baro.altitude[1500:] - alt[1500:]) < 1e-9  # one constant offset left
    assert abs(d.baro.altitude[1500] - d.baro.altitude[1499]) < 5.0
    d = check_drive(_drive(baro_alt=np.full(alt.size, 500.0)))
    assert d.baro is None and "stuck" in d.meta["warnings"][0]


def test_gnss_height_zero_everywhere_is_not_used():
    d = check_drive(_drive(gnss_h=np.zeros(len(SIM.gnss))))
    assert np.all(d.gnss.pos_sd[:, 2] >= 1e4)
    assert any("not logged" in w for w in d.meta["warnings"])


def test_time_stamps_in_milliseconds_are_refused():
    with pytest.raises(ValueError, match="milliseconds"):
        check_drive(_drive(t=SIM.imu.t * 1e3))


def test_nan_truth_is_dropped_with_a_warning():
    tr = SIM.truth
    q = tr.q_nb.copy()
    q[:] = np.nan
    d = check_drive(SIM.replace(truth=tr.__class__(tr.t, tr.lla, tr.vel_n, q)))
    assert d.truth is None and d.meta["source"] == "log"


def test_gnss_held_10_km_jump_is_dropped_as_one_glitch(tmp_path):
    """A phone folder whose GNSS sits 10 km north for 5 s: the 50 fixes are dropped and named
    (a rule that takes one fix at a time sees only "2 position steps faster than 150 m/s")."""
    from .writers import write_sl_folder

    d = load_drive(write_sl_folder(_mut("gnss-jump-10km-5s"), tmp_path / "jump"))
    c = load_drive(write_sl_folder(RAW, tmp_path / "clean"))
    w = [x for x in d.meta["warnings"] if x.startswith("gnss: 50 fix(es) in 1 glitch")]
    assert len(w) == 1 and "away for 5.1 s" in w[0], d.meta["warnings"]  # 50 fixes at 10 Hz
    assert len(d.gnss) == len(c.gnss) - 50
    assert d.meta["repaired"]["gnss"] == {"position glitch (away and back) dropped": 50}


def test_shared_ski_folder_gnss_held_10_km_jump_is_dropped(data_dir, tmp_path):
    """The real phone folder (1 Hz fixes) with every fix of 100-105 s moved 10 km north."""
    import shutil

    src = data_dir / "ski_iphone_100hz"
    if not src.is_dir():
        pytest.skip("ski_iphone_100hz not present")
    dst = tmp_path / "ski"
    shutil.copytree(src, dst)
    f = dst / "Location.csv"
    lines = f.read_text().splitlines()
    cols = lines[0].split(",")
    it, ilat = cols.index("seconds_elapsed"), cols.index("latitude")
    n = 0
    for k in range(1, len(lines)):
        p = lines[k].split(",")
        if 100.0 <= float(p[it]) < 105.0:
            p[ilat] = repr(float(p[ilat]) + 1.0e4 / 111_320.0)
            lines[k] = ",".join(p)
            n += 1
    f.write_text("\n".join(lines) + "\n")
    d, c = load_drive(dst), load_drive(src)
    w = [x for x in d.meta["warnings"] if x.startswith(f"gnss: {n} fix(es) in 1 glitch")]
    assert n >= 4 and len(w) == 1, (n, d.meta["warnings"])
    assert len(d.gnss) == len(c.gnss) - n
