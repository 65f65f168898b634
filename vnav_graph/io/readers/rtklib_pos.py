"""RTKLIB ``.pos`` solution files (rnx2rtkp, rtknavi, rtkpost, receivers' RTKLIB output).

A ``.pos`` file is text: ``%`` header lines, then one epoch per line, whitespace-separated:

- time: ``YYYY/MM/DD HH:MM:SS.sss`` or GPS week and time of week [s]; the column header's
  first word (``GPST`` or ``UTC``) names the time system;
- position: ``latitude(deg) longitude(deg) height(m)`` or ``x-ecef(m) y-ecef(m) z-ecef(m)``;
- ``Q`` (1 fix, 2 float, 3 SBAS, 4 DGPS, 5 single, 6 PPP: ``QUALITY``) and ``ns``;
- σ: ``sdn sde sdu sdne sdeu sdun`` [m] (or ``sdx sdy sdz sdxy sdyz sdzx`` in ECEF), the
  off-diagonal ones as sign(c)·√|c| of the covariance c;
- ``age(s) ratio``; then, when the solution has velocities, ``vn ve vu sdvn sdve sdvu …``
  [m/s] (or ``vx vy vz sdvx …`` in ECEF).

What this reader returns (:class:`PosSolution`): times as GPST seconds since the GPS epoch
(UTC converted with the leap seconds), latitude/longitude [rad], height [m], per-epoch NED
σ [m] (ECEF covariances rotated to NED), NED velocity [m/s] and σ where present. The σ are
the file's own: a fix's centimetres stay centimetres, a float or single-point epoch keeps
the larger σ RTKLIB wrote for it (``sd_scale`` in :func:`gnss_stream` multiplies them per
quality when a user wants more). Nothing is floored here; the estimators' numerical floor is
``sensors.gnss_model.GNSS_SD_FLOOR`` (1 cm).

Height datum: ``(lat/lon/height=WGS84/ellipsoidal…)`` → ``"ellipsoid"``,
``…/geodetic`` → ``"msl"`` (RTKLIB's geoid heights); ECEF solutions are ellipsoidal. A file
whose header does not say (e.g. a receiver's own RTKLIB output with only the column line)
needs the datum stated (``height_datum=``, ``--height-datum``, or the map's
``height_datum``); a statement that contradicts the header is refused.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ...types.streams import GnssStream
from ._common import Report, monotonic_mask
from .gpstime import GPS_EPOCH_UNIX_S, calendar_seconds, unix_to_gps, week_tow_to_gps

__all__ = ["QUALITY", "PosSolution", "gnss_stream", "is_pos", "read_pos", "to_datum"]

QUALITY = {1: "fix", 2: "float", 3: "sbas", 4: "dgps", 5: "single", 6: "ppp"}
HEIGHT_DATUMS = ("msl", "ellipsoid")
# σ given to the velocity of an epoch whose velocity σ is missing or zero: not used [m/s]
UNUSED_VEL_SD = 1.0e4
# columns after the two time tokens: position (13) and velocity (9)
N_POS_COLS, N_VEL_COLS = 13, 9


@dataclass(frozen=True)
class PosSolution:
    """One ``.pos`` file (module docstring).

    t_gpst : (N,) GPST seconds since 1980-01-06
    lla : (N, 3) latitude [rad], longitude [rad], height [m] in ``height_datum``
    q : (N,) RTKLIB quality (``QUALITY``); ns : (N,) satellites
    sd_ned : (N, 3) one-sigma north, east, down [m] as in the file
    vel_ned, vel_sd : (N, 3) or None [m/s]
    time_system : ``"GPST"`` or ``"UTC"`` (of the file; ``t_gpst`` is GPST either way)
    height_datum : ``"msl"``, ``"ellipsoid"`` or None (header silent, not stated)
    datum_source : ``"header"``, ``"stated"`` or None
    """

    name: str
    t_gpst: np.ndarray
    lla: np.ndarray
    q: np.ndarray
    ns: np.ndarray
    sd_ned: np.ndarray
    vel_ned: np.ndarray | None
    vel_sd: np.ndarray | None
    time_system: str
    height_datum: str | None
    datum_source: str | None
    form: str  # "llh" or "xyz"
    report: Report = field(default_factory=Report)

    def __len__(self) -> int:
        return int(self.t_gpst.size)

    def quality_counts(self) -> dict[str, int]:
        """Epochs per quality name, e.g. ``{"fix": 2190, "float": 8}``."""
        vals, counts = np.unique(self.q, return_counts=True)
        return {QUALITY.get(int(v), f"Q{int(v)}"): int(c) for v, c in zip(vals, counts,
                                                                            strict=True)}

    def select(self, mask: np.ndarray) -> PosSolution:
        from dataclasses import replace

        def s(a: np.ndarray | None) -> np.ndarray | None:
            return None if a is None else a[mask]

        return replace(self, t_gpst=self.t_gpst[mask], lla=self.lla[mask], q=self.q[mask],
                       ns=self.ns[mask], sd_ned=self.sd_ned[mask], vel_ned=s(self.vel_ned),
                       vel_sd=s(self.vel_sd))


def is_pos(head: bytes) -> bool:
    """True when ``head`` (the first bytes of a file) looks like an RTKLIB solution: a ``%``
    column line naming GPST or UTC and latitude or x-ecef columns."""
    try:
        text = head.decode("ascii", errors="strict")
    except UnicodeDecodeError:
        return False
    for line in text.splitlines():
        if line.startswith("%") and _column_line(line):
            return True
    return False


def _column_line(line: str) -> bool:
    words = line.lstrip("%").split()
    return bool(words) and words[0] in ("GPST", "UTC", "JST") and any(
        w.startswith(("latitude", "x-ecef", "e-baseline", "n-baseline")) for w in words)


def read_pos(path: str | Path, height_datum: str | None = None) -> PosSolution:
    """Read an RTKLIB ``.pos`` file (module docstring). ``height_datum``: ``"msl"`` or
    ``"ellipsoid"`` for a file whose header does not state it. Malformed lines (a cut last
    line, a wrong number of columns, unreadable numbers) are dropped and counted in
    ``report``; ValueError (one line) when nothing is readable or the file is not a
    lat/lon/height or ECEF solution."""
    p = Path(path)
    if height_datum is not None and height_datum not in HEIGHT_DATUMS:
        raise ValueError(f"height datum must be msl or ellipsoid, not {height_datum!r}")
    try:
        text = p.read_text(encoding="ascii", errors="replace")
    except OSError as exc:
        raise ValueError(f"{p.name}: cannot read ({exc.strerror})") from None
    header = [ln for ln in text.splitlines() if ln.startswith("%")]
    cols = [ln for ln in header if _column_line(ln)]
    if not cols:
        raise ValueError(f"{p.name}: not an RTKLIB solution (no '%  GPST latitude(deg) …' "
                         "or '%  GPST x-ecef(m) …' column line)")
    words = cols[-1].lstrip("%").split()
    time_system = words[0]
    if time_system == "JST":
        raise ValueError(f"{p.name}: times in JST are not supported (write GPST or UTC)")
    if any(w.startswith(("e-baseline", "n-baseline")) for w in words):
        raise ValueError(f"{p.name}: an ENU/NED baseline solution has no absolute position "
                         "(write lat/lon/height or x/y/z-ECEF)")
    if any(w.startswith("latitude(d'") for w in words):
        raise ValueError(f"{p.name}: latitude in degrees-minutes-seconds is not supported "
                         "(write the solution with decimal degrees, out-solformat=llh, "
                         "out-degformat=deg)")
    form = "xyz" if any(w.startswith("x-ecef") for w in words) else "llh"
    datum, source = _datum(p.name, header, form, height_datum)
    report = Report()
    rows, stamps = _rows(text, report)
    if not rows:
        raise ValueError(f"{p.name}: no readable solution line")
    t = _gpst(stamps, time_system, p.name)
    ncol = min(len(r) for r in rows)
    a = np.array([r[:ncol] for r in rows], dtype=float)
    has_vel = ncol >= N_POS_COLS + N_VEL_COLS
    if form == "llh":
        lla = np.column_stack([np.radians(a[:, 0]), np.radians(a[:, 1]), a[:, 2]])
        sd = a[:, 5:8].copy()
        vel = np.column_stack([a[:, 13], a[:, 14], -a[:, 15]]) if has_vel else None
        vsd = a[:, 16:19].copy() if has_vel else None
    else:
        lla, sd, vel, vsd = _from_ecef(a, has_vel)
    q, ns = a[:, 3].astype(int), a[:, 4].astype(int)
    ok = np.all(np.isfinite(lla), axis=1) & np.all(np.isfinite(sd), axis=1)
    report.drop("gnss", "position or sigma not finite", int((~ok).sum()))
    bad_sd = ok & np.any(sd <= 0, axis=1)
    report.drop("gnss", "position sigma zero (no solution)", int(bad_sd.sum()))
    ok &= ~bad_sd
    keep = np.zeros(t.size, dtype=bool)
    keep[ok] = monotonic_mask(t[ok], "gnss", report)
    if not keep.any():
        raise ValueError(f"{p.name}: no solution line with a position and its sigma")
    if vel is not None and vsd is not None:
        novel = keep & ~(np.all(np.isfinite(vel), axis=1) & np.all(vsd > 0, axis=1))
        if novel.any():
            vel[novel] = 0.0
            vsd[novel] = UNUSED_VEL_SD
            report.repair("gnss", f"velocity sigma zero or missing: velocity not used "
                          f"(sigma {UNUSED_VEL_SD:g} m/s)", int(novel.sum()))
    sol = PosSolution(p.name, t, lla, q, ns, sd, vel, vsd, time_system, datum, source, form,
                      report)
    return sol.select(keep)


def _datum(name: str, header: list[str], form: str, stated: str | None
           ) -> tuple[str | None, str | None]:
    said = None
    if form == "xyz":
        said = "ellipsoid"
    for ln in header:
        low = ln.lower()
        if "height=" in low or "height =" in low:
            if "ellipsoidal" in low:
                said = "ellipsoid"
            elif "geodetic" in low or "msl" in low:
                said = "msl"
    if said is not None and stated is not None and stated != said:
        raise ValueError(f"{name}: the header gives heights above the "
                         f"{'ellipsoid' if said == 'ellipsoid' else 'geoid (MSL)'}, "
                         f"not {stated}")
    if said is not None:
        return said, "header"
    return stated, None if stated is None else "stated"


def _rows(text: str, report: Report) -> tuple[list[list[str]], list[tuple[str, str]]]:
    rows: list[list[str]] = []
    stamps: list[tuple[str, str]] = []
    n_bad = 0
    for ln in text.splitlines():
        if not ln.strip() or ln.startswith("%"):
            continue
        w = ln.split()
        if len(w) < 2 + N_POS_COLS:
            n_bad += 1
            continue
        try:
            [float(x) for x in w[2:]]
        except ValueError:
            n_bad += 1
            continue
        stamps.append((w[0], w[1]))
        rows.append(w[2:])
    lengths = {len(r) for r in rows}
    if len(lengths) > 1:  # a line cut short or with extra columns: keep the common layout
        common = max(lengths, key=lambda n: sum(len(r) == n for r in rows))
        keep = [len(r) == common for r in rows]
        n_bad += keep.count(False)
        rows = [r for r, k in zip(rows, keep, strict=True) if k]
        stamps = [s for s, k in zip(stamps, keep, strict=True) if k]
    report.drop("gnss", "malformed solution line", n_bad)
    return rows, stamps


def _gpst(stamps: list[tuple[str, str]], system: str, name: str) -> np.ndarray:
    """GPST seconds since the GPS epoch of the time tokens."""
    if "/" in stamps[0][0] or "-" in stamps[0][0]:
        try:
            cal = np.array([calendar_seconds(f"{d} {c}") for d, c in stamps])
        except ValueError as exc:
            raise ValueError(f"{name}: unreadable time stamp ({exc})") from None
        if system == "UTC":
            return unix_to_gps(cal)
        return cal - GPS_EPOCH_UNIX_S  # a GPST calendar stamp counts no leap seconds
    try:
        week = np.array([float(d) for d, _ in stamps])
        tow = np.array([float(c) for _, c in stamps])
    except ValueError:
        raise ValueError(f"{name}: time is neither a date and time nor GPS week and "
                         "time of week") from None
    if system == "UTC":
        raise ValueError(f"{name}: week and time of week on the UTC scale is not a time "
                         "RTKLIB writes")
    return week_tow_to_gps(week, tow)


def _signed_sq(s: np.ndarray) -> np.ndarray:
    return np.sign(s) * s * s


def _ecef_to_ned(lat: np.ndarray, lon: np.ndarray) -> np.ndarray:
    """(N, 3, 3) rotations taking ECEF vectors into NED at lat/lon [rad]."""
    sl, cl, so, co = np.sin(lat), np.cos(lat), np.sin(lon), np.cos(lon)
    r = np.empty((lat.size, 3, 3))
    r[:, 0] = np.column_stack([-sl * co, -sl * so, cl])
    r[:, 1] = np.column_stack([-so, co, np.zeros_like(lat)])
    r[:, 2] = np.column_stack([-cl * co, -cl * so, -sl])
    return r


def _from_ecef(a: np.ndarray, has_vel: bool
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None]:
    import pymap3d

    lat, lon, h = pymap3d.ecef2geodetic(a[:, 0], a[:, 1], a[:, 2], deg=False)
    lla = np.column_stack([lat, lon, h])
    r = _ecef_to_ned(np.asarray(lat), np.asarray(lon))

    def cov(j: int) -> np.ndarray:  # sdx sdy sdz sdxy sdyz sdzx from column j
        sx, sy, sz, sxy, syz, szx = (a[:, j + k] for k in range(6))
        c = np.empty((a.shape[0], 3, 3))
        c[:, 0, 0], c[:, 1, 1], c[:, 2, 2] = sx * sx, sy * sy, sz * sz
        c[:, 0, 1] = c[:, 1, 0] = _signed_sq(sxy)
        c[:, 1, 2] = c[:, 2, 1] = _signed_sq(syz)
        c[:, 2, 0] = c[:, 0, 2] = _signed_sq(szx)
        ned = r @ c @ np.transpose(r, (0, 2, 1))
        d = np.diagonal(ned, axis1=1, axis2=2)
        # an all-zero covariance stays zero (→ dropped, "no solution"), never NaN
        return np.sqrt(np.clip(d, 0.0, None))

    sd = cov(5)
    if not has_vel:
        return lla, sd, None, None
    vel = np.einsum("nij,nj->ni", r, a[:, 13:16])
    return lla, sd, vel, cov(16)


def to_datum(h: np.ndarray, src: str, dst: str, geoid_sep_m: float | None,
             what: str) -> np.ndarray:
    """Heights ``h`` [m] from datum ``src`` to ``dst`` (``"msl"`` / ``"ellipsoid"``) with
    the geoid separation N = h_ellipsoid − h_msl [m] (``geoid_sep_m``). ValueError when the
    datums differ and N is not given (no geoid model in the package)."""
    if src == dst:
        return np.asarray(h, dtype=float)
    if geoid_sep_m is None:
        raise ValueError(f"{what}: heights above {src} but the drive's are above {dst}: give "
                         "the geoid separation (geoid_separation_m in the map, "
                         "N = ellipsoidal − MSL height)")
    n = float(geoid_sep_m)
    return np.asarray(h, dtype=float) + (n if dst == "ellipsoid" else -n)


def gnss_stream(sol: PosSolution, t0_gpst: float, datum: str,
                geoid_sep_m: float | None = None, lever_arm_b: Any = None,
                sd_scale: dict[str, float] | None = None, min_quality: int | None = None,
                time_offset_s: float = 0.0) -> tuple[GnssStream, list[str]]:
    """The solution as the drive's GNSS input, on the drive clock ``t = t_gpst − t0_gpst +
    time_offset_s`` [s], heights in ``datum``.

    ``sd_scale``: σ multiplier per quality name (``{"float": 2, "single": 5}``; default 1:
    the file's σ as written). ``min_quality``: keep epochs with Q ≤ this (1 = fixes only).
    Returns the stream and the notes that say what was taken (for ``Drive.meta``)."""
    if sol.height_datum is None:
        raise ValueError(f"{sol.name}: the header does not state the height datum: give "
                         "--height-datum msl|ellipsoid (or height_datum in the map)")
    keep = np.ones(len(sol), dtype=bool)
    if min_quality is not None:
        keep = sol.q <= int(min_quality)
        if not keep.any():
            raise ValueError(f"{sol.name}: no epoch with Q <= {min_quality}")
    s = sol.select(keep)
    scale = np.ones(len(s))
    for name, f in (sd_scale or {}).items():
        if name not in QUALITY.values():
            raise ValueError(f"sd_scale: unknown quality {name!r} (one of "
                             f"{', '.join(QUALITY.values())})")
        if not (np.isfinite(f) and f > 0):
            raise ValueError(f"sd_scale.{name}: must be > 0, not {f}")
        code = next(k for k, v in QUALITY.items() if v == name)
        scale[s.q == code] = float(f)
    lla = s.lla.copy()
    lla[:, 2] = to_datum(lla[:, 2], s.height_datum or datum, datum, geoid_sep_m, s.name)
    sd = s.sd_ned * scale[:, None]
    vsd = None if s.vel_sd is None else s.vel_sd * scale[:, None]
    lever = np.zeros(3) if lever_arm_b is None else np.asarray(lever_arm_b, dtype=float)
    t = s.t_gpst - t0_gpst + time_offset_s
    g = GnssStream(t, lla, sd, s.vel_ned, vsd, lever)
    med = np.median(s.sd_ned, axis=0)
    notes = [f"GNSS from {s.name} (RTKLIB {s.form}, {s.time_system}, heights above "
             f"{s.height_datum} ({s.datum_source})): {len(s)} epochs "
             f"({', '.join(f'{k} {v}' for k, v in s.quality_counts().items())}), median "
             f"sigma N/E/D {med[0]:.3f}/{med[1]:.3f}/{med[2]:.3f} m as in the file"
             + ("" if s.vel_ned is not None else ", no velocity columns")]
    if sd_scale:
        notes.append("GNSS sigma scaled by quality: "
                     + ", ".join(f"{k} x{v:g}" for k, v in sd_scale.items()))
    if s.height_datum != datum:
        notes.append(f"GNSS heights of {s.name} converted from {s.height_datum} to {datum} "
                     f"with the geoid separation N = {geoid_sep_m:+.3f} m")
    return g, notes
