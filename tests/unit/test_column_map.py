"""Column-mapped plain files: the committed walk map on the cut of rtk/walk_0827 in
tests/data/rtk_walk_cut (BSD-3, LICENSE beside it), map errors, the mounting convention, the
RTKLIB time-tag file, and the file's GNSS σ carried through to the estimators' model."""

from __future__ import annotations

import shutil
import struct
from pathlib import Path

import numpy as np
import pytest

from vnav_graph.io import load_drive
from vnav_graph.io.readers import detect_format
from vnav_graph.io.readers.column_map import find_map, load_map, mounting_matrix, read_mapped
from vnav_graph.io.readers.timetag import read_tag
from vnav_graph.sensors.gnss_model import GNSS_SD_FLOOR
from vnav_graph.sensors.model import sensor_model

REPO = Path(__file__).resolve().parents[2]
CUT = REPO / "tests" / "data" / "rtk_walk_cut"
WALK_MAP = REPO / "examples" / "maps" / "walk_0827.toml"
CAR_MAP = REPO / "examples" / "maps" / "car_drive_0708.toml"


def test_walk_cut_with_the_committed_map() -> None:
    d = read_mapped(CUT, WALK_MAP)
    assert d.meta["format"] == "column-map" and d.height_reference == "ellipsoid"
    # the cut's first line has 6 of 7 fields (cut by the logger): dropped, counted
    assert d.meta["dropped"]["imu"] == {"incomplete or unreadable row": 1}
    assert len(d.imu) == 1199
    assert 160 < d.imu.rate_hz < 175
    # at rest, body axes forward-right-down: specific force ≈ (0, 0, −g)
    f = d.imu.accel_b[:200].mean(axis=0)
    assert f[2] == pytest.approx(-9.8, abs=0.3) and np.hypot(f[0], f[1]) < 0.5
    assert np.max(np.abs(d.imu.gyro_b)) < 1.0  # deg/s converted to rad/s
    tag = read_tag(CUT / "imu_1730.csv.tag")
    raw = (CUT / "imu_1730.csv.tag").read_bytes()
    sec, frac = struct.unpack_from("<Id", raw, 64)
    assert tag.start_gpst == pytest.approx(sec + frac - 315964800.0)
    assert d.meta["t0_gpst_s"] == np.floor(tag.start_gpst)
    assert d.imu.t[0] == pytest.approx(tag.start_gpst - d.meta["t0_gpst_s"], abs=1e-6)
    # single-point GNSS with the file's σ (metres), on the drive clock
    assert d.gnss is not None and np.median(d.gnss.pos_sd[:, 0]) > 2.0
    assert d.gnss.t[0] >= d.imu.t[0]


def test_rtk_input_keeps_its_centimetre_sigma_end_to_end(tmp_path: Path) -> None:
    folder = tmp_path / "walk"
    shutil.copytree(CUT, folder)
    text = WALK_MAP.read_text().replace('file = "gnss_1730_spp.pos"',
                                        'file = "gnss_1730_sf.pos"\nheight_datum = "msl"')
    (folder / "walk.toml").write_text(text)
    assert find_map(folder) == folder / "walk.toml"
    assert detect_format(folder) == "column-map"
    drive = load_drive(folder)  # found inside the folder; the input checks run too
    assert drive.height_reference == "msl"
    assert np.median(drive.gnss.pos_sd, axis=0) == pytest.approx([0.0099, 0.0099, 0.0105],
                                                                 abs=0.001)
    model = sensor_model(drive)
    assert np.max(model.gnss_pos_sd) < 0.03  # cm, not the 1 m of a floor
    assert np.min(model.gnss_pos_sd) == pytest.approx(GNSS_SD_FLOOR)
    (folder / "second.toml").write_text(text)
    with pytest.raises(ValueError, match="several column maps"):
        find_map(folder)


def test_map_errors(tmp_path: Path) -> None:
    base = CAR_MAP.read_text()
    cases = {
        "unknown key": "surprise = 1\n" + base,
        "in \\[lever_arms\\]": base + "\nsurprise = 1\n",
        "accel_unit": base.replace('accel_unit = "g"', 'accel_unit = "furlong"'),
        "imu.time.base": base.replace('base = "tag-counter-ms"', 'base = "sundial"'),
        "must list 3": base.replace("gyro = [3, 4, 5]", "gyro = [3, 4]"),
        "not a TOML": "[imu\nfile=",
    }
    for what, text in cases.items():
        p = tmp_path / "m.toml"
        p.write_text(text)
        with pytest.raises(ValueError, match=what):
            load_map(p)
    with pytest.raises(ValueError, match="no such column map"):
        load_map(tmp_path / "absent.toml")


def test_mounting_convention() -> None:
    # (180, 0, 180): x and z flip, y stays
    assert mounting_matrix([180, 0, 180]) == pytest.approx(np.diag([-1.0, 1.0, -1.0]))
    # yaw 90: C = Rz(90)ᵀ takes the sensor's x axis to the body's −y
    assert mounting_matrix([0, 0, 90]) @ np.array([1.0, 0, 0]) == pytest.approx([0, -1, 0])
