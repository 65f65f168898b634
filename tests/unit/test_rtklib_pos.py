"""RTKLIB .pos reader: the real-format cuts in tests/data (rtk_car_cut, rtk_walk_cut; BSD-3,
LICENSE beside them) and synthetic variants of the same lines (week + time of week, UTC,
ECEF) against values computed independently of the reader."""

from __future__ import annotations

from datetime import datetime
from pathlib import Path

import numpy as np
import pymap3d
import pytest

from vnav_graph.io.readers.gpstime import gps_to_unix, unix_to_gps
from vnav_graph.io.readers.rtklib_pos import QUALITY, gnss_stream, is_pos, read_pos

DATA = Path(__file__).resolve().parent.parent / "data"
CAR = DATA / "rtk_car_cut" / "gnss_1934_sf.pos"
SPP = DATA / "rtk_walk_cut" / "gnss_1730_spp.pos"
RTK_WALK = DATA / "rtk_walk_cut" / "gnss_1730_sf.pos"

# 2025-07-08 19:34:18.499 GPST, counted by hand from the GPS epoch 1980-01-06
CAR_T0 = (datetime(2025, 7, 8, 19, 34, 18) - datetime(1980, 1, 6)).total_seconds() + 0.499


def _lines(p: Path) -> tuple[list[str], list[str]]:
    text = p.read_text().splitlines()
    return [ln for ln in text if ln.startswith("%")], [ln for ln in text if ln[:1] != "%"]


def test_car_cut_silent_header_keeps_cm_sigma() -> None:
    sol = read_pos(CAR)
    assert sol.height_datum is None and sol.datum_source is None
    with pytest.raises(ValueError, match="does not state the height datum"):
        gnss_stream(sol, CAR_T0, "msl")
    sol = read_pos(CAR, "msl")
    assert (sol.height_datum, sol.datum_source, sol.form) == ("msl", "stated", "llh")
    assert len(sol) == 40 and sol.time_system == "GPST"
    assert sol.t_gpst[0] == pytest.approx(CAR_T0, abs=1e-6)
    assert np.allclose(np.diff(sol.t_gpst), 0.25, atol=1e-6)
    assert np.degrees(sol.lla[0, 0]) == pytest.approx(40.0966268, abs=1e-9)
    assert sol.lla[0, 2] == pytest.approx(1601.474)
    # σ as in the file: 0.0098995 m, not floored
    assert sol.sd_ned[0] == pytest.approx([0.0098995, 0.0098995, 0.01])
    # vu = +0.009 m/s → v_down = −0.009
    assert sol.vel_ned[0] == pytest.approx([0.01, -0.002, -0.009])
    assert sol.quality_counts() == {"fix": 40}
    g, notes = gnss_stream(sol, CAR_T0, "msl")
    assert g.t[0] == pytest.approx(0.0, abs=1e-6)
    assert np.max(g.pos_sd) < 0.011
    assert "0.010/0.010/0.010 m" in notes[0]


def test_spp_header_datum_and_contradiction() -> None:
    sol = read_pos(SPP)
    assert (sol.height_datum, sol.datum_source) == ("ellipsoid", "header")
    assert sol.quality_counts() == {"single": 32}
    assert sol.sd_ned[0] == pytest.approx([2.9988, 2.5403, 6.0170])
    with pytest.raises(ValueError, match="ellipsoid"):
        read_pos(SPP, "msl")


def test_sd_scale_applies_per_quality_and_datum_conversion() -> None:
    sol = read_pos(RTK_WALK, "msl")
    counts = sol.quality_counts()
    assert set(counts) <= set(QUALITY.values())
    q = sol.q.copy()
    g, notes = gnss_stream(sol, sol.t_gpst[0], "ellipsoid", geoid_sep_m=-21.387,
                           sd_scale={"float": 2.0})
    ratio = g.pos_sd[:, 0] / sol.sd_ned[:, 0]
    assert np.allclose(ratio[q == 2], 2.0) and np.allclose(ratio[q == 1], 1.0)
    assert g.lla[:, 2] == pytest.approx(sol.lla[:, 2] - 21.387)
    assert any("geoid separation" in n for n in notes)
    with pytest.raises(ValueError, match="geoid separation"):
        gnss_stream(sol, sol.t_gpst[0], "ellipsoid")
    with pytest.raises(ValueError, match="unknown quality"):
        gnss_stream(sol, sol.t_gpst[0], "msl", sd_scale={"flaot": 2.0})
    fixed, _ = gnss_stream(sol, sol.t_gpst[0], "msl", min_quality=1)
    assert len(fixed) == int(np.sum(q == 1))


