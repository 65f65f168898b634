"""A reference trajectory (RTK, PPK, a navigation-grade INS' solution) read from a file and put
on a drive's clock, datum and measurement point: ``run --truth FILE`` / ``holdout --truth``.

Readers: RTKLIB ``.pos`` (``io.readers.rtklib_pos``) and NMEA 0183 (``io.readers.nmea``),
detected by content. What is reconciled, and said in the returned ``info``:

- time: the reference's GPST seconds (a UTC file converted with the leap seconds) minus the
  drive's ``t0_gpst_s`` (or its ``t0_unix_s`` converted to GPST); a drive with no absolute
  time cannot be scored against a file;
- heights: the reference's datum (header, the stated ``height_datum``) brought to the
  drive's (``Drive.height_reference``) with the geoid separation N = ellipsoidal − MSL when
  they differ;
- measurement point: with a lever arm ``l`` (the reference point relative to the IMU, body
  forward/right/down [m]) the IMU position is ``r_ref − C_nb l`` with C_nb level and headed
  along the reference's course while it moves faster than ``COURSE_MIN_SPEED`` (held
  between; the reference has no attitude);
- quality: ``fix_only`` keeps the epochs with Q = 1.

Velocities are the file's; a file without velocity columns gets central differences of its
positions (said in ``info``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from ..types import Drive, Trajectory

__all__ = ["COURSE_MIN_SPEED", "attach_reference", "drive_t0_gpst", "load_reference",
           "load_scored", "with_reference"]

COURSE_MIN_SPEED = 1.0  # m/s: slower, the course does not give the heading


def drive_t0_gpst(drive: Drive) -> float:
    """GPST seconds since the GPS epoch of t = 0 on the drive's clock."""
    if drive.meta.get("t0_gpst_s") is not None:
        return float(drive.meta["t0_gpst_s"])
    if drive.meta.get("t0_unix_s") is not None:
        from .readers.gpstime import unix_to_gps

        return float(unix_to_gps(float(drive.meta["t0_unix_s"])))
    raise ValueError(f"{drive.name}: the drive has no absolute time (GPS or UTC), so a "
                     "reference file cannot be put on its clock")


def _course_yaw(vel_n: np.ndarray) -> tuple[np.ndarray, int]:
    speed = np.hypot(vel_n[:, 0], vel_n[:, 1])
    moving = speed > COURSE_MIN_SPEED
    yaw = np.full(speed.size, np.nan)
    yaw[moving] = np.arctan2(vel_n[moving, 1], vel_n[moving, 0])
    if not moving.any():
        return np.zeros(speed.size), 0
    idx = np.where(moving, np.arange(speed.size), -1)
    idx = np.maximum.accumulate(idx)
    first = int(np.flatnonzero(moving)[0])
    idx[idx < 0] = first  # before the first motion: the first course
    return yaw[idx], int(moving.sum())


def _velocity(sol: Any, lla: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, str]:
    """NED velocity [m/s]: the file's, central differences of the positions where it has
    none."""
    from ..geo.frames import lla_to_ned

    if sol.vel_ned is not None:
        bad = np.any(sol.vel_sd >= 1e3, axis=1) if sol.vel_sd is not None else \
            np.zeros(len(sol), dtype=bool)
        if not bad.any():
            return sol.vel_ned.copy(), "file"
        note = "file (epochs without velocity: differences of positions)"
    else:
        bad = np.ones(len(sol), dtype=bool)
        note = "central differences of the positions (no velocity columns)"
    ned = lla_to_ned(lla, lla[0])
    diff = np.column_stack([np.gradient(ned[:, k], t) for k in range(3)])
    base = sol.vel_ned if sol.vel_ned is not None else diff
    return np.where(bad[:, None], diff, base), note


def _imu_point(lla: np.ndarray, vel: np.ndarray, lever_arm_b: Any
               ) -> tuple[np.ndarray, np.ndarray | None, str]:
    """The reference moved from its own point to the IMU (module docstring)."""
    from ..geo.frames import lla_to_ned, ned_to_lla

    if lever_arm_b is None or not np.any(np.asarray(lever_arm_b, dtype=float) != 0):
        return lla, None, "none given: the reference point is taken as the IMU"
    lever = np.asarray(lever_arm_b, dtype=float)
    yaw, n_moving = _course_yaw(vel)
    c, s = np.cos(yaw), np.sin(yaw)
    d_n = np.column_stack([c * lever[0] - s * lever[1], s * lever[0] + c * lever[1],
                           np.full(yaw.size, lever[2])])
    out = ned_to_lla(lla_to_ned(lla, lla[0]) - d_n, lla[0])
    return out, lever, (f"reference point at {lever.tolist()} m from the IMU (body F/R/D), "
                        "removed with a level attitude headed along the reference's course "
                        f"(moving > {COURSE_MIN_SPEED:g} m/s at {n_moving} of {yaw.size} "
                        "epochs, held between)")


