"""The Earth's main magnetic field from the World Magnetic Model (WMM), via ``pygeomag``.

``earth_field(lat, lon, h, year)`` evaluates the WMM epoch whose 5-year validity covers
``year`` (WMM2010 for 2010.0–2015.0, WMM2015v2 for 2015–2020, WMM2020 for 2020–2025,
WMM2025 for 2025–2030.0) and returns the field in the local navigation frame
(north-east-down) in microtesla, with declination, inclination and the intensities.

Units and conventions (as the WMM report, NOAA/BGS):

- latitude / longitude: geodetic WGS-84 [rad], east longitude positive;
- height: above the WGS-84 ellipsoid [m] (the ellipsoidal height the navigation uses);
- year: decimal year, e.g. 2025.5 ≈ 2 July 2025 (``decimal_year_from_datetime``,
  ``decimal_year_from_gps``);
- field: µT (the WMM tables print nT: 1 µT = 1000 nT), components X north, Y east, Z down;
- declination D: angle from true north to the horizontal field, east positive [rad];
- inclination I (dip): angle of the field below the horizontal, positive downward (northern
  magnetic hemisphere) [rad].

pygeomag is imported on first use, so importing this module costs nothing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta
from functools import lru_cache
from typing import Any

import numpy as np

from ..types.streams import FloatArray

# (first valid year, coefficient file in pygeomag/wmm/, model name) — newest last
_WMM_EPOCHS: tuple[tuple[float, str, str], ...] = (
    (2010.0, "WMM_2010.COF", "WMM2010"),
    (2015.0, "WMM_2015v2.COF", "WMM2015v2"),
    (2020.0, "WMM_2020.COF", "WMM2020"),
    (2025.0, "WMM_2025.COF", "WMM2025"),
)
WMM_LIFESPAN_YEARS = 5.0
GPS_EPOCH = datetime(1980, 1, 6, tzinfo=UTC)


@dataclass(frozen=True)
class FieldModel:
    """The main field at one place and time.

    ned_ut : (3,) flux density in the navigation frame, north / east / down [µT]
    declination_rad : D, true north → horizontal field, east positive [rad]
    inclination_rad : I, below the horizontal, positive down [rad]
    total_ut : F = |ned_ut| [µT]
    horizontal_ut : H = |(north, east)| [µT]
    model : the WMM epoch used, e.g. ``"WMM2010"``
    note : empty, or why the value is less trustworthy (year past the newest model's
        validity: the secular variation is extrapolated)
    """

    ned_ut: FloatArray
    declination_rad: float
    inclination_rad: float
    total_ut: float
    horizontal_ut: float
    model: str
    note: str = ""


def _select_epoch(year: float) -> tuple[float, str, str, str]:
    """(epoch, file, name, note) of the WMM whose validity covers ``year``."""
    if not math.isfinite(year):
        raise ValueError(f"earth_field: year must be a finite decimal year, got {year!r}")
    first = _WMM_EPOCHS[0][0]
    if year < first:
        raise ValueError(f"earth_field: no WMM before {first:.0f} (year {year:g})")
    for epoch, fname, name in reversed(_WMM_EPOCHS):
        if year >= epoch:
            note = ""
            if year > epoch + WMM_LIFESPAN_YEARS:
                note = (f"year {year:g} is past {name}'s validity "
                        f"({epoch:g}–{epoch + WMM_LIFESPAN_YEARS:g}): secular variation "
                        "extrapolated")
            return epoch, fname, name, note
    raise AssertionError("unreachable")


@lru_cache(maxsize=len(_WMM_EPOCHS))
def _geomag(fname: str) -> Any:
    from pygeomag import GeoMag  # lazy: keeps `import vnav_graph` fast

    return GeoMag(coefficients_file=f"wmm/{fname}")


def earth_field(lat_rad: float, lon_rad: float, h_m: float, year: float) -> FieldModel:
    """The WMM main field at geodetic ``lat_rad``, ``lon_rad`` [rad], height ``h_m`` above
    the WGS-84 ellipsoid [m] and decimal ``year``.

    The WMM epoch is the one whose validity covers ``year``; a year after the newest model's
    validity uses the newest model (extrapolated, said in ``FieldModel.note``); a year before
    2010 raises ``ValueError``. Crustal and external (ionospheric, storm) fields are not in
    the model: a few hundred nT typically, more near magnetic anomalies.
    """
    year = float(year)
    _, fname, name, note = _select_epoch(year)
    r = _geomag(fname).calculate(
        glat=math.degrees(float(lat_rad)), glon=math.degrees(float(lon_rad)),
        alt=float(h_m) / 1000.0, time=year, allow_date_outside_lifespan=bool(note),
    )
    ned = np.array([r.x, r.y, r.z]) / 1000.0  # nT → µT
    return FieldModel(
        ned_ut=ned,
        declination_rad=math.radians(r.d),
        inclination_rad=math.radians(r.i),
        total_ut=float(r.f) / 1000.0,
        horizontal_ut=float(r.h) / 1000.0,
        model=name,
        note=note,
    )


def decimal_year_from_datetime(when: datetime) -> float:
    """Decimal year of ``when`` (fraction of its calendar year elapsed, to the second):
    2025-01-01T00:00 → 2025.0, 2025-07-02T12:00 → 2025.5. A naive datetime is taken as UTC."""
    if when.tzinfo is None:
        when = when.replace(tzinfo=UTC)
    y = when.astimezone(UTC).year
    start = datetime(y, 1, 1, tzinfo=UTC)
    length = (datetime(y + 1, 1, 1, tzinfo=UTC) - start).total_seconds()
    return y + (when - start).total_seconds() / length


def decimal_year_from_gps(gps_seconds: float) -> float:
    """Decimal year of a GPS time in seconds since the GPS epoch 1980-01-06T00:00 UTC (week ×
    604800 + time of week). Leap seconds (18 s since 2017) are ignored: 6e-7 year, nothing
    to the field."""
    return decimal_year_from_datetime(GPS_EPOCH + timedelta(seconds=float(gps_seconds)))


__all__ = ["FieldModel", "decimal_year_from_datetime", "decimal_year_from_gps", "earth_field"]
