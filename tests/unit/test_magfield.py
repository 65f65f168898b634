"""WMM main field (vnav_graph.geo.magfield) against NOAA's published test values."""

import math
from datetime import datetime

import numpy as np
import pytest

from vnav_graph.geo.magfield import (
    decimal_year_from_datetime,
    decimal_year_from_gps,
    earth_field,
)

R = math.radians

# NOAA WMM test values (WMM2010testvalues.pdf, WMM2020testvalues.pdf, WMM2025testvalues.pdf;
# pygeomag's test/test_values carry the first two): year, height [km], lat [deg], lon [deg],
# X, Y, Z [nT], D, I [deg], model. The WMM2025 rows' I is atan2(Z, H) of the printed X, Y, Z.
NOAA = [
    (2010.0, 0, 80, 0, 6649.5, -714.6, 54346.2, -6.13, 82.98, "WMM2010"),
    (2010.0, 100, 0, 120, 37452.0, 611.9, -11180.8, 0.94, -16.62, "WMM2010"),
    (2012.5, 0, -80, 240, 5713.6, 15731.8, -53184.3, 70.04, -72.53, "WMM2010"),
    (2020.0, 0, 80, 0, 6570.4, -146.3, 54606.0, -1.28, 83.14, "WMM2020"),
    (2020.0, 0, 0, 120, 39624.3, 109.9, -10932.5, 0.16, -15.42, "WMM2020"),
    (2022.5, 100, -80, 240, 5815.0, 14803.0, -49755.3, 68.55, -72.27, "WMM2020"),
    (2025.0, 0, 80, 0, 6521.6, 145.9, 54791.5, 1.28, 83.21, "WMM2025"),
    (2025.0, 0, 0, 120, 39677.8, -109.6, -10580.2, -0.16, -14.93, "WMM2025"),
    (2027.5, 100, -80, 240, 5984.0, 14760.1, -49317.7, 67.93, -72.10, "WMM2025"),
]


@pytest.mark.parametrize("year,h_km,lat,lon,x,y,z,d,i,model", NOAA)
def test_noaa_test_values(year, h_km, lat, lon, x, y, z, d, i, model):
    f = earth_field(R(lat), R(lon), h_km * 1000.0, year)
    assert f.model == model and f.note == ""
    # the tables print 0.1 nT and 0.01 deg
    np.testing.assert_allclose(f.ned_ut * 1000.0, [x, y, z], atol=0.1)
    assert math.degrees(f.declination_rad) == pytest.approx(d, abs=0.01)
    assert math.degrees(f.inclination_rad) == pytest.approx(i, abs=0.01)


def test_components_consistent_with_angles():
    f = earth_field(R(47.26), R(11.39), 580.0, 2025.5)
    n, e, d = f.ned_ut
    assert np.linalg.norm(f.ned_ut) == pytest.approx(f.total_ut, rel=1e-9)
    assert math.hypot(n, e) == pytest.approx(f.horizontal_ut, rel=1e-9)
    assert math.atan2(e, n) == pytest.approx(f.declination_rad, abs=1e-9)
    assert math.atan2(d, f.horizontal_ut) == pytest.approx(f.inclination_rad, abs=1e-9)
    expect = f.total_ut * np.array([
        math.cos(f.inclination_rad) * math.cos(f.declination_rad),
        math.cos(f.inclination_rad) * math.sin(f.declination_rad),
        math.sin(f.inclination_rad),
    ])
    np.testing.assert_allclose(f.ned_ut, expect, atol=1e-9)
    assert 20.0 < f.total_ut < 70.0  # µT, not nT


def test_signs():
    # Innsbruck: dip ≈ +64°, declination a few degrees east
    ibk = earth_field(R(47.26), R(11.39), 580.0, 2025.5)
    assert 60 < math.degrees(ibk.inclination_rad) < 68 and ibk.ned_ut[2] > 0
    assert 2 < math.degrees(ibk.declination_rad) < 7 and ibk.ned_ut[1] > 0
    # Seattle: declination ≈ 15° east (pygeomag's doc example); southern hemisphere: dip up
    sea = earth_field(R(47.6205), R(-122.3493), 0.0, 2025.25)
    assert math.degrees(sea.declination_rad) == pytest.approx(15.07, abs=0.01)
    syd = earth_field(R(-33.87), R(151.21), 0.0, 2026.0)
    assert syd.inclination_rad < 0 and syd.ned_ut[2] < 0 and syd.declination_rad > 0
    # west declination: Perth ≈ 1–2° W
    per = earth_field(R(-31.95), R(115.86), 0.0, 2026.0)
    assert per.declination_rad < 0


def test_epoch_choice_and_range():
    at = (R(47.26), R(11.39), 580.0)
    assert earth_field(*at, 2014.3).model == "WMM2010"
    assert earth_field(*at, 2015.0).model == "WMM2015v2"
    assert earth_field(*at, 2019.99).model == "WMM2015v2"
    assert earth_field(*at, 2024.9).model == "WMM2020"
    assert earth_field(*at, 2030.0).model == "WMM2025"
    late = earth_field(*at, 2031.5)
    assert late.model == "WMM2025" and "extrapolated" in late.note
    with pytest.raises(ValueError, match="no WMM before 2010"):
        earth_field(*at, 2009.9)
    with pytest.raises(ValueError):
        earth_field(*at, float("nan"))


def test_height_lowers_the_field():
    lo = earth_field(R(47.0), R(11.0), 0.0, 2025.5)
    hi = earth_field(R(47.0), R(11.0), 10_000.0, 2025.5)
    # dipole: F ∝ r⁻³ → −3·10 km / 6371 km ≈ −0.47 %
    assert hi.total_ut / lo.total_ut == pytest.approx(1 - 3 * 10 / 6371.2, abs=5e-4)


def test_decimal_year():
    assert decimal_year_from_datetime(datetime(2025, 1, 1)) == 2025.0
    assert decimal_year_from_datetime(datetime(2025, 7, 2, 12)) == pytest.approx(2025.5)
    assert decimal_year_from_datetime(datetime(2024, 7, 2)) == pytest.approx(2024.5)  # leap
    assert decimal_year_from_gps(0.0) == pytest.approx(1980 + 5 / 366)
    # GPS week 2000 starts 2018-05-06 (day 125 of 2018)
    assert decimal_year_from_gps(2000 * 604800.0) == pytest.approx(2018 + 125 / 365)
