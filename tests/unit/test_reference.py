"""A reference file put on a drive's clock, datum and IMU point (``io.reference``): the walk
cut's RTK solution against the cut drive, and a synthetic straight run for the lever arm."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from vnav_graph.geo.frames import lla_to_ned
from vnav_graph.io.readers.column_map import read_mapped
from vnav_graph.io.readers.rtklib_pos import read_pos
from vnav_graph.io.reference import attach_reference, load_reference
from vnav_graph.types import Drive
from vnav_graph.types.streams import ImuStream

REPO = Path(__file__).resolve().parents[2]
CUT = REPO / "tests" / "data" / "rtk_walk_cut"
WALK_MAP = REPO / "examples" / "maps" / "walk_0827.toml"
HEAD = ("%  GPST            latitude(deg) longitude(deg) height(m) Q  ns  sdn(m) sde(m) sdu(m) "
        "sdne(m) sdeu(m) sdun(m) age(s) ratio vn(m/s) ve(m/s) vu(m/s) sdvn sdve sdvu sdvne "
        "sdveu sdvun")


def test_walk_reference_time_and_datum() -> None:
    drive = read_mapped(CUT, WALK_MAP)
    d = attach_reference(drive, CUT / "gnss_1730_sf.pos", CUT, WALK_MAP)
    sol = read_pos(CUT / "gnss_1730_sf.pos", "msl")
    info = d.meta["reference"]
    tr = d.truth
    k = np.searchsorted(sol.t_gpst - drive.meta["t0_gpst_s"], tr.t[0])
    assert tr.t[0] == pytest.approx(sol.t_gpst[k] - drive.meta["t0_gpst_s"])
    # RTK heights above MSL, the drive's (single-point input) above the ellipsoid
    assert tr.alt[0] == pytest.approx(sol.lla[k, 2] - 21.387)
    assert "N = -21.387 m" in info["height"] and info["file"] == "gnss_1730_sf.pos"
    assert info["lever_arm_m"] is None
    with pytest.raises(ValueError, match="geoid separation"):
        load_reference(CUT / "gnss_1730_sf.pos", drive, "msl")
    with pytest.raises(ValueError, match="does not state the height datum"):
        load_reference(CUT / "gnss_1730_sf.pos", drive)


def _straight_north(tmp_path: Path) -> tuple[Path, Drive]:
    """5 m/s due north for 10 s at 4 Hz, from GPST 2025/08/28 17:30:40.000; every fourth
    epoch float (Q = 2)."""
    lat0, lon0, h0 = np.radians(40.0967), np.radians(-105.1472), 1600.0
    rows = []
    for k in range(41):
        lat = lat0 + 5.0 * 0.25 * k / 6_370_000.0
        rows.append(f"2025/08/28 17:30:{40 + 0.25 * k:06.3f} {np.degrees(lat):.9f} "
                    f"{np.degrees(lon0):.9f} {h0:.4f} {2 if k % 4 == 0 else 1} 20 "
                    "0.01 0.01 0.01 0 0 0 0 0 5.0 0.0 0.0 0.05 0.05 0.05 0 0 0")
    f = tmp_path / "north.pos"
    f.write_text(HEAD + "\n" + "\n".join(rows) + "\n")
    t = np.arange(0.0, 10.0, 0.01)
    imu = ImuStream(t, np.zeros((t.size, 3)), np.tile([0.0, 0.0, -9.8], (t.size, 1)))
    sol = read_pos(f, "ellipsoid")
    drive = Drive(imu, None, None, sol.lla[0],
                  meta={"t0_gpst_s": float(sol.t_gpst[0]), "height_reference": "ellipsoid"})
    return f, drive


def test_lever_arm_moves_the_reference_to_the_imu(tmp_path: Path) -> None:
    f, drive = _straight_north(tmp_path)
    plain, _ = load_reference(f, drive, "ellipsoid")
    # reference point 1 m right of and 0.5 m above the IMU; heading north: right = east
    moved, info = load_reference(f, drive, "ellipsoid", lever_arm_b=[0.0, 1.0, -0.5])
    d = lla_to_ned(moved.lla, drive.origin_lla) - lla_to_ned(plain.lla, drive.origin_lla)
    assert d[:, 0] == pytest.approx(0.0, abs=1e-6)
    assert d[:, 1] == pytest.approx(-1.0, abs=1e-6)
    assert d[:, 2] == pytest.approx(0.5, abs=1e-6)
    assert info["lever_arm_m"] == [0.0, 1.0, -0.5]
    assert plain.t[0] == pytest.approx(0.0) and plain.vel_n[0] == pytest.approx([5, 0, 0])
    fixed, info = load_reference(f, drive, "ellipsoid", fix_only=True)
    assert len(plain) == 41 and len(fixed) == 30 and info["quality"] == {"fix": 30}


def test_reference_outside_the_drive_or_without_time(tmp_path: Path) -> None:
    f, drive = _straight_north(tmp_path)
    late = drive.replace(meta={**drive.meta, "t0_gpst_s": drive.meta["t0_gpst_s"] + 86400})
    with pytest.raises(ValueError, match="does not overlap the drive"):
        load_reference(f, late, "ellipsoid")
    with pytest.raises(ValueError, match="no absolute time"):
        load_reference(f, drive.replace(meta={}), "ellipsoid")
    (tmp_path / "x.txt").write_text("a,b,c\n1,2,3\n")
    with pytest.raises(ValueError, match="not a reference trajectory"):
        load_reference(tmp_path / "x.txt", drive)


def test_reference_that_is_the_gnss_input_is_flagged() -> None:
    drive = read_mapped(CUT, WALK_MAP)
    own = attach_reference(drive, CUT / "gnss_1730_spp.pos", CUT, WALK_MAP)
    assert own.meta["reference"]["is_gnss_input"] is True
    assert any("is the drive's GNSS input" in w for w in own.meta["warnings"])
    assert "both above ellipsoid" in own.meta["reference"]["height"]
    other = attach_reference(drive, CUT / "gnss_1730_sf.pos", CUT, WALK_MAP)
    assert other.meta["reference"]["is_gnss_input"] is False
    assert not other.meta.get("warnings")
