"""Input sanity checks: units, axes, time stamps and hostile streams, before any estimator.

:func:`check_drive` runs on every Drive that :func:`vnav_graph.io.load_drive` returns (logs and
``.npz`` files alike; simulated drives do not pass through it). Each finding is either

- **repaired**: the stream is rebuilt, ``meta["repaired"][stream][reason] = count`` (the
  readers' convention) and one line is appended to ``meta["warnings"]``; or
- **rejected**: ``ValueError`` with one line naming the stream and the likely cause; or
- **reported**: a ``meta["warnings"]`` line only, where no repair is safe.

Checks, with the evidence each uses
-----------------------------------
- reader drops: per stream, the fraction of records a reader dropped (``meta["dropped"]``).
  Above ``WARN_DROP_FRACTION`` a warning names the reasons; above ``REFUSE_DROP_FRACTION``
  the drive is refused (shuffled IMU stamps once kept 11 of 6,223 samples and ran). Reasons
  that mean a damaged file (``CORRUPTION_WORDS``: malformed rows, non-finite values, stamps
  going backwards, truncation) are reported at any count.
- time-stamp units: the IMU's median sample interval. Beyond ``MAX_IMU_DT_S`` the stamps are
  almost surely milliseconds read as seconds; below ``MIN_IMU_DT_S`` (over 20 kHz),
  microseconds read as nanoseconds. Both are refused: the scale cannot be told from the
  interval alone (a 1 kHz IMU in ms looks like a 1 Hz one in s).
- truth: a truth trajectory with NaN/inf is dropped (the drive is then scored as a real log).
- IMU units, axes and hostile samples (specific-force magnitude, gyro units, axes against
  each other, gravity axis, held samples, mean specific force, clipping): see
  :mod:`vnav_graph.io.imu_checks`.
- baro: constant for the whole drive → barometer dropped; altitude in feet (slope ≈ 3.28
  against GNSS height) → ÷ 3.28084 and re-aligned; single-sample jumps larger than
  ``BARO_STEP_M`` + 30 m/s·Δt → spikes removed, persistent ones → level shift removed.
- GNSS: height identical in every fix (not logged) → vertical σ set to ``UNUSED_SD_M``;
  fixes that jump away faster than ``GNSS_JUMP_SPEED`` and come back: an isolated fix, or
  a horizontal block of them within ``GNSS_GLITCH_MAX_S`` (``vnav_graph.nav.gnss_glitch``)
  → dropped; other impossible steps are reported (heights are gated by the estimators).
- GNSS height unit: its climb against the baro's and against its own vertical velocity;
  feet → × 0.3048, another scale → refused (:mod:`vnav_graph.io.height_units`).
- coverage: a missing GNSS or baro stream, logging gaps (``GAP_WARN_S``) and a stream that
  ends well before the others (a truncated file) are reported.
- specific force: an accelerometer that reads less than gravity and the baro's climb need
  (``sensors.model.specific_force_deficit``, logs without an IMU spec) is reported with the
  bias walk the estimators then give it.
- magnetometer (optional): reader drops, the time-unit comparison with the IMU, gaps and a
  stream cut short, as for baro. Its absence is not reported (most drives have none; the
  reader's notes say why).
"""

from __future__ import annotations

from collections.abc import Callable
from types import MappingProxyType
from typing import Any

import numpy as np

from ..nav.gnss_glitch import MAX_GLITCH_S, MAX_SPEED, glitch_mask
from ..types import Drive
from ..types.streams import BaroStream, BoolArray, FloatArray, GnssStream
from .findings import Findings, reject
from .height_units import check_gnss_height_units
from .imu_checks import IMU_CHECKS