def test_week_tow_and_utc_forms_give_the_same_gpst(tmp_path: Path) -> None:
    head, rows = _lines(SPP)
    ref = read_pos(SPP)
    week_rows, utc_rows = [], []
    for ln in rows:
        d, c, *rest = ln.split()
        cal = datetime.strptime(f"{d} {c}", "%Y/%m/%d %H:%M:%S.%f")
        gps = (cal - datetime(1980, 1, 6)).total_seconds()
        week, tow = divmod(gps, 604800.0)
        week_rows.append(f"{int(week)} {tow:.3f} " + " ".join(rest))
        utc = datetime.utcfromtimestamp(float(gps_to_unix(gps)))
        utc_rows.append(utc.strftime("%Y/%m/%d %H:%M:%S.%f")[:-3] + " " + " ".join(rest))
    (tmp_path / "w.pos").write_text("\n".join(head + week_rows) + "\n")
    utc_head = [h.replace("%  GPST", "%  UTC ") for h in head]
    (tmp_path / "u.pos").write_text("\n".join(utc_head + utc_rows) + "\n")
    w, u = read_pos(tmp_path / "w.pos"), read_pos(tmp_path / "u.pos")
    assert u.time_system == "UTC"
    assert np.allclose(w.t_gpst, ref.t_gpst, atol=1e-6)
    assert np.allclose(u.t_gpst, ref.t_gpst, atol=1e-6)
    # 2025: GPST − UTC = 18 s
    assert float(unix_to_gps(gps_to_unix(ref.t_gpst[0]))) == pytest.approx(ref.t_gpst[0])


def test_ecef_form_round_trip_and_covariance_rotation(tmp_path: Path) -> None:
    lat, lon, h = 40.0966, -105.1471, 1578.6
    x, y, z = pymap3d.geodetic2ecef(lat, lon, h)
    # a known NED covariance (σ 0.3, 0.4, 0.9 m, no correlation) written in ECEF
    sl, cl = np.sin(np.radians(lat)), np.cos(np.radians(lat))
    so, co = np.sin(np.radians(lon)), np.cos(np.radians(lon))
    r_ne = np.array([[-sl * co, -sl * so, cl], [-so, co, 0.0], [-cl * co, -cl * so, -sl]])
    c_e = r_ne.T @ np.diag([0.3, 0.4, 0.9]) ** 2 @ r_ne

    def ss(v: float) -> float:
        return float(np.sign(v) * np.sqrt(abs(v)))

    sd = [np.sqrt(c_e[0, 0]), np.sqrt(c_e[1, 1]), np.sqrt(c_e[2, 2]), ss(c_e[0, 1]),
          ss(c_e[1, 2]), ss(c_e[2, 0])]
    v_ecef = r_ne.T @ np.array([1.0, 2.0, -0.5])  # NED velocity (1, 2, −0.5) m/s
    vals = [x, y, z, 5, 9, *sd, 0.0, 0.0, *v_ecef, 0.1, 0.1, 0.1, 0, 0, 0]
    text = ("%  GPST                  x-ecef(m)      y-ecef(m)      z-ecef(m)   Q  ns   sdx(m)"
            "   sdy(m)   sdz(m)  sdxy(m)  sdyz(m)  sdzx(m) age(s)  ratio    vx(m/s)    vy(m/s)"
            "    vz(m/s)      sdvx     sdvy     sdvz    sdvxy    sdvyz    sdvzx\n"
            "2025/08/28 17:30:39.750 " + " ".join(f"{v:.6f}" for v in vals) + "\n")
    (tmp_path / "x.pos").write_text(text)
    sol = read_pos(tmp_path / "x.pos")
    assert (sol.form, sol.height_datum) == ("xyz", "ellipsoid")
    assert np.degrees(sol.lla[0, :2]) == pytest.approx([lat, lon], abs=1e-9)
    assert sol.lla[0, 2] == pytest.approx(h, abs=1e-3)
    assert sol.sd_ned[0] == pytest.approx([0.3, 0.4, 0.9], abs=1e-5)
    assert sol.vel_ned[0] == pytest.approx([1.0, 2.0, -0.5], abs=1e-6)


def test_bad_input(tmp_path: Path) -> None:
    head, rows = _lines(SPP)
    cut = tmp_path / "cut.pos"
    cut.write_text("\n".join(head + rows[:-1] + [rows[-1][:40]]) + "\n")
    sol = read_pos(cut)
    assert len(sol) == len(rows) - 1
    assert sol.report.dropped["gnss"]["malformed solution line"] == 1
    (tmp_path / "none.pos").write_text("\n".join(head) + "\n")
    with pytest.raises(ValueError, match="no readable solution line"):
        read_pos(tmp_path / "none.pos")
    (tmp_path / "txt.pos").write_text("hello\n1 2 3\n")
    with pytest.raises(ValueError, match="not an RTKLIB solution"):
        read_pos(tmp_path / "txt.pos")
    zero = rows[0].split()
    zero[7:10] = ["0.0000"] * 3
    (tmp_path / "z.pos").write_text("\n".join(head + [" ".join(zero)] + rows[1:]) + "\n")
    z = read_pos(tmp_path / "z.pos")
    assert z.report.dropped["gnss"]["position sigma zero (no solution)"] == 1
    assert is_pos(SPP.read_bytes()[:4096]) and not is_pos(b"\xa3\x95\x80\x80")
    with pytest.raises(ValueError, match="msl or ellipsoid"):
        read_pos(SPP, "geoid")
