"""Drive save/load is lossless; corrupt files give a clean ValueError."""

import json

import numpy as np
import pytest

from vnav_graph.io import load_drive, save_npz
from vnav_graph.simulation import simulate
from vnav_graph.types.streams import MagStream


def test_npz_round_trip_is_lossless(tmp_path):
    d = simulate("sortie", 4, duration_s=30.0)
    p = save_npz(d, tmp_path / "d.npz")
    e = load_drive(p)
    for a, b in [(d.imu.t, e.imu.t), (d.imu.gyro_b, e.imu.gyro_b), (d.gnss.lla, e.gnss.lla),
                 (d.gnss.vel_n, e.gnss.vel_n), (d.baro.alt, e.baro.alt),
                 (d.truth.q_nb, e.truth.q_nb), (d.truth.bias_baro, e.truth.bias_baro)]:
        np.testing.assert_array_equal(a, b)
    assert e.imu.spec == d.imu.spec and e.gnss.spec == d.gnss.spec
    assert e.baro.spec == d.baro.spec and e.baro_truth == d.baro_truth
    # load_drive adds only the sanity checks' statistics; a clean drive gets no warning
    assert {k: v for k, v in e.meta.items() if k != "sanity"} == dict(d.meta)
    assert "warnings" not in e.meta and "imu_rotation_stats" in e.meta["sanity"]
    assert (e.mag is None) == (d.mag is None)
    if d.mag is not None:
        np.testing.assert_array_equal(e.mag.field_b, d.mag.field_b)


def _with_mag(d, sd_ut=0.7):
    """``d`` with a 10 Hz magnetometer [µT, body FRD] turning at 5°/s."""
    t = d.imu.t[::10]
    psi = np.radians(5.0 * t)
    field = np.column_stack([21.5 * np.cos(psi), -21.5 * np.sin(psi), np.full(t.size, 42.5)])
    return d.replace(mag=MagStream(t, field, sd_ut))


def test_npz_round_trip_with_magnetometer(tmp_path):
    d = _with_mag(simulate("sortie", 4, duration_s=30.0))
    p = save_npz(d, tmp_path / "m.npz")
    with np.load(p) as z:  # the file's own layout: float64 arrays, sd in the JSON header
        assert z["mag_t"].dtype == np.float64 and z["mag_field_b"].shape == (len(d.mag), 3)
        assert json.loads(z["header"].tobytes().decode())["mag_sd_ut"] == 0.7
    e = load_drive(p)
    np.testing.assert_array_equal(e.mag.t, d.mag.t)
    np.testing.assert_array_equal(e.mag.field_b, d.mag.field_b)
    assert e.mag.sd_ut == 0.7
    assert not [w for w in e.meta.get("warnings", []) if w.startswith("mag")]


def test_npz_refuses_a_stream_it_does_not_store(tmp_path, monkeypatch):
    # a Drive stream the file format does not keep (here the magnetometer, as if the format
    # predated it) is an error naming the stream, not a file that reads back without it
    from vnav_graph.io import drive_io

    d = _with_mag(simulate("sortie", 4, duration_s=30.0))
    monkeypatch.setattr(drive_io, "STORED_STREAMS", ("gnss", "baro"))
    with pytest.raises(ValueError, match=r"drive\.mag: a drive file \(\.npz\) does not store"):
        save_npz(d, tmp_path / "m.npz")
    assert not (tmp_path / "m.npz").exists()
    save_npz(d.replace(mag=None), tmp_path / "m.npz")  # without it the file is written


def test_npz_magnetometer_damage_is_a_clean_error(tmp_path):
    d = _with_mag(simulate("hill-drive", 1, duration_s=10.0))
    p = save_npz(d, tmp_path / "m.npz")
    with np.load(p) as z:
        arrays = {k: z[k] for k in z.files}
    header = json.loads(arrays.pop("header").tobytes().decode())

    def write(name, arr, hdr):
        out = dict(arr, header=np.frombuffer(json.dumps(hdr).encode(), dtype=np.uint8))
        np.savez_compressed(tmp_path / name, **out)
        return tmp_path / name

    no_field = {k: v for k, v in arrays.items() if k != "mag_field_b"}
    with pytest.raises(ValueError, match="missing array 'mag_field_b'"):
        load_drive(write("a.npz", no_field, header))
    ms = dict(arrays, mag_t=np.round(arrays["mag_t"] * 1e3).astype(np.int64))
    with pytest.raises(ValueError, match="mag_t.*integer"):
        load_drive(write("b.npz", ms, header))
    with pytest.raises(ValueError, match="mag_sd_ut"):
        load_drive(write("c.npz", arrays, dict(header, mag_sd_ut="1 uT")))
    nt = dict(arrays, mag_field_b=arrays["mag_field_b"] * 1e3)  # nT stored as µT
    with pytest.raises(ValueError, match="mag.field_b"):
        load_drive(write("d.npz", nt, header))
    old = {k: v for k, v in arrays.items() if not k.startswith("mag_")}  # before the magnetometer
    e = load_drive(write("f.npz", old, {k: v for k, v in header.items() if k != "mag_sd_ut"}))
    assert e.mag is None
    np.testing.assert_array_equal(e.imu.t, d.imu.t)
    no_sd = {k: v for k, v in header.items() if k != "mag_sd_ut"}
    assert load_drive(write("e.npz", arrays, no_sd)).mag.sd_ut == 1.0  # MagStream default


def test_corrupt_and_truncated_files(tmp_path):
    d = simulate("hill-drive", 1, duration_s=10.0)
    p = save_npz(d, tmp_path / "d.npz")
    cut = tmp_path / "cut.npz"
    cut.write_bytes(p.read_bytes()[: p.stat().st_size // 2])
    with pytest.raises(ValueError, match="cut.npz"):
        load_drive(cut)
    with pytest.raises(ValueError, match="no such file"):
        load_drive(tmp_path / "missing.npz")


def test_sanity_reports_a_magnetometer_cut_short(tmp_path):
    d = _with_mag(simulate("hill-drive", 1, duration_s=60.0))
    m = d.mag
    half = m.select(m.t < m.t[0] + 20.0)
    e = load_drive(save_npz(d.replace(mag=half), tmp_path / "h.npz"))
    assert len(e.mag) == len(half)  # reported, not changed
    assert any(w.startswith("mag: covers 0..20 s") for w in e.meta["warnings"])