WARN_DROP_FRACTION = 0.05
REFUSE_DROP_FRACTION = 0.90
MAX_IMU_DT_S = 2.0  # a median IMU interval above this: ms stamps read as s
MIN_IMU_DT_S = 5e-5  # below this (> 20 kHz): µs stamps read as ns
SLOW_IMU_DT_S = 0.2  # under 5 Hz without averaged_1s: reported
GAP_WARN_S = {"imu": 1.0, "gnss": 10.0, "baro": 5.0, "mag": 5.0}  # gaps reported above [s]
BARO_STEP_M = 30.0
BARO_STEP_RATE = 30.0  # m/s: vertical speed no vehicle of this package exceeds
FEET = 0.3048
UNUSED_SD_M = 1.0e4
GNSS_JUMP_SPEED = MAX_SPEED  # m/s between consecutive fixes (nav.gnss_glitch)
GNSS_GLITCH_MAX_S = MAX_GLITCH_S  # longest away-and-back glitch dropped [s]


# ---------------------------------------------------------------------------- drops
def _dropped_counts(meta: dict[str, Any]) -> dict[str, dict[str, int]]:
    d = meta.get("dropped")
    if not isinstance(d, dict):
        return {}
    out: dict[str, dict[str, int]] = {}
    for s, reasons in d.items():
        if isinstance(reasons, dict):
            out[str(s)] = {str(r): int(c) for r, c in reasons.items()
                           if isinstance(c, (int, float)) and c > 0}
    return out


# Drop reasons that mean the file itself is damaged: warned about at any count. Other reasons
# (no 3-D fix, duplicated stamps, stale phone fixes) are routine and warned above
# WARN_DROP_FRACTION.
CORRUPTION_WORDS = ("malformed", "finite", "physical range", "not increasing", "truncated",
                    "implausible", "invalid pressure", "missing", "corrupt", "field count")


def _check_drops(drive: Drive, f: Findings) -> None:
    kept = {"imu": len(drive.imu), "gyro": len(drive.imu),
            "gnss": 0 if drive.gnss is None else len(drive.gnss),
            "baro": 0 if drive.baro is None else len(drive.baro),
            "rows": len(drive.imu)}
    if drive.mag is not None:  # no MagStream (e.g. an all-zero MAG log): the notes say why
        kept["mag"] = len(drive.mag)
    for stream, reasons in _dropped_counts(f.meta).items():
        n = sum(reasons.values())
        if not n:
            continue
        what = "; ".join(f"{c} {r}" for r, c in sorted(reasons.items(), key=lambda x: -x[1]))
        if stream == "log":
            f.warn(f"log: {what}")
            continue
        if stream not in kept:
            continue
        frac = n / (n + kept[stream])
        if frac > REFUSE_DROP_FRACTION and stream in ("imu", "gyro", "rows"):
            raise reject(stream, f"reader dropped {n} of {n + kept[stream]} records ({what}): "
                         "the log is unusable (shuffled, corrupt or duplicated time stamps?)")
        damaged = [r for r in reasons if any(w in r for w in CORRUPTION_WORDS)]
        if frac > REFUSE_DROP_FRACTION:
            f.warn(f"{stream}: reader dropped {n} of {n + kept[stream]} records ({what}); "
                   "what is left is unreliable")
        elif frac > WARN_DROP_FRACTION or damaged:
            f.warn(f"{stream}: reader dropped {n} of {n + kept[stream]} records "
                   f"({100 * frac:.1f} %: {what})")


# ---------------------------------------------------------------------------- time
def _check_time_units(drive: Drive, f: Findings) -> None:
    dt = float(np.median(np.diff(drive.imu.t))) if len(drive.imu) > 1 else 0.0
    if dt > MAX_IMU_DT_S:
        raise reject("imu", f"median sample interval {dt:.3g} s: time stamps in milliseconds "
                     "read as seconds?")
    if 0 < dt < MIN_IMU_DT_S:
        raise reject("imu", f"median sample interval {dt:.3g} s ({1e-3 / dt:.0f} kHz): time "
                     "stamps in microseconds read as nanoseconds?")
    if dt > SLOW_IMU_DT_S and not f.meta.get("averaged_1s"):
        f.warn(f"imu: {1 / dt:.2f} Hz sample rate is too slow for strapdown inertial navigation "
               "(time stamps in the wrong unit, or averaged data?)")
    for name, s in (("gnss", drive.gnss), ("baro", drive.baro), ("mag", drive.mag)):
        if s is None or len(s) < 3:
            continue
        sdt = float(np.median(np.diff(s.t)))
        if sdt > 100.0 * max(dt, 0.01) and sdt > 30.0:
            f.warn(f"{name}: median interval {sdt:.3g} s against {dt:.3g} s for the IMU "
                   "(time-stamp unit differs between streams?)")


