"""IMU input checks: units, axes and hostile samples (run by ``io.sanity.check_drive``).

Each check takes the Drive and the :class:`~vnav_graph.io.findings.Findings` of the run and
returns a repaired Drive (or None when nothing changes), or raises ``ValueError``;
:data:`IMU_CHECKS` lists them in the order ``check_drive`` runs them.

Units come first: every reader (DataFlash, ULog, Sensor Logger, ``.npz``) calls
``imu_units.unit_fixes`` on the raw, finite samples *before* any range screen of its own, so a gyro
in deg/s is converted instead of screened as "outside physical range" (a DataFlash range of
50 'rad/s' once dropped every sample above 50 deg/s: 31 % of a deg/s log). The checks below
then find rad/s and m/s² and change nothing; they still decide for a drive that reaches
``check_drive`` some other way.

Checks, with the evidence each uses
-----------------------------------
- specific-force magnitude: the median |f| over the drive is g for any vehicle that does not
  stay in free fall. ``≈ 1`` → g units (× g0); ``≈ g0²`` → scaled by g0 twice (÷ g0); any
  other value outside [6, 14] m/s² is refused.
- gyro units: over 1 s block means of |ω|, a busiest second above ``DEG_BUSY`` rad/s (458°/s
  held for a second) or a quietest second above ``DEG_QUIET`` rad/s (never below 29°/s) is a
  gyro in deg/s (→ × π/180): a vehicle's rates in rad/s stay a few rad/s at most, the same
  rates in deg/s are 57 times larger (docs/real_logs.md, "IMU unit and axis checks").
- axes against each other, ground vehicles (one dominant rotation axis, E[ω̄ω̄ᵀ] eigenvalue
  ratio ≥ ``GROUND_AXIS_RATIO``): a car turns about the vertical, so its principal rotation
  axis more than 45° from the mean specific force means accelerometer and gyro columns are
  swapped against each other (refused; cars measure 0.4-3°, swapped 87-90°). A mirror (two
  accelerometer columns swapped, gravity unmoved) is caught by :func:`handedness`
  (centripetal force on the right in right turns).
- axes against each other, any vehicle that moves and turns (:func:`course_rate_fit`): the
  gyro's turn about the down axis (−mean specific force) must explain the GNSS course
  changes over 5 s windows. Refused when the gyro explains at least half of them
  (``COURSE_R2_EXPLAINED``) but about the down axis less than a fifth (``COURSE_R2_NONE``),
  or 10 points less than about its best axis (``COURSE_R2_GAP``, significant at
  ``COURSE_P``): columns swapped; or when it turns the wrong way (a mirrored axis).
  Measured (r2 about the best axis minus about down): every scenario, seeds 0-2, ≤ 0.06, all
  pass. Gyro x/z swapped: 29 of 30 simulated drives refused; z inverted: 28 of 30 refused
  (k −0.45 to −1.22). A hovering multirotor turns too little against its course to decide
  (docs/real_logs.md, "IMU unit and axis checks").
  A gyro in deg/s turns 57.3 times too far: k = π/180 × the clean k (0.45-1.3 → 0.008-0.023),
  so k in ``DEG_K_BAND`` (0.005-0.05) with ``r2_down`` ≥ 0.5 converts it (the sortie aircraft
  in deg/s: its busiest second is 6 'rad/s', under ``DEG_BUSY``).
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
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ..geo.earth import G0
from ..types import Drive
from ..types.streams import BoolArray, FloatArray, ImuStream
from .findings import Findings, reject
from .imu_units import (
    ACCEL_G2_REASON,
    ACCEL_G_REASON,
    ACCEL_IN_G,
    ACCEL_TWICE,
    GYRO_DEG_REASON,
    block_means,
    gyro_in_degrees,
)

ACCEL_OK = (6.0, 14.0)  # median |f| [m/s²] accepted as "g in m/s²"
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
MAX_MEAN_SPECIFIC_FORCE = 3.0 * G0  # 1 s mean |f| beyond g ± this: reported
COURSE_MIN_SPEED = 3.0  # m/s: a GNSS course is defined (the handedness check's speed)
COURSE_MIN_BLOCKS = 30  # moving 1 s blocks needed
COURSE_WINDOW_S = 5.0  # course change over this many 1 s blocks (a turn's scale)
COURSE_MIN_RATE = 0.02  # rad/s rms course rate: the drive turns
COURSE_R2_EXPLAINED = 0.5  # the gyro explains at least half the course-rate variance
COURSE_R2_NONE = 0.2  # ... but about the down axis less than a fifth of it
COURSE_R2_GAP = 0.1  # ... or 10 points less than about its best axis (clean: <= 0.06)
COURSE_P = 1e-3  # ... and that difference significant (F test, independent windows)
DEG_K_BAND = (0.005, 0.05)  # course change per gyro turn of a deg/s gyro (clean k: 0.45-1.3)


def rotation_stats(t: FloatArray, gyro: FloatArray, accel: FloatArray) -> dict[str, float]:
    """Statistics of 1 s block means of the gyro used by the unit and axis checks.

    ``quiet``: 2nd percentile of |ω̄| [rad/s] (the quietest seconds); ``busy``: 99.9th
    percentile; ``axis_ratio``: first over second eigenvalue of E[ω̄ ω̄ᵀ]; ``axis_rms``:
    sqrt of the first [rad/s]; ``axis_angle_deg``: angle between that principal rotation axis
    and the mean specific force.
    """
    _, wm = block_means(t, gyro, 1.0)
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
         keep: BoolArray | None = None) -> ImuStream:
    i = drive.imu
    if keep is None:
        return ImuStream(i.t, gyro, accel, i.spec)
    return ImuStream(i.t[keep], gyro[keep], accel[keep], i.spec)


def _check_accel_magnitude(drive: Drive, f: Findings) -> Drive:
    mag = float(np.median(np.linalg.norm(drive.imu.accel_b, axis=1)))
    if ACCEL_OK[0] <= mag <= ACCEL_OK[1]:
        return drive
    if ACCEL_IN_G[0] <= mag <= ACCEL_IN_G[1]:
        f.repair("imu", ACCEL_G_REASON, len(drive.imu),
                 f"imu: median |specific force| {mag:.3g} is g units, not m/s^2: converted "
                 "(x 9.80665)")
        return drive.replace(imu=_imu(drive, drive.imu.gyro_b, drive.imu.accel_b * G0))
    if ACCEL_TWICE[0] <= mag <= ACCEL_TWICE[1]:
        f.repair("imu", ACCEL_G2_REASON, len(drive.imu),
                 f"imu: median |specific force| {mag:.4g} m/s^2 is about g^2: converted "
                 "twice to m/s^2; divided by 9.80665")
        return drive.replace(imu=_imu(drive, drive.imu.gyro_b, drive.imu.accel_b / G0))
    raise reject("imu", f"median |specific force| {mag:.3g} m/s^2 is not about g "
                 "(9.8): wrong unit, gravity removed, or not an accelerometer")


def _check_rotation(drive: Drive, f: Findings) -> Drive:
    i = drive.imu
    st = rotation_stats(i.t, i.gyro_b, i.accel_b)
    f.diag["imu_rotation_stats"] = st
    if st["blocks"] < 5:
        return drive
    if gyro_in_degrees(st):
        f.repair("imu", GYRO_DEG_REASON, len(i),
                 f"imu: gyro rates look like deg/s (quietest second {st['quiet']:.2g}, "
                 f"busiest {st['busy']:.3g} 'rad/s'): converted (x pi/180)")
        return drive.replace(imu=_imu(drive, i.gyro_b * (np.pi / 180.0), i.accel_b))
    ground = (st["axis_ratio"] >= GROUND_AXIS_RATIO and st["busy"] < GROUND_BUSY
              and st["axis_rms"] > GROUND_AXIS_RMS)
    if ground and st["axis_angle_deg"] > 45.0:
        raise reject("imu", f"the vehicle turns about an axis {st['axis_angle_deg']:.0f} deg "
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
    tb, am = block_means(i.t, i.accel_b, 1.0)
    _, wm = block_means(i.t, i.gyro_b, 1.0)
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


def _check_handedness(drive: Drive, f: Findings) -> None:
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
        raise reject("imu", f"accelerometer axes are mirrored against the gyro (centripetal "
                     f"force on the left in right turns; handedness {hd['h']:.2f}): two "
                     "accelerometer columns swapped?")


def course_rate_fit(drive: Drive) -> dict[str, float] | None:
    """How well the gyro explains the GNSS course changes (any vehicle that moves and turns).

    On 1 s blocks, the course χ comes from the GNSS velocity, or from the block means of its
    positions differenced over ±1 block where the log has no velocity (a 10 Hz fix's noise
    differenced over 0.1 s would swamp it). Over every ``COURSE_WINDOW_S`` window of
    consecutive blocks moving faster than ``COURSE_MIN_SPEED``, the course change Δχ is
    fitted by least squares to the gyro's turn about the down axis d̂ (−mean specific
    force), Δχ ≈ k·Σ(ω̄·d̂)·1 s, and to its turn about all three axes, Δχ ≈ (Σω̄)·u. Returns
    k, the fractions of Δχ's variance each explains (``r2_down``, ``r2_any``), the rms
    course rate and the number of moving blocks; None without GNSS or with fewer than
    ``COURSE_MIN_BLOCKS`` moving blocks. A vehicle turns about the vertical whatever it is (a
    banked aircraft's ω·d̂ is the turn rate / cos(bank): k ≈ 1.2 on the sortie scenario), so
    k > 0 with ``r2_down`` high; a gyro whose columns are swapped against the
    accelerometer's turns about a horizontal axis (``r2_down`` ≈ 0 while ``r2_any`` stays
    high) and a mirrored one turns the wrong way (k < 0).
    """
    g = drive.gnss
    i = drive.imu
    if g is None or len(g) < 10:
        return None
    tb, wm = block_means(i.t, i.gyro_b, 1.0)
    inside = (tb > g.t[0]) & (tb < g.t[-1])
    tb, wm = tb[inside], wm[inside]
    if tb.size < COURSE_MIN_BLOCKS:
        return None
    if g.vel_n is not None and np.all(np.isfinite(g.vel_n[:, :2])):
        vn, ve = np.interp(tb, g.t, g.vel_n[:, 0]), np.interp(tb, g.t, g.vel_n[:, 1])
    else:
        from ..geo.frames import lla_to_ned

        ned = lla_to_ned(g.lla, g.lla[0])
        tg, pm = block_means(g.t, ned[:, :2], 1.0)
        if tg.size < 3:
            return None
        vg = np.gradient(pm, tg, axis=0)
        vn, ve = np.interp(tb, tg, vg[:, 0]), np.interp(tb, tg, vg[:, 1])
    chi = np.unwrap(np.arctan2(ve, vn))
    moving = (np.hypot(vn, ve) > COURSE_MIN_SPEED) & np.isfinite(chi)
    if moving.sum() < COURSE_MIN_BLOCKS:
        return None
    d = -i.accel_b.mean(axis=0)
    d = d / max(float(np.linalg.norm(d)), 1e-12)
    step = np.r_[np.diff(tb), np.inf]  # blocks 1 s apart are consecutive
    cw = np.vstack([np.zeros(3), np.cumsum(wm, axis=0)])
    w = int(COURSE_WINDOW_S)
    k0 = np.arange(tb.size - w)
    ok = np.array([moving[k:k + w + 1].all() and np.all(step[k:k + w] < 1.5) for k in k0],
                  dtype=bool)
    if ok.sum() < 3:
        return None
    k0 = k0[ok]
    y = chi[k0 + w] - chi[k0]
    x = cw[k0 + w] - cw[k0]  # Σ ω̄ over the window's blocks (1 s each)
    xd = x @ d
    ss = float(np.sum((y - y.mean()) ** 2))
    if ss <= 0 or float(np.sum(xd**2)) <= 0:
        return None
    k = float(np.sum(xd * y) / np.sum(xd**2))
    u, *_ = np.linalg.lstsq(x, y, rcond=None)
    rate = np.gradient(chi, tb)[moving]
    rss_down, rss_any = float(np.sum((y - k * xd) ** 2)), float(np.sum((y - x @ u) ** 2))
    # nested least squares (1 against 3 parameters): F test on the independent windows (the
    # sliding windows overlap: n / COURSE_WINDOW_S of them are independent)
    n_ind = y.size / COURSE_WINDOW_S
    from scipy.stats import f as f_dist

    p_down = 1.0
    if n_ind > 4 and rss_any > 0:
        fstat = (rss_down - rss_any) / 2.0 / (rss_any / (n_ind - 3.0))
        p_down = float(f_dist.sf(fstat, 2, n_ind - 3.0))
    return {"k_down": k, "r2_down": 1.0 - rss_down / ss, "r2_any": 1.0 - rss_any / ss,
            "p_down": p_down, "course_rate_rms": float(np.sqrt(np.mean(rate**2))),
            "blocks": float(moving.sum()), "windows": float(y.size),
            "axis_angle_deg": float(np.degrees(np.arccos(min(1.0, abs(float(u @ d)) / max(
                float(np.linalg.norm(u)), 1e-12)))))}


def _check_course_rate(drive: Drive, f: Findings) -> Drive | None:
    """The gyro against the GNSS course (:func:`course_rate_fit`), any vehicle: a gyro that
    explains the turns about the down axis (``COURSE_R2_EXPLAINED``) with a gain
    k in ``DEG_K_BAND`` turns 57 times too fast: deg/s, converted (a vehicle that never
    turns faster than 8 deg/s for a second escapes the rate test of :func:`unit_fixes`).
    Refused when the gyro explains the turns but not about the gravity axis
    (``COURSE_R2_NONE``, or ``COURSE_R2_GAP`` less than about its best axis, significant at
    ``COURSE_P``), or turns the wrong way about it."""
    fit = course_rate_fit(drive)
    f.diag["imu_course_rate_fit"] = fit
    if fit is None or fit["course_rate_rms"] < COURSE_MIN_RATE:
        return None
    if fit["r2_down"] >= COURSE_R2_EXPLAINED and DEG_K_BAND[0] <= fit["k_down"] <= DEG_K_BAND[1]:
        i = drive.imu
        f.repair("imu", GYRO_DEG_REASON, len(i),
                 f"imu: the gyro turns {1 / fit['k_down']:.0f} times as far as the GNSS course "
                 f"in turns (r2 {fit['r2_down']:.2f}; 57.3 is deg/s): converted (x pi/180)")
        return drive.replace(imu=_imu(drive, i.gyro_b * (np.pi / 180.0), i.accel_b))
    off_axis = fit["r2_down"] < COURSE_R2_NONE or (
        fit["r2_any"] - fit["r2_down"] >= COURSE_R2_GAP and fit["p_down"] < COURSE_P)
    if fit["r2_any"] >= COURSE_R2_EXPLAINED and off_axis:
        raise reject("imu", f"the gyro explains {100 * fit['r2_any']:.0f} % of the GNSS course "
                     f"changes in turns, but only {100 * max(fit['r2_down'], 0.0):.0f} % about the "
                     f"axis gravity gives as down (its best axis is {fit['axis_angle_deg']:.0f} "
                     "deg from it): gyro axes swapped against the accelerometer's?")
    if fit["r2_down"] >= COURSE_R2_EXPLAINED and fit["k_down"] < 0:
        raise reject("imu", f"the gyro turns the wrong way about the down axis ("
                     f"{fit['k_down']:.2f} x the GNSS course change in turns): a gyro axis "
                     "inverted (mirrored against the accelerometer)?")
    return None


def _check_held_samples(drive: Drive, f: Findings) -> Drive:
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


def _check_mean_force(drive: Drive, f: Findings) -> Drive:
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
        raise reject("imu", f"{int(bad_s.sum())} of {bad_s.size} seconds have a mean specific "
                     "force over 3 g away from 1 g: not an accelerometer in m/s^2 with gravity")
    f.repair("imu", "seconds with a mean specific force > 3 g from 1 g removed (bridged as a "
             "gap)", int(drop.sum()),
             f"imu: {int(bad_s.sum())} second(s) whose mean specific force is up to "
             f"{float(dev.max()) / G0:.1f} g away from 1 g (impact, clipping averaged away or "
             f"corrupt values): their {int(drop.sum())} samples removed, bridged as a gap")
    return drive.replace(imu=_imu(drive, i.gyro_b, i.accel_b, ~drop))


def _check_gravity_axis(drive: Drive, f: Findings) -> None:
    m = drive.imu.accel_b.mean(axis=0)
    n = float(np.linalg.norm(m))
    if n <= 0:
        return
    tilt = float(np.degrees(np.arccos(np.clip(-m[2] / n, -1.0, 1.0))))
    f.diag["imu_gravity_tilt_deg"] = tilt
    if tilt > MAX_TILT_DEG:
        ax = int(np.argmax(np.abs(m)))
        raise reject("imu", f"mean specific force points along {'-' if m[ax] < 0 else '+'}"
                     f"{'xyz'[ax]}_b, {tilt:.0f} deg from -z_b (the body axes must be "
                     "forward-right-down): axes swapped, or the IMU is mounted on its side")


def _clipped(x: FloatArray, floor: float) -> tuple[BoolArray, float]:
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


def _check_clipping(drive: Drive, f: Findings) -> Drive:
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
        raise reject("imu", f"{n} of {len(i)} samples at the sensor's range limit: the "
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


IMU_CHECKS: tuple[Callable[[Drive, Findings], Drive | None], ...] = (
    _check_accel_magnitude, _check_rotation, _check_gravity_axis, _check_handedness,
    _check_course_rate,
    _check_held_samples, _check_clipping, _check_mean_force,
)
