"""GPS time: calendar stamps, week + time of week, and UTC, as seconds since the GPS epoch.

GPST seconds are counted from 1980-01-06T00:00:00 on the GPS scale (no leap seconds); UTC
differs by the leap seconds in force (18 s since 2017). ``gps_to_unix`` (the readers' shared
table of leap seconds) converts GPST → Unix UTC; ``unix_to_gps`` inverts it.
"""

from __future__ import annotations

from datetime import UTC, datetime
from typing import Any

import numpy as np

from ._common import GPS_EPOCH_UNIX_S, gps_to_unix

__all__ = ["GPS_EPOCH_UNIX_S", "SECONDS_PER_WEEK", "calendar_seconds", "gps_to_unix", "unix_to_gps",
           "week_tow_to_gps"]

SECONDS_PER_WEEK = 604800.0


def calendar_seconds(stamp: str) -> float:
    """``YYYY/MM/DD HH:MM:SS.sss`` (or with ``-`` / ``T``) read as seconds since 1970-01-01 on
    the stamp's own scale (no leap seconds). ValueError when it is not such a stamp."""
    s = stamp.strip().replace("/", "-").replace("T", " ")
    date, _, clock = s.partition(" ")
    if not clock:
        raise ValueError(f"not a date and time: {stamp!r}")
    whole, _, frac = clock.partition(".")
    dt = datetime.strptime(f"{date} {whole}", "%Y-%m-%d %H:%M:%S").replace(tzinfo=UTC)
    return dt.timestamp() + (float(f"0.{frac}") if frac else 0.0)


def week_tow_to_gps(week: Any, tow: Any) -> np.ndarray:
    """GPS week and time of week [s] → GPST seconds since the GPS epoch."""
    return np.asarray(week, dtype=float) * SECONDS_PER_WEEK + np.asarray(tow, dtype=float)


def unix_to_gps(unix_s: Any) -> np.ndarray:
    """Unix time [s, UTC] → GPST seconds since the GPS epoch (the inverse of ``gps_to_unix``;
    exact away from the second of a leap)."""
    u = np.asarray(unix_s, dtype=float)
    g = u - GPS_EPOCH_UNIX_S + 18.0
    return g + (u - gps_to_unix(g))