def _check_coverage(drive: Drive, f: Findings) -> None:
    """Missing streams, logging gaps and streams that end early (a truncated file)."""
    for name in ("gnss", "baro"):
        if getattr(drive, name) is None:
            f.warn(f"{name}: no usable {name} data in the input (absent from the file, or "
                   "every record rejected): estimators run without it")
    streams = (("imu", drive.imu), ("gnss", drive.gnss), ("baro", drive.baro),
               ("mag", drive.mag))
    spans = {n: (s.t[0], s.t[-1]) for n, s in streams if s is not None}
    t0 = min(a for a, _ in spans.values())
    t1 = max(b for _, b in spans.values())
    total = t1 - t0
    for n, (a, b) in spans.items():
        missing = (a - t0) + (t1 - b)
        if total > 0 and missing > max(GAP_WARN_S[n], 0.1 * total):
            f.warn(f"{n}: covers {a - t0:.0f}..{b - t0:.0f} s of the drive's {total:.0f} s "
                   "(stream cut short: file truncated or a logger stopped?)")
    for n, s in streams:
        if s is None or len(s) < 3:
            continue
        dt = np.diff(s.t)
        gap = dt > max(GAP_WARN_S[n], 5.0 * float(np.median(dt)))
        if gap.any():
            k = int(np.argmax(dt))
            f.warn(f"{n}: {int(gap.sum())} logging gap(s) longer than {GAP_WARN_S[n]:g} s, the "
                   f"longest {dt[k]:.1f} s at t = {s.t[k]:.1f} s (bridged by the estimators)")


# ---------------------------------------------------------------------------- baro
def _baro_from_alt(b: BaroStream, alt: FloatArray, keep: BoolArray | None = None
                   ) -> BaroStream:
    """The baro stream with a repaired altitude; the raw pressure is dropped so that no
    stream carries a pressure that disagrees with its altitude (estimators use altitude)."""
    if keep is None:
        keep = np.ones(len(b), dtype=bool)
    return BaroStream(b.t[keep], None, alt[keep], b.spec)


