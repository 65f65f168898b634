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
- specific-force magnitude: the median |f| over the drive is g for any vehicle that does not
  stay in free fall. ``≈ 1`` → g units (× g0); ``≈ g0²`` → scaled by g0 twice (÷ g0); any
  other value outside [6, 14] m/s² is refused.
- gyro units: over 1 s block means of |ω|, a busiest second above ``DEG_BUSY`` rad/s (458°/s
  held for a second) or a quietest second above ``DEG_QUIET`` rad/s (never below 29°/s) is a
  gyro in deg/s (→ × π/180). Measured on the shared logs in rad/s: busiest ≤ 3.2, quietest
  ≤ 0.043; in deg/s: busiest ≥ 28 for every log that moves.
- axes against each other, ground vehicles (one dominant rotation axis, E[ω̄ω̄ᵀ] eigenvalue
  ratio ≥ ``GROUND_AXIS_RATIO``): a car turns about the vertical, so its principal rotation
  axis more than 45° from the mean specific force means accelerometer and gyro columns are
  swapped against each other (refused; cars measure 0.4-3°, swapped 87-90°). A mirror (two
  accelerometer columns swapped, gravity unmoved) is caught by :func:`handedness`
  (centripetal force on the right in right turns).
- gravity axis: the mean specific force should point along −z_b (FRD, level mounting); more
  than ``MAX_TILT_DEG`` away is refused (swapped axes, or an IMU mounted on its side).
- held samples: runs of bit-identical IMU samples for ``HELD_MIN_S`` are removed (a stuck
  sensor or a forward-filled gap), so the estimators bridge them as a gap.
- a 1 s mean specific force more than 3 g from g (impact, corrupt values, or clipping
  averaged away in 1 Hz data): those seconds are removed and bridged as a gap.
- IMU clipping: ≥ ``CLIP_MIN_SAMPLES`` samples on one axis pinned within
  ``CLIP_REL_TOL`` of that axis's extreme |value| (≥ 2 g for the accelerometer, the smallest
  full-scale range in use) are clipped. Handled as PX4 EKF2 handles a clipped delta velocity
  it cannot trust: each clipping episode (clipped samples closer than ``CLIP_MERGE_S``,
  padded by ``CLIP_PAD_S``) is removed, so every estimator bridges it as an IMU gap (inflated
  process noise, re-levelling). Counted in ``meta["clipping"]``.
- baro: constant for the whole drive → barometer dropped; altitude in feet (slope ≈ 3.28
  against GNSS height) → ÷ 3.28084 and re-aligned; single-sample jumps larger than
  ``BARO_STEP_M`` + 30 m/s·Δt → spikes removed, persistent ones → level shift removed.
- GNSS: height identical in every fix (not logged) → vertical σ set to ``UNUSED_SD_M``;
  isolated fixes jumping faster than ``GNSS_JUMP_SPEED`` → dropped.
- coverage: a missing GNSS or baro stream, logging gaps (``GAP_WARN_S``) and a stream that
  ends well before the others (a truncated file) are reported.
