"""GNSS height unit check (``io.height_units``): feet are converted, another scale is refused,
and nothing fires on clean data (simulated, every corpus format, the shared logs)."""

from __future__ import annotations

import numpy as np
import pytest

from tests.fuzz.corpus import SEMANTIC, SUFFIX, WRITERS, sim_raw, write_dataflash
from vnav_graph.io import load_drive
from vnav_graph.io.findings import Findings
from vnav_graph.io.height_units import Climb, check_gnss_height_units, verdict
from vnav_graph.simulation import list_scenarios, simulate

RAW, SIM = sim_raw()
UNIT_WORDS = ("gnss: height climbs",)


def _unit_warnings(d) -> list[str]:
    return [w for w in d.meta.get("warnings") or [] if w.startswith(UNIT_WORDS)]


def _c(ratio: float, sd: float = 0.05) -> Climb:
    return Climb(ratio, sd * ratio, 20, 20, 50.0)


@pytest.mark.parametrize(("found", "kind"), [
    ({"the baro": _c(1.05)}, "metres"),
    ({"the baro": _c(3.28), "its vertical velocity": _c(3.30)}, "feet"),
    ({"the baro": _c(3.28)}, "feet"),
    ({"the baro": _c(0.305)}, "twice"),
    ({"the baro": _c(2.0)}, "other"),
    ({"the baro": _c(1.5)}, "near"),
    # heights and velocity wrong together, the baro right (the Erle 181 glitch): not units
    ({"the baro": _c(5.97), "its vertical velocity": _c(0.84)}, "metres"),
    ({"the baro": _c(3.28), "its vertical velocity": _c(1.0)}, "both-feet"),
    ({"the baro": _c(3.28), "its vertical velocity": _c(2.0)}, "disagree"),
    ({"the baro": _c(3.28, sd=0.2)}, "none"),  # not determined
    ({"the baro": Climb(3.28, 0.1, 15, 25, 50.0)}, "none"),  # 40 % of windows trimmed
])
def test_verdict(found, kind):
    assert verdict(found)[0] == kind


def test_dataflash_gnss_altitude_in_feet_is_converted(tmp_path):
    """The corpus's "GNSS altitude in feet" DataFlash log: heights back to metres, the baro
    (put into the GNSS datum by the reader) moved with them."""
    ft = load_drive(write_dataflash(SEMANTIC["gnss-alt-feet"][0](RAW, None), tmp_path / "f.bin"))
    ok = load_drive(write_dataflash(RAW, tmp_path / "m.bin"))
    w = _unit_warnings(ft)
    assert len(w) == 1 and "feet, not metres; converted (x 0.3048)" in w[0], w
    r = ft.meta["sanity"]["gnss_height_climb_ratio"]
    # measured 3.283 ± 0.092 (baro) and 3.284 ± 0.083 (GNSS vertical velocity)
    assert r["the baro"]["ratio"] == pytest.approx(1 / 0.3048, rel=0.1)
    assert r["its vertical velocity"]["ratio"] == pytest.approx(1 / 0.3048, rel=0.1)
    assert np.max(np.abs(ft.gnss.lla[:, 2] - ok.gnss.lla[:, 2])) < 1e-3  # float32 Alt
    assert np.max(np.abs(ft.baro.altitude - ok.baro.altitude)) < 2.0  # measured 0.87 m
    assert ft.origin_lla[2] == pytest.approx(ok.origin_lla[2], abs=1e-2)
    assert ft.meta["repaired"]["gnss"] == {"height scaled by 0.3048 (unit)": len(ft.gnss)}


def test_a_scale_error_that_is_not_feet_is_refused(tmp_path):
    raw = RAW.copy()
    raw.h = raw.h[0] + 2.0 * (raw.h - raw.h[0])
    raw.vel_n = raw.vel_n.copy()
    raw.vel_n[:, 2] *= 1.0  # the velocity stays right: only the height is scaled
    with pytest.raises(ValueError, match=r"gnss: height climbs 2\.\d\dx .*neither metres "
                                         "nor feet") as e:
        load_drive(write_dataflash(raw, tmp_path / "x2.bin"))
    assert "\n" not in str(e.value)


@pytest.mark.parametrize("fmt", sorted(WRITERS))
def test_feet_in_every_format_and_clean_files_silent(tmp_path, fmt):
    args = (SIM,) if fmt == "npz" else ()
    clean = load_drive(WRITERS[fmt](RAW, tmp_path / f"c{SUFFIX[fmt]}", *args))
    assert _unit_warnings(clean) == []
    ft = load_drive(WRITERS[fmt](SEMANTIC["gnss-alt-feet"][0](RAW, None),
                                 tmp_path / f"f{SUFFIX[fmt]}", *args))
    assert any("converted (x 0.3048)" in w for w in _unit_warnings(ft))


def test_shared_logs_are_silent(data_dir):
    logs = [p for p in sorted(data_dir.glob("*/*")) if p.suffix.lower() in (".bin", ".ulg",
                                                                               ".csv")
            and "ski" not in p.parent.name]
    logs += [p for p in data_dir.glob("ski*") if p.is_dir()]
    assert len(logs) >= 5
    for p in logs:
        d = load_drive(p)
        assert _unit_warnings(d) == [], (p.name, _unit_warnings(d))


@pytest.mark.slow
@pytest.mark.parametrize("scenario", list_scenarios())
def test_simulated_scenarios_are_silent(scenario):
    for seed in (0, 1, 2):
        d = simulate(scenario, seed)
        f = Findings(dict(d.meta))
        assert check_gnss_height_units(d, f) is None, (scenario, seed)
        assert f.warnings == list(d.meta.get("warnings") or []), (scenario, seed, f.warnings)


def test_the_refusal_is_exit_2_with_one_line(tmp_path, capsys):
    from vnav_graph.cli import main

    raw = RAW.copy()
    raw.h = raw.h[0] + 2.0 * (raw.h - raw.h[0])
    out = tmp_path / "out"
    assert main(["run", str(write_dataflash(raw, tmp_path / "x2.bin")), "--estimators", "loop3",
                 "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith("vnav-graph: error: gnss: height climbs 2.0")  # measured 2.01
    assert "neither metres nor feet" in err[0]
    assert not out.exists() or not any(out.iterdir())


@pytest.mark.parametrize("log", ["erle_pxf_218/218.BIN", "erle_pxf_loiter_rtl/Loiter_RTL.bin"])
def test_shared_dataflash_logs_with_gps_alt_in_feet_are_converted(data_dir, tmp_path, log):
    """The real flights with GPS Alt rewritten in feet: measured 3.10 ± 0.15 (218) and
    3.18 ± 0.20 (Loiter_RTL) against the baro; back to metres within the field's 1 cm
    rounding, the baro datum with them."""
    from tests.fuzz.writers import dataflash_scale_field

    src = data_dir / log
    if not src.exists():
        pytest.skip(f"{log} not present")
    p = tmp_path / src.name
    p.write_bytes(dataflash_scale_field(src.read_bytes(), "GPS", "Alt", 1 / 0.3048))
    ft, ok = load_drive(p), load_drive(src)
    assert any("feet, not metres; converted (x 0.3048)" in w for w in _unit_warnings(ft))
    assert np.max(np.abs(ft.gnss.lla[:, 2] - ok.gnss.lla[:, 2])) < 0.005
    assert np.max(np.abs(ft.baro.altitude - ok.baro.altitude)) < 0.1  # measured 0.06 m
