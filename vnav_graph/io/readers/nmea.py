"""NMEA 0183 GNSS logs (GGA, RMC, VTG, GST) as GNSS input or as a reference, parsed with
``pynmea2`` (MIT), every sentence's checksum checked.

- ``GGA``: time of day (UTC), latitude, longitude, altitude above the geoid and the geoid
  separation N, fix quality, satellites, HDOP. Quality → RTKLIB's Q (``QUALITY`` of
  ``rtklib_pos``): 4 RTK fixed → 1 fix, 5 RTK float → 2 float, 9 SBAS → 3, 2 DGPS → 4,
  1 GPS → 5 single; 0 (no fix) and 6 (dead reckoning), 7 (manual), 8 (simulator) are dropped.
- ``RMC``: the date (GGA has none; a log without an RMC date is refused), speed and course
  over ground; ``VTG`` speed and course where there is no RMC at that time.
- ``GST``: σ of latitude, longitude and altitude [m], used as the fix's σ. Without a GST for
  an epoch the σ is HDOP × ``UERE_M`` of its quality (horizontal; vertical 1.5 ×), a stated
  default, and the notes say so.

Heights: with the geoid separation in every GGA the heights are ellipsoidal (altitude + N),
otherwise they stay above the geoid (MSL). Velocity: horizontal from speed and course, σ
``VEL_SD_H``; the vertical is not in NMEA and is not used (σ 1e4 m/s). Sentences that fail
their checksum, have none, or cannot be parsed are dropped and counted.
"""

from __future__ import annotations

from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from ._common import Report
from .gpstime import unix_to_gps
from .rtklib_pos import UNUSED_VEL_SD, PosSolution

__all__ = ["GGA_TO_Q", "UERE_M", "VEL_SD_H", "is_nmea", "read_nmea"]

GGA_TO_Q = {4: 1, 5: 2, 9: 3, 2: 4, 1: 5, 3: 5}
# σ per unit HDOP when a fix has no GST [m], by RTKLIB Q: a documented default
UERE_M = {1: 0.02, 2: 0.3, 3: 1.5, 4: 1.0, 5: 3.0}
VEL_SD_H = 0.2  # m/s, horizontal velocity σ from speed and course (NMEA gives none)
KNOT = 1852.0 / 3600.0


def is_nmea(head: bytes) -> bool:
    """True when a line of ``head`` is an NMEA sentence (``$xxGGA`` / ``$xxRMC`` …)."""
    for line in head.splitlines()[:50]:
        s = line.strip()
        if s[:1] == b"$" and s[3:6] in (b"GGA", b"RMC", b"VTG", b"GST") and b"*" in s:
            return True
    return False


def _tod(ts: object) -> float | None:
    if ts is None:
        return None
    return (ts.hour * 3600 + ts.minute * 60 + ts.second  # type: ignore[attr-defined]
            + ts.microsecond * 1e-6)  # type: ignore[attr-defined]


def read_nmea(path: str | Path) -> PosSolution:
    """The fixes of an NMEA file as a :class:`~.rtklib_pos.PosSolution` (module docstring);
    ValueError (one line) when no GGA with a date is readable."""
    import pynmea2

    p = Path(path)
    try:
        text = p.read_text(encoding="ascii", errors="replace")
    except OSError as exc:
        raise ValueError(f"{p.name}: cannot read ({exc.strerror})") from None
    report = Report()
    gga: list[tuple[float, object]] = []
    gst: dict[float, tuple[float, float, float]] = {}
    vel: dict[float, tuple[float, float]] = {}
    dates: list[tuple[float, object]] = []
    n_bad = 0
    for line in text.splitlines():
        s = line.strip()
        if not s.startswith("$"):
            continue
        try:
            m = pynmea2.parse(s, check=True)
        except (pynmea2.ParseError, ValueError, TypeError, AttributeError):
            n_bad += 1
            continue
        kind = getattr(m, "sentence_type", "")
        tod = _tod(getattr(m, "timestamp", None)) if kind != "VTG" else None
        try:
            if kind == "GGA" and tod is not None:
                gga.append((tod, m))
            elif kind == "GST" and tod is not None:
                gst[round(tod, 2)] = (float(m.std_dev_latitude), float(m.std_dev_longitude),
                                      float(m.std_dev_altitude))
            elif kind == "RMC" and tod is not None and m.status == "A":
                if m.datestamp is not None:
                    dates.append((tod, m.datestamp))
                if m.spd_over_grnd is not None and m.true_course is not None:
                    vel[round(tod, 2)] = (float(m.spd_over_grnd) * KNOT, float(m.true_course))
            elif kind == "VTG" and gga and m.spd_over_grnd_kmph is not None \
                    and m.true_track is not None:
                vel.setdefault(round(gga[-1][0], 2), (float(m.spd_over_grnd_kmph) / 3.6,
                                                      float(m.true_track)))
        except (TypeError, ValueError):
            n_bad += 1
    report.drop("gnss", "NMEA sentence with a bad or missing checksum, or unreadable", n_bad)
    if not gga:
        raise ValueError(f"{p.name}: no readable GGA sentence (NMEA 0183 with checksums)")
    if not dates:
        raise ValueError(f"{p.name}: no RMC sentence with a date: the UTC day of the GGA "
                         "times is unknown")
    return _solution(p.name, gga, gst, vel, dates, report)