"""

from __future__ import annotations

from collections.abc import Callable
from types import MappingProxyType
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..geo.earth import G0
from ..types import BaroStream, Drive, GnssStream, ImuStream

FloatArray = NDArray[np.float64]

WARN_DROP_FRACTION = 0.05
REFUSE_DROP_FRACTION = 0.90
MAX_IMU_DT_S = 2.0  # a median IMU interval above this: ms stamps read as s
MIN_IMU_DT_S = 5e-5  # below this (> 20 kHz): µs stamps read as ns
SLOW_IMU_DT_S = 0.2  # under 5 Hz without averaged_1s: reported
ACCEL_OK = (6.0, 14.0)  # median |f| [m/s²] accepted as "g in m/s²"
ACCEL_IN_G = (0.6, 1.4)
ACCEL_TWICE = (60.0, 140.0)
DEG_BUSY = 8.0  # rad/s: 99.9th pct of 1 s mean |ω| above this (458 deg/s held 1 s) → deg/s
DEG_QUIET = 0.5  # rad/s: even the quietest seconds turn at 29 deg/s → deg/s
GROUND_AXIS_RATIO = 10.0  # rotation mostly about one axis (cars: 20-120; drones: < 5; skier: 5-15)
GROUND_BUSY = 1.5  # rad/s: a ground vehicle's 1 s mean rates stay below this
GROUND_AXIS_RMS = 0.02  # rad/s: enough turning to judge the axis
MAX_TILT_DEG = 60.0
CLIP_MIN_SAMPLES = 3
CLIP_REL_TOL = 0.002
CLIP_MIN_ACCEL = 2.0 * G0  # smallest accelerometer full-scale range [m/s²]
CLIP_MERGE_S = 0.5  # clipped samples closer than this belong to one episode [s]
CLIP_PAD_S = 0.05  # removed on each side of an episode [s]
CLIP_MIN_GYRO = 4.0  # rad/s (≈ 250 deg/s, the smallest common gyro range)
HELD_MIN_SAMPLES = 5
HELD_MIN_S = 1.0
GAP_WARN_S = {"imu": 1.0, "gnss": 10.0, "baro": 5.0}  # gaps reported above these [s]
MAX_MEAN_SPECIFIC_FORCE = 3.0 * G0  # 1 s mean |f| beyond g ± this: reported
BARO_STEP_M = 30.0
BARO_STEP_RATE = 30.0  # m/s: vertical speed no vehicle of this package exceeds
FEET = 0.3048
UNUSED_SD_M = 1.0e4
GNSS_JUMP_SPEED = 150.0  # m/s between consecutive fixes, there and back


class _Findings:
    def __init__(self, meta: dict[str, Any]) -> None:
        self.meta = meta
        self.diag: dict[str, Any] = {}  # measured statistics → meta["sanity"]
        self.warnings: list[str] = [str(w) for w in (meta.get("warnings") or [])]
        rep = meta.get("repaired")
        self.repaired: dict[str, dict[str, int]] = (
            {k: dict(v) for k, v in rep.items() if isinstance(v, dict)}
            if isinstance(rep, dict) else {})

    def repair(self, stream: str, reason: str, count: int, warning: str) -> None:
        d = self.repaired.setdefault(stream, {})
        d[reason] = d.get(reason, 0) + int(count)
        self.warnings.append(warning)

    def warn(self, warning: str) -> None:
        self.warnings.append(warning)


def _reject(stream: str, why: str) -> ValueError:
    return ValueError(f"{stream}: {why}")


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


def _check_drops(drive: Drive, f: _Findings) -> None:
    kept = {"imu": len(drive.imu), "gyro": len(drive.imu),
            "gnss": 0 if drive.gnss is None else len(drive.gnss),
            "baro": 0 if drive.baro is None else len(drive.baro),
            "rows": len(drive.imu)}
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
            raise _reject(stream, f"reader dropped {n} of {n + kept[stream]} records ({what}): "
                          "the log is unusable (shuffled, corrupt or duplicated time stamps?)")
        damaged = [r for r in reasons if any(w in r for w in CORRUPTION_WORDS)]
        if frac > REFUSE_DROP_FRACTION:
            f.warn(f"{stream}: reader dropped {n} of {n + kept[stream]} records ({what}); "
                   "what is left is unreliable")
        elif frac > WARN_DROP_FRACTION or damaged:
            f.warn(f"{stream}: reader dropped {n} of {n + kept[stream]} records "
                   f"({100 * frac:.1f} %: {what})")


# ---------------------------------------------------------------------------- time
def _check_time_units(drive: Drive, f: _Findings) -> None:
    dt = float(np.median(np.diff(drive.imu.t))) if len(drive.imu) > 1 else 0.0
    if dt > MAX_IMU_DT_S:
        raise _reject("imu", f"median sample interval {dt:.3g} s: time stamps in milliseconds "
                      "read as seconds?")
    if 0 < dt < MIN_IMU_DT_S:
        raise _reject("imu", f"median sample interval {dt:.3g} s ({1e-3 / dt:.0f} kHz): time "
                      "stamps in microseconds read as nanoseconds?")
    if dt > SLOW_IMU_DT_S and not f.meta.get("averaged_1s"):
        f.warn(f"imu: {1 / dt:.2f} Hz sample rate is too slow for strapdown inertial navigation "
               "(time stamps in the wrong unit, or averaged data?)")
    for name, s in (("gnss", drive.gnss), ("baro", drive.baro)):
        if s is None or len(s) < 3:
            continue
        sdt = float(np.median(np.diff(s.t)))
        if sdt > 100.0 * max(dt, 0.01) and sdt > 30.0:
            f.warn(f"{name}: median interval {sdt:.3g} s against {dt:.3g} s for the IMU "
                   "(time-stamp unit differs between streams?)")


def _check_coverage(drive: Drive, f: _Findings) -> None:
    """Missing streams, logging gaps and streams that end early (a truncated file)."""
    for name in ("gnss", "baro"):
        if getattr(drive, name) is None:
            f.warn(f"{name}: no usable {name} data in the input (absent from the file, or "
                   "every record rejected): estimators run without it")
    spans = {n: (s.t[0], s.t[-1]) for n, s in (("imu", drive.imu), ("gnss", drive.gnss),
                                              ("baro", drive.baro)) if s is not None}
    t0 = min(a for a, _ in spans.values())
    t1 = max(b for _, b in spans.values())
    total = t1 - t0
    for n, (a, b) in spans.items():
        missing = (a - t0) + (t1 - b)
        if total > 0 and missing > max(GAP_WARN_S[n], 0.1 * total):
            f.warn(f"{n}: covers {a - t0:.0f}..{b - t0:.0f} s of the drive's {total:.0f} s "
                   "(stream cut short: file truncated or a logger stopped?)")
    for n, s in (("imu", drive.imu), ("gnss", drive.gnss), ("baro", drive.baro)):
        if s is None or len(s) < 3:
            continue
        dt = np.diff(s.t)
        gap = dt > max(GAP_WARN_S[n], 5.0 * float(np.median(dt)))
        if gap.any():
            k = int(np.argmax(dt))
            f.warn(f"{n}: {int(gap.sum())} logging gap(s) longer than {GAP_WARN_S[n]:g} s, the "
                   f"longest {dt[k]:.1f} s at t = {s.t[k]:.1f} s (bridged by the estimators)")


# ---------------------------------------------------------------------------- IMU
def _block_means(t: FloatArray, x: FloatArray, block_s: float) -> tuple[FloatArray, FloatArray]:
    # np.unique, not bincount over the raw index: one stamp far in the future (a flipped
    # bit) must not allocate an array as long as the time it spans
    _, k = np.unique(np.floor((t - t[0]) / block_s), return_inverse=True)
    n = np.bincount(k)
    tm = np.bincount(k, weights=t) / n
    xm = np.column_stack([np.bincount(k, weights=x[:, j]) / n for j in range(x.shape[1])])
    return tm, xm


def rotation_stats(t: FloatArray, gyro: FloatArray, accel: FloatArray) -> dict[str, float]:
    """Statistics of 1 s block means of the gyro used by the unit and axis checks.

    ``quiet``: 2nd percentile of |ω̄| [rad/s] (the quietest seconds); ``busy``: 99.9th
    percentile; ``axis_ratio``: first over second eigenvalue of E[ω̄ ω̄ᵀ]; ``axis_rms``:
    sqrt of the first [rad/s]; ``axis_angle_deg``: angle between that principal rotation axis
    and the mean specific force.
    """
    _, wm = _block_means(t, gyro, 1.0)
    n = np.linalg.norm(wm, axis=1)
    lam, vec = np.linalg.eigh(wm.T @ wm / max(len(wm), 1))
    m = accel.mean(axis=0)
    m = m / max(float(np.linalg.norm(m)), 1e-12)
    ang = float(np.degrees(np.arccos(min(1.0, abs(float(vec[:, -1] @ m))))))
    return {"quiet": float(np.percentile(n, 2)), "busy": float(np.percentile(n, 99.9)),
            "axis_ratio": float(lam[-1] / max(lam[-2], 1e-30)),
            "axis_rms": float(np.sqrt(max(lam[-1], 0.0))), "axis_angle_deg": ang,
            "blocks": float(len(wm))}


def _imu(drive: Drive, gyro: FloatArray, accel: FloatArray,
         keep: NDArray[np.bool_] | None = None) -> ImuStream:
    i = drive.imu
    if keep is None:
        return ImuStream(i.t, gyro, accel, i.spec)
    return ImuStream(i.t[keep], gyro[keep], accel[keep], i.spec)


def _check_accel_magnitude(drive: Drive, f: _Findings) -> Drive:
    mag = float(np.median(np.linalg.norm(drive.imu.accel_b, axis=1)))
    if ACCEL_OK[0] <= mag <= ACCEL_OK[1]:
        return drive
    if ACCEL_IN_G[0] <= mag <= ACCEL_IN_G[1]:
        f.repair("imu", "specific force in g: multiplied by 9.80665", len(drive.imu),
                 f"imu: median |specific force| {mag:.3g} is g units, not m/s^2: converted "
                 "(x 9.80665)")
        return drive.replace(imu=_imu(drive, drive.imu.gyro_b, drive.imu.accel_b * G0))
    if ACCEL_TWICE[0] <= mag <= ACCEL_TWICE[1]:
        f.repair("imu", "specific force multiplied by g twice: divided by 9.80665",
                 len(drive.imu), f"imu: median |specific force| {mag:.4g} m/s^2 is about g^2: "
                 "converted twice to m/s^2; divided by 9.80665")
        return drive.replace(imu=_imu(drive, drive.imu.gyro_b, drive.imu.accel_b / G0))
    raise _reject("imu", f"median |specific force| {mag:.3g} m/s^2 is not about g "
                  "(9.8): wrong unit, gravity removed, or not an accelerometer")


def _check_rotation(drive: Drive, f: _Findings) -> Drive:
    i = drive.imu
    st = rotation_stats(i.t, i.gyro_b, i.accel_b)
    f.diag["imu_rotation_stats"] = st
    if st["blocks"] < 5:
        return drive
    if st["busy"] > DEG_BUSY or st["quiet"] > DEG_QUIET:
        f.repair("imu", "gyro in deg/s: multiplied by pi/180", len(i),
                 f"imu: gyro rates look like deg/s (quietest second {st['quiet']:.2g}, "
                 f"busiest {st['busy']:.3g} 'rad/s'): converted (x pi/180)")
        return drive.replace(imu=_imu(drive, i.gyro_b * (np.pi / 180.0), i.accel_b))
    ground = (st["axis_ratio"] >= GROUND_AXIS_RATIO and st["busy"] < GROUND_BUSY
              and st["axis_rms"] > GROUND_AXIS_RMS)
    if ground and st["axis_angle_deg"] > 45.0:
        raise _reject("imu", f"the vehicle turns about an axis {st['axis_angle_deg']:.0f} deg "
                      "from gravity (a ground vehicle turns about the vertical): accelerometer "
                      "and gyro axes swapped against each other?")
    return drive


def handedness(drive: Drive) -> dict[str, float] | None:
    """Is the accelerometer frame right-handed with the gyro's (ground vehicles)?

    With d the down axis (−mean specific force), the horizontal specific force of a car is
    ``f_h ≈ x̂·dv/dt + ŷ·v·r`` (forward acceleration, centripetal), r = ω·d the yaw rate, v the
    GNSS speed. Least squares on 1 s block means gives the vectors e ≈ x̂ and c ≈ ŷ; in an FRD
    frame ŷ = d × x̂, so ``h = (d × e)·c / (|e||c|)`` is +1. Two accelerometer columns swapped
    (a mirror against the gyro, gravity possibly unaffected) give −1. None without a ground
    vehicle's evidence (GNSS, speed above 3 m/s, turns and speed changes).
    """
    g = drive.gnss
    if g is None or len(g) < 30:
        return None
    i = drive.imu
    tb, am = _block_means(i.t, i.accel_b, 1.0)
    _, wm = _block_means(i.t, i.gyro_b, 1.0)
    d = -i.accel_b.mean(axis=0)
    d = d / max(float(np.linalg.norm(d)), 1e-12)
    from ..geo.frames import lla_to_ned

    ned = lla_to_ned(g.lla, g.lla[0])
    if g.vel_n is not None:
        v_ne = g.vel_n[:, :2]
    else:
        v_ne = np.column_stack([np.gradient(ned[:, 0], g.t), np.gradient(ned[:, 1], g.t)])
    speed = np.hypot(v_ne[:, 0], v_ne[:, 1])
    inside = (tb > g.t[0]) & (tb < g.t[-1])
    if inside.sum() < 30:
        return None
    tb, am, wm = tb[inside], am[inside], wm[inside]
    v = np.interp(tb, g.t, speed)
    dv = np.gradient(v, tb)
    r = wm @ d
    fh = am - np.outer(am @ d, d)
    ok = v > 3.0
    if ok.sum() < 30:
        return None
    x = np.column_stack([dv[ok], v[ok] * r[ok]])
    if np.linalg.cond(x) > 1e3 or np.std(x[:, 1]) < 0.3:
        return None
    coef, *_ = np.linalg.lstsq(x, fh[ok], rcond=None)
    e, c = coef[0], coef[1]
    ne, nc = float(np.linalg.norm(e)), float(np.linalg.norm(c))
    if ne < 1e-6 or nc < 1e-6:
        return None
    return {"h": float(np.cross(d, e) @ c / (ne * nc)), "forward_gain": ne,
            "centripetal_gain": nc, "blocks": float(ok.sum())}


def _check_handedness(drive: Drive, f: _Findings) -> None:
    st = f.diag.get("imu_rotation_stats") or {}
    ground = (st.get("axis_ratio", 0.0) >= GROUND_AXIS_RATIO
              and st.get("busy", np.inf) < GROUND_BUSY
              and st.get("axis_rms", 0.0) > GROUND_AXIS_RMS)
    if not ground:
        return
    hd = handedness(drive)
    f.diag["imu_handedness"] = hd
    if hd is None:
        return
    if hd["h"] < -0.5 and hd["centripetal_gain"] > 0.4 and hd["forward_gain"] > 0.4:
        raise _reject("imu", f"accelerometer axes are mirrored against the gyro (centripetal "
                      f"force on the left in right turns; handedness {hd['h']:.2f}): two "
                      "accelerometer columns swapped?")


def _check_held_samples(drive: Drive, f: _Findings) -> Drive:
    """Runs of bit-identical IMU samples (all six values) lasting ``HELD_MIN_S`` or more: a
    stuck sensor, or a logging gap filled by repeating the last value (forward-fill
    resampling). Noise makes real consecutive samples differ; the repeats are removed so
    the estimators bridge the run as a gap."""
    i = drive.imu
    x = np.column_stack([i.gyro_b, i.accel_b])
    same = np.all(x[1:] == x[:-1], axis=1)
    if not same.any():
        return drive
    rep = np.r_[False, same]
    # run starts/ends of repeated samples
    edges = np.flatnonzero(np.diff(np.r_[0, rep.astype(np.int8), 0]))
    drop = np.zeros(len(i), dtype=bool)
    n_runs = 0
    longest = 0.0
    for a, b in zip(edges[::2], edges[1::2], strict=True):
        dur = float(i.t[b - 1] - i.t[a - 1])
        if b - a >= HELD_MIN_SAMPLES and dur >= HELD_MIN_S:
            drop[a:b] = True
            n_runs += 1
            longest = max(longest, dur)
    if not n_runs:
        return drive
    f.repair("imu", "held (repeated) samples removed (bridged as an IMU gap)", int(drop.sum()),
             f"imu: {n_runs} run(s) of identical samples, the longest {longest:.1f} s (sensor "
             "stuck or a gap filled by repetition): removed, bridged as a gap")
    return drive.replace(imu=_imu(drive, i.gyro_b, i.accel_b, ~drop))


def _check_mean_force(drive: Drive, f: _Findings) -> Drive:
    """Seconds whose mean specific force is more than 3 g away from g: no vehicle of this
    package sustains that for a second; a hard impact, corrupt values, or clipping averaged
    away (1 Hz means). Their samples are removed and bridged as a gap, like clipping."""
    i = drive.imu
    _, k = np.unique(np.floor(i.t - i.t[0]), return_inverse=True)
    n = np.bincount(k)
    mean = np.column_stack([np.bincount(k, weights=i.accel_b[:, j]) / n for j in range(3)])
    dev = np.abs(np.linalg.norm(mean, axis=1) - G0)
    bad_s = dev > MAX_MEAN_SPECIFIC_FORCE
    if not bad_s.any():
        return drive
    drop = bad_s[k]
    if drop.mean() > 0.5:
        raise _reject("imu", f"{int(bad_s.sum())} of {bad_s.size} seconds have a mean specific "
                      "force over 3 g away from 1 g: not an accelerometer in m/s^2 with gravity")
    f.repair("imu", "seconds with a mean specific force > 3 g from 1 g removed (bridged as a "
             "gap)", int(drop.sum()),
             f"imu: {int(bad_s.sum())} second(s) whose mean specific force is up to "
             f"{float(dev.max()) / G0:.1f} g away from 1 g (impact, clipping averaged away or "
             f"corrupt values): their {int(drop.sum())} samples removed, bridged as a gap")
    return drive.replace(imu=_imu(drive, i.gyro_b, i.accel_b, ~drop))


def _check_gravity_axis(drive: Drive, f: _Findings) -> None:
    m = drive.imu.accel_b.mean(axis=0)
    n = float(np.linalg.norm(m))
    if n <= 0:
        return
    tilt = float(np.degrees(np.arccos(np.clip(-m[2] / n, -1.0, 1.0))))
    f.diag["imu_gravity_tilt_deg"] = tilt
    if tilt > MAX_TILT_DEG:
        ax = int(np.argmax(np.abs(m)))
        raise _reject("imu", f"mean specific force points along {'-' if m[ax] < 0 else '+'}"
                      f"{'xyz'[ax]}_b, {tilt:.0f} deg from -z_b (the body axes must be "
                      "forward-right-down): axes swapped, or the IMU is mounted on its side")


def _clipped(x: FloatArray, floor: float) -> tuple[NDArray[np.bool_], float]:
    """Samples pinned at an axis's extreme |value| (see CLIP_*); and the inferred limit."""
    clip = np.zeros(x.shape[0], dtype=bool)
    lim = 0.0
    for j in range(x.shape[1]):
        a = np.abs(x[:, j])
        top = float(a.max())
        if top < floor:
            continue
        at = a >= top * (1.0 - CLIP_REL_TOL)
        if at.sum() >= CLIP_MIN_SAMPLES and np.any(at[1:] & at[:-1]):
            clip |= at
            lim = max(lim, top)
    return clip, lim