def _check_baro(drive: Drive, f: Findings) -> Drive:
    b = drive.baro
    if b is None or len(b) < 5:
        return drive
    alt = np.asarray(b.altitude, dtype=float)
    if float(np.ptp(alt)) == 0.0:
        f.repair("baro", "constant for the whole drive: barometer not used", len(b),
                 f"baro: the same value in all {len(b)} samples (sensor stuck or not logged): "
                 "barometer not used")
        return drive.replace(baro=None)
    # steps: no vehicle climbs BARO_STEP_RATE m/s; a jump beyond it is a data error
    d = np.diff(alt)
    lim = BARO_STEP_M + BARO_STEP_RATE * np.diff(b.t)
    jumps = np.flatnonzero(np.abs(d) > lim)
    if jumps.size:
        keep = np.ones(len(b), dtype=bool)
        shift = np.zeros(len(b))
        n_spike = n_shift = 0
        used: set[int] = set()
        for i in jumps:
            if i in used:
                continue
            back = [j for j in jumps if i < j <= i + 20 and j not in used
                    and abs(d[j] + d[i]) < 0.3 * abs(d[i])]
            if back:  # out and back: the samples in between are a spike
                j = back[0]
                keep[i + 1:j + 1] = False
                used.update((i, j))
                n_spike += 1
            else:  # a level shift: later samples keep the new offset
                shift[i + 1:] -= d[i]
                used.add(i)
                n_shift += 1
        alt = alt + shift
        parts = []
        if n_spike:
            parts.append(f"{n_spike} spike(s) removed ({int((~keep).sum())} samples)")
        if n_shift:
            parts.append(f"{n_shift} level shift(s) undone")
        big = float(np.max(np.abs(d[jumps])))
        f.repair("baro", "jumps beyond any climb rate removed", int(jumps.size),
                 f"baro: {jumps.size} jump(s) between consecutive samples up to {big:.0f} m "
                 f"(faster than {BARO_STEP_RATE:.0f} m/s): {', '.join(parts)}")
        b = _baro_from_alt(b, alt, keep)
        alt = alt[keep]
        drive = drive.replace(baro=b)
    g = drive.gnss
    if g is not None and len(g) >= 10:
        inside = (b.t >= g.t[0]) & (b.t <= g.t[-1])
        if inside.sum() >= 10:
            hg = np.interp(b.t[inside], g.t, g.lla[:, 2])
            ha = alt[inside]
            if np.ptp(hg) >= 20.0 and np.ptp(ha) >= 20.0:
                x, y = hg - np.median(hg), ha - np.median(ha)
                slope = float(np.sum(x * y) / np.sum(x * x))
                if 1 / FEET - 0.5 <= slope <= 1 / FEET + 0.5:
                    new = (alt - np.median(alt[inside])) * FEET + np.median(hg)
                    f.repair("baro", "altitude in feet: multiplied by 0.3048", len(b),
                             f"baro: altitude rises {slope:.2f}x as fast as GNSS height: feet, "
                             "not metres; converted (x 0.3048, datum re-aligned to GNSS)")
                    drive = drive.replace(baro=_baro_from_alt(b, new))
                elif slope < 0:
                    f.warn(f"baro: altitude falls where GNSS height rises (slope {slope:.2f}): "
                           "sign inverted (depth or down instead of altitude?)")
    return drive


# ---------------------------------------------------------------------------- GNSS
def _check_gnss(drive: Drive, f: Findings) -> Drive:
    g = drive.gnss
    if g is None or len(g) < 3:
        return drive
    if len(g) >= 10 and float(np.ptp(g.lla[:, 2])) == 0.0:
        sd = g.pos_sd.copy()
        sd[:, 2] = UNUSED_SD_M
        f.repair("gnss", "height identical in every fix: vertical sigma set to 1e4 m",
                 len(g), f"gnss: height is {g.lla[0, 2]:g} m in all {len(g)} fixes (not "
                 "logged): GNSS height not used (baro datum and holdout scores are then "
                 "meaningless)")
        g = GnssStream(g.t, g.lla, sd, g.vel_n, g.vel_sd, g.lever_arm_b, g.spec)
        drive = drive.replace(gnss=g)
    from ..geo.frames import lla_to_ned

    ned = lla_to_ned(g.lla, g.lla[0])
    step = np.linalg.norm(np.diff(ned, axis=0), axis=1)
    fast = step / np.diff(g.t) > GNSS_JUMP_SPEED
    # fixes that jump away and come back (one fix or a block): nav.gnss_glitch
    # (horizontal: any length; 3-D: isolated spikes only, see its docstring)
    glitch = (glitch_mask(g.t, ned[:, :2], GNSS_JUMP_SPEED, GNSS_GLITCH_MAX_S)
              | glitch_mask(g.t, ned, GNSS_JUMP_SPEED, GNSS_GLITCH_MAX_S, max_fixes=1))
    if glitch.any():
        n = int(glitch.sum())
        k = np.flatnonzero(glitch)
        # each glitch fix against the last good fix before it (a glitch never starts a stream)
        before = np.maximum.accumulate(np.where(glitch, 0, np.arange(len(g))))[k]
        big = float(np.max(np.linalg.norm(ned[k] - ned[before], axis=1)))
        runs = int(np.sum(np.diff(np.r_[0, glitch.astype(np.int8)]) == 1))
        f.repair("gnss", "position glitch (away and back) dropped", n,
                 f"gnss: {n} fix(es) in {runs} glitch(es) jumping up to {big:.0f} m away and "
                 f"back (faster than {GNSS_JUMP_SPEED:.0f} m/s, the longest away for "
                 f"{_longest_away_s(g.t, glitch):.1f} s): dropped")
        drive = drive.replace(gnss=g.select(~glitch))
    elif fast.any():
        f.warn(f"gnss: {int(fast.sum())} position step(s) faster than "
               f"{GNSS_JUMP_SPEED:.0f} m/s between consecutive fixes (glitches?)")
    return drive


