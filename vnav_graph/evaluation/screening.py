"""Plausibility screening of the withheld GNSS fixes a holdout scores against.

A withheld fix is a *reference*: when it is wrong (a multipath spike, a height jump), every
estimator is scored against the error. The screen uses only the log itself — no estimator's
output — and excludes a withheld fix when any of these fails:

- **baro climb**: the GNSS-minus-baro height difference d(t) = h_GNSS(t) − h_baro(t) changes
  slowly (baro bias drift, scale × height change); a fix whose d departs from the running
  median of d over ±``BARO_HALF_S`` (the fixes around it, withheld or not) by more than
  ``K_SIGMA`` × σ is not a height the vehicle had. σ = max(reported σ_v, the robust scatter of
  d about its running median over the whole log, ``MIN_SD_M``): a receiver whose heights
  wander is judged by its own wander, not by its optimistic σ;
- **vertical speed**: a single fix that jumps from *both* neighbours at more than
  ``MAX_VSPEED`` (a spike, not a climb);
- **reported velocity** (when the log has GNSS velocity): a fix whose horizontal position
  disagrees with *both* neighbours' positions carried by the mean reported velocity, beyond
  ``K_SIGMA`` × σ (σ from the reported position and velocity σ and an acceleration of
  ``MAX_ACCEL`` over the interval);
- **height excursion**: the GNSS-minus-baro difference d *jumps* away from its level and
  later jumps back to it (a multipath plateau, a receiver's wrong solution held for tens of
  seconds). The baro-climb check judges a fix against the running median of the fixes
  around it, so a plateau longer than about ``BARO_HALF_S`` carries its own median and
  passes. A jump is a change of d between consecutive fixes (≤ ``JUMP_DT_S`` apart) beyond
  ``K_SIGMA`` × √(σ₁² + σ₂²), each σ = max(reported σ_v, the robust scatter of those changes
  over the log / √2, ``MIN_SD_M``): a barometer cannot step, and a true climb moves both
  heights. The fixes from a jump up to an opposite jump that returns d to within the first
  jump's bound of its level before it (medians of ``LEVEL_FIXES`` fixes each side), at most
  ``MAX_EXCURSION_S`` later, are excluded. A step that never returns is left alone: with
  no level to come back to, the log alone cannot say which side is wrong.

The counts by check and the excluded times go into ``holdout.json["reference_screening"]``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..types import Drive
from ..types.streams import FloatArray

BARO_HALF_S = 15.0  # s
K_SIGMA = 5.0
MIN_SD_M = 0.5  # m
MAX_VSPEED = 60.0  # m/s
MAX_ACCEL = 5.0  # m/s²
JUMP_DT_S = 5.0  # s: consecutive fixes further apart than this are not a jump
MAX_EXCURSION_S = 300.0  # s
LEVEL_FIXES = 5


def _running_median(t: FloatArray, x: FloatArray, half: float) -> FloatArray:
    lo = np.searchsorted(t, t - half, side="left")
    hi = np.searchsorted(t, t + half, side="right")
    return np.array([np.median(x[a:b]) for a, b in zip(lo, hi, strict=True)])


def _gnss_minus_baro(drive: Drive, min_fixes: int
                     ) -> tuple[np.ndarray, FloatArray, FloatArray, FloatArray] | None:
    """The fixes inside the baro's span (indices), their times, d = GNSS − baro height and
    the receiver's σ_v there; None without a baro or with fewer than ``min_fixes`` such
    fixes."""
    g, b = drive.gnss, drive.baro
    if b is None or b.t.size < 2 or g is None:
        return None
    inside = np.flatnonzero((g.t >= b.t[0]) & (g.t <= b.t[-1]))
    if inside.size < min_fixes:
        return None
    t = g.t[inside]
    return inside, t, g.lla[inside, 2] - np.interp(t, b.t, b.altitude), g.pos_sd[inside, 2]


def _baro_check(drive: Drive) -> np.ndarray | None:
    """Bool (N,) over all fixes: passes the baro-climb check (None: no baro to check with)."""
    got = _gnss_minus_baro(drive, 5)
    if got is None:
        return None
    inside, t, d, sd_v = got
    assert drive.gnss is not None  # the helper found fixes
    ok = np.ones(len(drive.gnss), dtype=bool)
    dev = d - _running_median(t, d, BARO_HALF_S)
    scatter = 1.4826 * float(np.median(np.abs(dev)))
    sd = np.maximum(np.maximum(sd_v, scatter), MIN_SD_M)
    ok[inside] = np.abs(dev) <= K_SIGMA * sd
    return ok


def _vspeed_check(drive: Drive) -> np.ndarray:
    g = drive.gnss
    assert g is not None
    ok = np.ones(g.t.size, dtype=bool)
    if g.t.size < 3:
        return ok
    h, t = g.lla[:, 2], g.t
    rate = np.abs(np.diff(h)) / np.maximum(np.diff(t), 1e-3)
    fast = rate > MAX_VSPEED
    ok[1:-1] = ~(fast[:-1] & fast[1:])
    return ok


def _velocity_check(drive: Drive) -> np.ndarray | None:
    g = drive.gnss
    if g is None or g.vel_n is None or g.vel_sd is None or g.t.size < 3:
        return None
    from ..geo.frames import lla_to_ned

    p = lla_to_ned(g.lla, drive.origin_lla)[:, :2]
    v, sv, sp = g.vel_n[:, :2], g.vel_sd[:, :2], g.pos_sd[:, :2]
    dt = np.diff(g.t)[:, None]
    miss = (p[1:] - p[:-1]) - 0.5 * (v[1:] + v[:-1]) * dt
    var = (sp[1:] ** 2 + sp[:-1] ** 2 + (0.5 * dt) ** 2 * (sv[1:] ** 2 + sv[:-1] ** 2)
           + (0.5 * MAX_ACCEL * dt**2) ** 2)
    bad = np.any(miss**2 > K_SIGMA**2 * var, axis=1)
    ok = np.ones(g.t.size, dtype=bool)
    ok[1:-1] = ~(bad[:-1] & bad[1:])
    return ok


def excursion_check(drive: Drive) -> np.ndarray | None:
    """Bool (N,) over all fixes: not inside a height excursion (module docstring)."""
    got = _gnss_minus_baro(drive, 2 * LEVEL_FIXES + 2)
    if got is None:
        return None
    inside, t, d, sd_v = got
    assert drive.gnss is not None  # the helper found fixes
    ok = np.ones(len(drive.gnss), dtype=bool)
    step = np.diff(d)
    near = np.diff(t) <= JUMP_DT_S
    if not near.any():
        return ok
    med = float(np.median(step[near]))
    scatter = 1.4826 * float(np.median(np.abs(step[near] - med)))
    sd = np.maximum(np.maximum(sd_v, scatter / np.sqrt(2.0)), MIN_SD_M)
    lim = K_SIGMA * np.hypot(sd[1:], sd[:-1])  # lim[k]: for the step d[k + 1] − d[k]
    jumps = np.flatnonzero(near & (np.abs(step) > lim)) + 1  # d[j] differs from d[j - 1]
    i = 0
    while i < jumps.size:
        j = jumps[i]
        before = float(np.median(d[max(0, j - LEVEL_FIXES):j]))
        back = None
        for m in jumps[i + 1:]:
            if t[m] - t[j] > MAX_EXCURSION_S:
                break
            if np.sign(step[m - 1]) != np.sign(step[j - 1]):
                after = float(np.median(d[m:m + LEVEL_FIXES]))
                if abs(after - before) <= lim[j - 1]:
                    back = m
                    break
        if back is None:
            i += 1
            continue
        ok[inside[j:back]] = False
        i = int(np.searchsorted(jumps, back))  # the next jump at or after the return
        if i < jumps.size and jumps[i] == back:
            i += 1
    return ok


def screen_reference(drive: Drive, withheld: np.ndarray) -> tuple[np.ndarray, dict[str, Any]]:
    """(usable, report): ``usable`` (N,) bool is ``withheld`` minus the implausible fixes;
    ``report`` is the JSON block (module docstring)."""
    g = drive.gnss
    assert g is not None
    checks = {"baro_climb": _baro_check(drive), "vertical_speed": _vspeed_check(drive),
              "reported_velocity": _velocity_check(drive),
              "height_excursion": excursion_check(drive)}
    keep = withheld.copy()
    by_check: dict[str, int | None] = {}
    for name, ok in checks.items():
        if ok is None:
            by_check[name] = None  # not applicable to this log
            continue
        by_check[name] = int(np.sum(withheld & ~ok))
        keep &= ok
    excluded = withheld & ~keep
    report = {
        "method": "baro-climb consistency, vertical-speed spikes, position vs reported "
                  "velocity, height excursions against the baro (no estimator output); see "
                  "vnav_graph/evaluation/screening.py",
        "withheld": int(withheld.sum()), "excluded": int(excluded.sum()),
        "by_check": by_check, "excluded_t": [float(x) for x in g.t[excluded]],
    }
    return keep, report