def _check_clipping(drive: Drive, f: _Findings) -> Drive:
    i = drive.imu
    ca, lim_a = _clipped(i.accel_b, CLIP_MIN_ACCEL)
    cg, lim_g = _clipped(i.gyro_b, CLIP_MIN_GYRO)
    clip = ca | cg
    n = int(clip.sum())
    if not n:
        return drive
    # a clipping episode is one event: the samples between clipped ones (below the limit only
    # while the signal swings through) are no more trustworthy, so the whole episode, padded
    # by CLIP_PAD_S, is removed and bridged as one gap
    k = np.flatnonzero(clip)
    t = i.t
    starts = np.r_[0, np.flatnonzero(np.diff(t[k]) > CLIP_MERGE_S) + 1]
    ends = np.r_[starts[1:] - 1, k.size - 1]
    for a, b in zip(starts, ends, strict=True):
        clip |= (t >= t[k[a]] - CLIP_PAD_S) & (t <= t[k[b]] + CLIP_PAD_S)
    removed = int(clip.sum())
    if n > 0.5 * len(i):
        raise _reject("imu", f"{n} of {len(i)} samples at the sensor's range limit: the "
                      "log is mostly clipped (wrong unit or range setting?)")
    f.meta["clipping"] = {"imu": {"accel_samples": int(ca.sum()), "gyro_samples": int(cg.sum()),
                                  "episodes": int(starts.size), "samples_removed": removed,
                                  "accel_limit_m_s2": lim_a or None,
                                  "gyro_limit_rad_s": lim_g or None,
                                  "handling": "samples removed: bridged as an IMU gap"}}
    lims = [f"{lim_a / G0:.1f} g" if lim_a else "", f"{lim_g:.2f} rad/s" if lim_g else ""]
    f.repair("imu", "clipping episodes removed (bridged as an IMU gap)", removed,
             f"imu: {n} clipped samples in {starts.size} episode(s) at the sensor's range "
             f"({', '.join(x for x in lims if x)}): the episodes ({removed} samples) removed, "
             "so the estimators bridge them as a gap")
    return drive.replace(imu=_imu(drive, i.gyro_b, i.accel_b, ~clip))