def load_reference(path: str | Path, drive: Drive, height_datum: str | None = None,
                   lever_arm_b: Any = None, geoid_sep_m: float | None = None,
                   fix_only: bool = False) -> tuple[Trajectory, dict[str, Any]]:
    """The reference in ``path`` on ``drive``'s clock, datum and IMU point (module
    docstring), and what was done (``info``, JSON-ready). ValueError (one line) when it
    cannot be read or does not overlap the drive."""
    from .readers.rtklib_pos import QUALITY, is_pos, read_pos, to_datum

    p = Path(path)
    if not p.is_file():
        raise ValueError(f"--truth: no such file {p}")
    with open(p, "rb") as fh:
        head = fh.read(8192)
    if is_pos(head):
        sol = read_pos(p, height_datum)
        if sol.height_datum is None:
            raise ValueError(f"{p.name}: the header does not state the height datum: give "
                             "--height-datum msl|ellipsoid (or height_datum in the map's "
                             "[truth])")
        fmt = f"RTKLIB .pos ({sol.form}, {sol.time_system})"
    else:
        from .readers.nmea import is_nmea, read_nmea

        if not is_nmea(head):
            raise ValueError(f"{p.name}: not a reference trajectory (RTKLIB .pos or NMEA "
                             "0183)")
        sol = read_nmea(p)
        fmt = "NMEA 0183 (UTC)"
    n_all = len(sol)
    if fix_only:
        sol = sol.select(sol.q == 1)
        if len(sol) < 2:
            raise ValueError(f"{p.name}: fewer than 2 fixed (Q = 1) epochs")
    t0 = drive_t0_gpst(drive)
    t = sol.t_gpst - t0
    span = (t >= drive.imu.t[0] - 1.0) & (t <= drive.imu.t[-1] + 1.0)
    if span.sum() < 2:
        raise ValueError(f"{p.name}: the reference does not overlap the drive in time "
                         "(another day, or GPST against UTC?)")
    sol = sol.select(span)
    t = t[span]
    dst = drive.height_reference
    src = str(sol.height_datum)
    lla = sol.lla.copy()
    lla[:, 2] = to_datum(lla[:, 2], src, dst, geoid_sep_m, p.name)
    vel, vel_from = _velocity(sol, lla, t)
    lla, lever, lever_note = _imu_point(lla, vel, lever_arm_b)
    traj = Trajectory(t, lla, vel)
    gaps = np.diff(t)
    qn = {QUALITY.get(int(k), f"Q{int(k)}"): int(v)
          for k, v in zip(*np.unique(sol.q, return_counts=True), strict=True)}
    if src == dst:
        hnote = f"both above {dst}: no conversion"
    else:
        hnote = (f"reference above {src} ({sol.datum_source}), drive above {dst}: converted "
                 f"with the geoid separation N = {geoid_sep_m:+.3f} m")
    info = {
        "file": p.name,
        "format": fmt,
        "epochs": int(len(sol)),
        "epochs_in_file": int(n_all),
        "quality": qn,
        "fix_only": bool(fix_only),
        "time": (f"reference in {sol.time_system}"
                 + (" converted to GPST with the leap seconds" if sol.time_system == "UTC"
                    else "") + "; drive clock t = GPST − "
                 f"{t0:.3f} s (the drive's t0_gpst_s)"),
        "height": hnote,
        "lever_arm_m": None if lever is None else lever.tolist(),
        "lever_arm": lever_note,
        "velocity": vel_from,
        "largest_gap_s": float(gaps.max()) if gaps.size else None,
        "sd_median_m": [float(x) for x in np.median(sol.sd_ned, axis=0)],
    }
    return traj, info


def with_reference(drive: Drive, traj: Trajectory, info: dict[str, Any],
                   is_input: bool = False) -> Drive:
    """``drive`` with ``traj`` as its truth and ``meta["reference"] = info``; ``is_input``:
    the reference is the drive's own GNSS input (a warning says what the scores then mean,
    and ``info["is_gnss_input"]``)."""
    meta = dict(drive.meta)
    meta["reference"] = {**info, "is_gnss_input": bool(is_input)}
    if is_input:
        meta["warnings"] = [*list(meta.get("warnings") or []),
                            f"the reference {info['file']} is the drive's GNSS input: the "
                            "errors measure how closely the estimates follow it, not their "
                            "accuracy without it (vnav-graph holdout --truth scores withheld "
                            "windows against it)"]
    return drive.replace(truth=traj, meta=meta)


def attach_reference(drive: Drive, truth: str | Path, drive_path: str | Path | None,
                     column_map: str | Path | None = None, height_datum: str | None = None,
                     fix_only: bool = False) -> Drive:
    """``run/holdout --truth``: the drive with the reference in ``truth`` as its truth. The
    column map (``column_map``, or the one inside the drive's folder) gives the reference's
    ``[truth]`` height datum and ``fix_only`` (when ``[truth] file`` is this file or not
    given), the lever arm ``lever_arms.truth`` and the geoid separation; ``height_datum``
    (``--height-datum``) wins over the map's."""
    from .readers.column_map import find_map, lever, load_map

    doc: dict[str, Any] = {}
    if column_map is None and drive_path is not None and Path(drive_path).is_dir():
        column_map = find_map(drive_path)
    if column_map is not None:
        doc = load_map(column_map)
    tr = doc.get("truth") or {}
    if tr.get("file") and Path(tr["file"]).name != Path(truth).name:
        tr = {}  # the map's [truth] describes another file
    traj, info = load_reference(
        truth, drive, height_datum or tr.get("height_datum"), lever(doc, "truth"),
        doc.get("geoid_separation_m"), fix_only or bool(tr.get("fix_only", False)))
    gfile = drive.meta.get("gnss_file")
    same = (gfile is not None and drive_path is not None and Path(drive_path).is_dir()
            and (Path(drive_path) / str(gfile)).resolve() == Path(truth).resolve())
    return with_reference(drive, traj, info, same)


def load_scored(path: str | Path, column_map: str | Path | None = None,
                height_datum: str | None = None, truth: str | Path | None = None,
                fix_only: bool = False) -> Drive:
    """``vnav-graph run/holdout``'s drive: ``io.load_drive`` with the column map and, with
    ``truth``, the reference as its truth (:func:`attach_reference`)."""
    from . import load_drive

    drive = load_drive(path, column_map=column_map, height_datum=height_datum)
    if truth is None:
        if fix_only:
            raise ValueError("--truth-fix-only needs --truth FILE")
        return drive
    return attach_reference(drive, truth, path, column_map, height_datum, fix_only)