def _longest_away_s(t: FloatArray, mask: BoolArray) -> float:
    """The longest time a run of True entries of ``mask`` kept the stream away: from the last
    False entry before the run to the first after it (a glitch never starts or ends a
    stream)."""
    d = np.diff(np.r_[0, mask.astype(np.int8), 0])
    first, end = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
    before, after = np.maximum(first - 1, 0), np.minimum(end, t.size - 1)
    return float(np.max(t[after] - t[before])) if first.size else 0.0


def _check_truth(drive: Drive, f: Findings) -> Drive:
    tr = drive.truth
    if tr is None:
        return drive
    arrs = [tr.lla, tr.vel_n] + [a for a in (tr.q_nb, tr.bias_baro) if a is not None]
    if all(np.all(np.isfinite(a)) for a in arrs):
        return drive
    f.repair("truth", "non-finite values: truth dropped", 1,
             "truth: contains NaN or inf; truth dropped, the drive is scored as a real log")
    f.meta["source"] = "log"
    return drive.replace(truth=None, baro_truth=None)


def _check_specific_force(drive: Drive, f: Findings) -> None:
    """An accelerometer that reads less specific force than gravity and the baro's climb need
    (``sensors.model.specific_force_deficit``): reported, with what the estimators do about
    it. Only where the IMU model is inferred from the data (a log without a spec)."""
    from ..config import ImuSpec
    from ..geo.earth import gravity
    from ..sensors import model as sm

    i = drive.imu
    if isinstance(i.spec, ImuSpec) or len(i) < 10:
        return
    g0 = float(gravity(float(drive.origin_lla[0]), float(drive.origin_lla[2])))
    d, walk = sm.rectifying_walk(i, drive.baro, g0)
    if d is None or not np.isfinite(d):
        return
    f.diag["specific_force_deficit_mps2"] = d
    if walk > 0:
        f.warn(f"imu: the accelerometer reads less specific force than gravity and the baro's "
               f"climb need ({sm.DEFICIT_QUANTILE:g}th percentile {d:+.2f} m/s² over "
               f"{sm.DEFICIT_WINDOW_S:g} s windows: vibration rectification or clipping); the "
               f"estimators give its bias a random walk of {walk:.3g} m/s²/√s")


CHECKS: tuple[Callable[[Drive, Findings], Drive | None], ...] = (
    _check_drops, _check_time_units, _check_truth, *IMU_CHECKS, _check_baro,
    check_gnss_height_units, _check_gnss, _check_coverage, _check_specific_force,
)


def check_drive(drive: Drive) -> Drive:
    """Run every check (module docstring) on ``drive``; repaired Drive or ValueError.

    ``meta["warnings"]`` (list of one-line strings) and ``meta["repaired"]`` (stream → reason →
    count) are extended when something is found; ``meta["sanity"]`` holds the measured
    statistics; everything else in ``meta`` is kept.
    """
    f = Findings(dict(drive.meta))
    for check in CHECKS:
        out = check(drive, f)
        if isinstance(out, Drive):
            drive = out
    meta = dict(f.meta)
    meta["sanity"] = f.diag
    if f.warnings:
        meta["warnings"] = f.warnings
    if f.repaired:
        meta["repaired"] = f.repaired
    return drive.replace(meta=MappingProxyType(meta))