# ---------------------------------------------------------------------------- baro
def _baro_from_alt(b: BaroStream, alt: FloatArray, keep: NDArray[np.bool_] | None = None
                   ) -> BaroStream:
    """The baro stream with a repaired altitude; the raw pressure is dropped so that no
    stream carries a pressure that disagrees with its altitude (estimators use altitude)."""
    if keep is None:
        keep = np.ones(len(b), dtype=bool)
    return BaroStream(b.t[keep], None, alt[keep], b.spec)


def _check_baro(drive: Drive, f: _Findings) -> Drive:
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
def _check_gnss(drive: Drive, f: _Findings) -> Drive:
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
    speed = step / np.diff(g.t)
    fast = speed > GNSS_JUMP_SPEED
    # an isolated bad fix: fast in and fast out, and its neighbours agree with each other
    spike = np.zeros(len(g), dtype=bool)
    spike[1:-1] = fast[:-1] & fast[1:]
    if spike.any():
        k = np.flatnonzero(spike)
        around = np.linalg.norm(ned[k + 1] - ned[k - 1], axis=1) / (g.t[k + 1] - g.t[k - 1])
        spike[k[around > GNSS_JUMP_SPEED]] = False
    if spike.any():
        n = int(spike.sum())
        big = float(np.max(step[np.flatnonzero(spike) - 1]))
        f.repair("gnss", "isolated position jump dropped", n,
                 f"gnss: {n} isolated fix(es) jumping up to {big:.0f} m away and back "
                 f"(faster than {GNSS_JUMP_SPEED:.0f} m/s): dropped")
        drive = drive.replace(gnss=g.select(~spike))
    elif fast.any():
        f.warn(f"gnss: {int(fast.sum())} position step(s) faster than "
               f"{GNSS_JUMP_SPEED:.0f} m/s between consecutive fixes (glitches?)")
    return drive


def _check_truth(drive: Drive, f: _Findings) -> Drive:
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


CHECKS: tuple[Callable[[Drive, _Findings], Drive | None], ...] = (
    _check_drops, _check_time_units, _check_truth, _check_accel_magnitude, _check_rotation,
    _check_gravity_axis, _check_handedness, _check_held_samples, _check_clipping,
    _check_mean_force, _check_baro,
    _check_gnss, _check_coverage,
)


def check_drive(drive: Drive) -> Drive:
    """Run every check (module docstring) on ``drive``; repaired Drive or ValueError.

    ``meta["warnings"]`` (list of one-line strings) and ``meta["repaired"]`` (stream → reason →
    count) are extended when something is found; ``meta["sanity"]`` holds the measured
    statistics; everything else in ``meta`` is kept.
    """
    f = _Findings(dict(drive.meta))
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
