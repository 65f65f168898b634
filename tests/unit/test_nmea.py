"""NMEA 0183 reader: sentences written with pynmea2 (valid checksums) from known values,
read back; bad checksums, missing dates and files without fixes."""

from __future__ import annotations

from datetime import datetime
from pathlib import Path

import numpy as np
import pynmea2
import pytest

from vnav_graph.io.readers.nmea import UERE_M, VEL_SD_H, is_nmea, read_nmea

LAT, LON = 40.0966916, -105.1471665  # deg
ALT, SEP = 1601.435, -21.387  # m above the geoid, geoid separation N


def _dm(v: float, pos: str, neg: str, width: int) -> tuple[str, str]:
    a = abs(v)
    d = int(a)
    return f"{d:0{width}d}{(a - d) * 60:07.4f}", pos if v >= 0 else neg


def sentences(n: int = 8, qual: int = 4, gst: bool = True, rmc: bool = True,
              sep: str = f"{SEP}") -> list[str]:
    out = []
    for k in range(n):
        t = f"1730{39 + k:02d}.00"
        lat, ns = _dm(LAT + k * 1e-5, "N", "S", 2)
        lon, ew = _dm(LON, "E", "W", 3)
        out.append(str(pynmea2.GGA("GN", "GGA", (t, lat, ns, lon, ew, str(qual), "21", "0.8",
                                                 f"{ALT + k:.3f}", "M", sep, "M", "", ""))))
        if rmc:
            out.append(str(pynmea2.RMC("GN", "RMC", (t, "A", lat, ns, lon, ew, "1.944",
                                                     "90.0", "280825", "", "", "D"))))
        if gst:
            out.append(str(pynmea2.GST("GN", "GST", (t, "0.01", "0.01", "0.01", "0", "0.011",
                                                     "0.012", "0.020"))))
    return out


def _gps(h: int, m: int, s: float) -> float:
    utc = datetime(2025, 8, 28, h, m, int(s))
    return (utc - datetime(1980, 1, 6)).total_seconds() + (s - int(s)) + 18.0


def test_gga_rmc_gst_read_back(tmp_path: Path) -> None:
    f = tmp_path / "a.nmea"
    f.write_text("\n".join(sentences()) + "\n")
    assert is_nmea(f.read_bytes())
    sol = read_nmea(f)
    assert len(sol) == 8 and sol.time_system == "UTC" and sol.height_datum == "ellipsoid"
    assert sol.t_gpst[0] == pytest.approx(_gps(17, 30, 39.0))  # UTC + 18 s
    assert np.allclose(np.diff(sol.t_gpst), 1.0)
    assert np.degrees(sol.lla[0, :2]) == pytest.approx([LAT, LON], abs=1e-6)
    assert sol.lla[:, 2] == pytest.approx(ALT + SEP + np.arange(8))
    assert sol.quality_counts() == {"fix": 8}
    assert sol.sd_ned[0] == pytest.approx([0.011, 0.012, 0.020])
    # 1.944 kn due east
    assert sol.vel_ned[0, :2] == pytest.approx([0.0, 1.944 * 1852 / 3600], abs=1e-9)
    assert sol.vel_sd[0] == pytest.approx([VEL_SD_H, VEL_SD_H, 1e4])


def test_without_gst_sigma_from_hdop_and_msl_without_separation(tmp_path: Path) -> None:
    f = tmp_path / "b.nmea"
    f.write_text("\n".join(sentences(qual=1, gst=False, sep="")) + "\n")
    sol = read_nmea(f)
    assert sol.height_datum == "msl" and sol.quality_counts() == {"single": 8}
    assert sol.sd_ned[0] == pytest.approx([0.8 * UERE_M[5]] * 2 + [1.2 * UERE_M[5]])
    assert any("without GST" in n for n in sol.report.notes)


def test_bad_checksums_dropped_and_bad_files_refused(tmp_path: Path) -> None:
    lines = sentences()
    lines[0] = lines[0][:-2] + ("00" if lines[0][-2:] != "00" else "11")  # wrong checksum
    lines[4] = lines[4].split("*")[0]  # the second epoch's RMC without a checksum
    f = tmp_path / "c.nmea"
    f.write_text("\n".join(lines) + "\n")
    sol = read_nmea(f)
    assert len(sol) == 7  # the first GGA is gone
    assert np.sum(sol.vel_sd[:, 0] > 1e3) == 1  # the second epoch has no velocity
    assert sum(sol.report.dropped["gnss"].values()) == 2
    (tmp_path / "d.nmea").write_text("\n".join(sentences(rmc=False)) + "\n")
    with pytest.raises(ValueError, match="no RMC sentence with a date"):
        read_nmea(tmp_path / "d.nmea")
    (tmp_path / "e.nmea").write_text("hello\n$GPGGA,garbage*00\n")
    with pytest.raises(ValueError, match="no readable GGA"):
        read_nmea(tmp_path / "e.nmea")
    (tmp_path / "f.nmea").write_text("\n".join(sentences(qual=0)) + "\n")
    with pytest.raises(ValueError, match="no GGA sentence with a position fix"):
        read_nmea(tmp_path / "f.nmea")