def _solution(name: str, gga: list[tuple[float, object]],
              gst: dict[float, tuple[float, float, float]],
              vel: dict[float, tuple[float, float]], dates: list[tuple[float, object]],
              report: Report) -> PosSolution:
    rows = []
    n_nofix = 0
    day0 = datetime.combine(dates[0][1], datetime.min.time(), UTC).timestamp()  # type: ignore[arg-type]
    tod0 = dates[0][0]
    for tod, m in gga:
        q = GGA_TO_Q.get(int(m.gps_qual or 0))  # type: ignore[attr-defined]
        if q is None or m.latitude is None or m.altitude is None:  # type: ignore[attr-defined]
            n_nofix += 1
            continue
        # the day of each fix: the RMC date, rolling over when the time of day wraps
        unix = day0 + tod + (86400.0 if tod < tod0 - 43200 else 0.0)
        sep = m.geo_sep  # type: ignore[attr-defined]
        rows.append((unix, float(m.latitude), float(m.longitude), float(m.altitude),  # type: ignore[attr-defined]
                     None if sep in (None, "") else float(sep), q,
                     int(m.num_sats or 0), float(m.horizontal_dil or 1.0), tod))  # type: ignore[attr-defined]
    report.drop("gnss", "GGA without a position fix (quality 0, 6, 7 or 8)", n_nofix)
    if not rows:
        raise ValueError(f"{name}: no GGA sentence with a position fix")
    unix = np.array([r[0] for r in rows])
    ellipsoidal = all(r[4] is not None for r in rows)
    h = np.array([r[3] + (r[4] if ellipsoidal else 0.0) for r in rows])
    lla = np.column_stack([np.radians([r[1] for r in rows]), np.radians([r[2] for r in rows]),
                           h])
    q = np.array([r[5] for r in rows])
    sd = np.empty((len(rows), 3))
    n_gst = 0
    for k, r in enumerate(rows):
        g = gst.get(round(r[8], 2))
        if g is not None and all(np.isfinite(g)) and min(g) > 0:
            sd[k] = g
            n_gst += 1
        else:
            sh = UERE_M[r[5]] * max(r[7], 0.5)
            sd[k] = (sh, sh, 1.5 * sh)
    v = np.zeros((len(rows), 3))
    vsd = np.full((len(rows), 3), UNUSED_VEL_SD)
    for k, r in enumerate(rows):
        sc = vel.get(round(r[8], 2))
        if sc is not None:
            cr = np.radians(sc[1])
            v[k, :2] = sc[0] * np.cos(cr), sc[0] * np.sin(cr)
            vsd[k, :2] = VEL_SD_H
    if n_gst < len(rows):
        report.notes.append(f"{name}: {len(rows) - n_gst} of {len(rows)} fixes without GST: "
                            "sigma = HDOP x the quality's UERE (default, nmea.UERE_M)")
    t = unix_to_gps(unix)
    order = np.argsort(t, kind="stable")
    sol = PosSolution(name, t, lla, q, np.array([r[6] for r in rows]), sd, v, vsd, "UTC",
                      "ellipsoid" if ellipsoidal else "msl", "GGA", "nmea", report)
    return sol.select(order)
