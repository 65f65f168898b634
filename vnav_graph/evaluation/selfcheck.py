"""Does an estimate agree with the measurements it was given? A self-check that needs no truth.

Every estimate is compared with the GNSS fixes of the drive it ran on (on a real log's
holdout run, the withheld fixes are not in that drive). At each fix within ``NEAR_S`` (or five
output epochs) of an epoch of the estimate, the normalised residual is

    z = r / √(σ_gnss² + σ_est²),   r = estimate − fix,

for the height (σ_gnss the fix's down σ, σ_est the estimate's altitude σ where it has a
covariance, else 0) and, for an estimate with a horizontal position, for the horizontal
distance (σ² summed over north and east). Per window of ``WINDOW_S`` seconds with at least
``MIN_FIXES`` fixes the statistic is the median of |z| and of |r|.

Thresholds. For a consistent estimate z ~ N(0, 1) and the median of |z| over n ≥ 3 fixes is
about 0.67; it exceeds ``Z_DIVERGED`` = 100 with a χ² tail probability (χ²₁ > 10⁴ for at
least half of the fixes) below 10⁻³⁰⁰. What does raise |z| without divergence is
overconfidence under GNSS errors correlated over minutes: measured NEES/dof up to 624 on an
urban variant, i.e. |z| ≈ 25 in the worst case. ``Z_DIVERGED`` is four times that. A glitch is
not divergence either: a receiver that jumps for a few seconds (and the estimator that
rightly refuses it) makes one window at most, so a verdict needs ``DIVERGED_WINDOWS``
consecutive windows (60 s). ``RESID_FLOOR_M`` is a physical floor: a residual under 100 m is
never called divergence, whatever σ claims (a 1 cm σ on a 1 m error is overconfidence, which
NEES reports).

Measured with every estimator (seed 0 of each shipped scenario, each shared log): the largest
window median |z| on the scenarios is 43 (the fixed-gain loops on hot-baro, which report no
σ), on the shared logs about half of ``Z_DIVERGED`` (docs/real_logs.md, "Self-check on the
shared logs"). On long-outage observer1d reaches |z| 319 (640 m) in the one window after
each 180 s outage and is back under 1 the window after: a recovering estimator, not a
diverged one. None is flagged.

The estimate is ``"diverged"`` when a run of ``DIVERGED_WINDOWS`` consecutive windows each has
median |z| > ``Z_DIVERGED`` and median |r| > ``RESID_FLOOR_M``, in height or horizontally; or
when it is *lost*, whatever its σ: every fix for ``LOST_S`` seconds in a row more than
``LOST_M`` from it (an estimator that reports σ of kilometres is not overconfident, but an
answer kilometres from the fixes it was given is still not an answer: an IMU-only answer
after a long logging gap drifts away at tens of m/s with σ to match). On the shared logs
only an estimator that follows glitched GNSS comes over ``LOST_M``, for seconds, well under
``LOST_S`` (docs/real_logs.md, "Self-check on the shared logs").

Every answer
------------
:func:`check_answers` checks the final trajectory *and* the causal one (``Estimate.online``,
where the estimator has one that is not its final answer), each in height and horizontally;
either diverging marks the estimate (the reason says which).

After an outage
---------------
Across a GNSS outage (consecutive fixes more than ``OUTAGE_MIN_S`` apart: a receiver outage,
or a holdout window) an answer stands on its own. At the first fix after it, the answer at
its last epoch before that fix (for a filter the prediction, before the fix is used) is
compared with the fix: the jump r against σ = √(σ_fix² + σ_est²), in height and
horizontally. For an estimate that is consistent across the outage r/σ is N(0, 1) per axis:
|r| > ``JUMP_SIGMA`` σ = 5σ has probability 5.7e-7 in height (χ²₁ > 25) and below 1e-10
horizontally (σ² summed over two axes: χ²₂ > 50), so over the few dozen outages of a drive a
consistent estimate is never flagged. ``JUMP_FLOOR_M`` = ``RESID_FLOOR_M`` is added for what
σ does not model (multipath and glitches of the returning fix, tens of metres; an estimator
that reports no σ is judged by the floor alone). A jump beyond ``5σ + 100 m`` is *flagged*:
a warning naming it, the answer kept "ok" (long-outage's observer1d: 640 m at 319σ after a
180 s outage, it recovers). A jump beyond ``LOST_M`` marks the estimate ``"diverged"``: for the
length of the outage its answer was kilometres from where the vehicle was.

Far off
-------
Where the run has a reference (truth on a simulated drive, the withheld fixes of a holdout
run), :func:`far_off` marks an answer whose error ever exceeds ``LOST_M`` ``"diverged"``,
whatever the fixes it was given say (a held 1 km height glitch the estimate followed, an
answer across an IMU gap): no estimate more than 1 km off is reported "ok".
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..types import Drive, Estimate
from ..types.streams import FloatArray

WINDOW_S = 30.0
MIN_FIXES = 3
Z_DIVERGED = 100.0
RESID_FLOOR_M = 100.0
DIVERGED_WINDOWS = 2
NEAR_S = 1.0  # a fix is checked when an epoch of the estimate is this close (or 5 epochs)
LOST_M = 1000.0
LOST_S = 30.0
OUTAGE_MIN_S = 10.0  # fixes further apart than this bound a GNSS outage (io.sanity's gap)
JUMP_SIGMA = 5.0  # the jump to the first fix after an outage, in its own σ (docstring)
JUMP_FLOOR_M = RESID_FLOOR_M  # ... plus this floor [m]
DIVERGED = "diverged"  # the status of an estimate that fails the check (summary.json)


@dataclass(frozen=True)
class SelfCheck:
    """The verdict of :func:`self_check`; ``reason`` is one line (None when consistent)."""

    diverged: bool
    reason: str | None
    worst_z: float | None  # the largest window median |z| (None: no window to check)
    windows: int  # windows checked
    # the outage jumps beyond JUMP_SIGMA σ + JUMP_FLOOR_M (dicts: outage_jump's keys)
    jumps: tuple[dict[str, Any], ...] = ()
    flags: tuple[str, ...] = ()  # one warning line per flagged jump
    online: SelfCheck | None = None  # the same check of the causal answer (check_answers)

    def as_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"diverged": self.diverged, "reason": self.reason,
                               "worst_median_z": self.worst_z, "windows": self.windows,
                               "outage_jumps": [dict(j) for j in self.jumps],
                               "flags": list(self.flags)}
        out["online"] = None if self.online is None else self.online.as_dict()
        return out


def _window_medians(t: FloatArray, z: FloatArray, r: FloatArray,
                    t0: float) -> list[tuple[float, float, float]]:
    """(window start, median |z|, median |r|) per window with ≥ MIN_FIXES finite fixes."""
    ok = np.isfinite(z) & np.isfinite(r)
    t, z, r = t[ok], np.abs(z[ok]), np.abs(r[ok])
    if t.size == 0:
        return []
    idx = np.floor((t - t0) / WINDOW_S).astype(np.int64)
    out = []
    for w in np.unique(idx):
        m = idx == w
        if m.sum() >= MIN_FIXES:
            out.append((t0 + w * WINDOW_S, float(np.median(z[m])), float(np.median(r[m]))))
    return out


def _verdict(kind: str, wins: list[tuple[float, float, float]]) -> str | None:
    run: list[tuple[float, float, float]] = []
    for w in wins:
        bad = w[1] > Z_DIVERGED and w[2] > RESID_FLOOR_M
        contiguous = bool(run) and abs(w[0] - run[-1][0] - WINDOW_S) < 1e-6
        run = ([*run, w] if contiguous else [w]) if bad else []
        if len(run) >= DIVERGED_WINDOWS:
            worst = max(run, key=lambda x: x[1])
            return (f"{kind} residual to the GNSS fixes it was given: median {worst[2]:.0f} m "
                    f"= {worst[1]:.0f} sigma over {len(run) * WINDOW_S:.0f} s from "
                    f"t = {run[0][0]:.0f} s (limit {Z_DIVERGED:.0f} sigma and "
                    f"{RESID_FLOOR_M:.0f} m for {DIVERGED_WINDOWS * WINDOW_S:.0f} s)")
    return None


def _lost(kind: str, t: FloatArray, r: FloatArray) -> str | None:
    """The first run of consecutive fixes all more than ``LOST_M`` off lasting ``LOST_S``."""
    big = np.abs(r) > LOST_M
    start = None
    for k in range(t.size):
        if not big[k]:
            start = None
            continue
        start = k if start is None else start
        if t[k] - t[start] >= LOST_S:
            end = k
            while end + 1 < t.size and big[end + 1]:
                end += 1
            return (f"{kind} residual to the GNSS fixes it was given above {LOST_M:.0f} m "
                    f"for {t[end] - t[start]:.0f} s from t = {t[start]:.0f} s (max "
                    f"{np.max(np.abs(r[start:end + 1])):.0f} m): the estimate lost them")
    return None


def self_check(est: Estimate, drive: Drive) -> SelfCheck:
    """Compare ``est`` with the GNSS fixes of ``drive`` (module docstring)."""
    g = drive.gnss
    tr = est.trajectory
    if g is None or tr.t.size < 2:
        return SelfCheck(False, None, None, 0)
    # fixes near an epoch of the estimate: across a gap in its output (an IMU gap) the
    # interpolated trajectory is no estimate
    j = np.clip(np.searchsorted(tr.t, g.t), 1, tr.t.size - 1)
    near = np.minimum(np.abs(g.t - tr.t[j - 1]), np.abs(tr.t[j] - g.t))
    reach = max(NEAR_S, 5.0 * float(np.median(np.diff(tr.t))))
    inside = (g.t >= tr.t[0]) & (g.t <= tr.t[-1]) & (near <= reach)
    if not inside.any():
        return SelfCheck(False, None, None, 0)
    tg = g.t[inside]
    # heights and positions only: no attitude slerp (``Trajectory.at``) on this per-run path
    lla = np.column_stack([np.interp(tg, tr.t, tr.lla[:, j]) for j in range(3)])
    from ..nav.error_state import component

    def est_var(comp: int) -> FloatArray:
        sd = est.sigma_at(tg, comp)
        return np.zeros(tg.size) if sd is None else np.nan_to_num(sd, nan=0.0) ** 2

    r_v = lla[:, 2] - g.lla[inside, 2]
    z_v = r_v / np.sqrt(g.pos_sd[inside, 2] ** 2 + est_var(component("pos_n", 2)))
    t0 = float(tr.t[0])
    wins = {"height": _window_medians(tg, z_v, r_v, t0)}
    resid = {"height": r_v}
    if "pos_h" in est.provides:
        from ..geo.frames import lla_to_ned

        d = lla_to_ned(lla, drive.origin_lla)[:, :2] - lla_to_ned(
            g.lla[inside], drive.origin_lla)[:, :2]
        r_h = np.sqrt(np.sum(d**2, axis=1))
        var_h = (np.sum(g.pos_sd[inside, :2] ** 2, axis=1) + est_var(component("pos_n", 0))
                 + est_var(component("pos_n", 1)))
        wins["horizontal"] = _window_medians(tg, r_h / np.sqrt(var_h), r_h, t0)
        resid["horizontal"] = r_h
    n = max(len(w) for w in wins.values())
    zs = [w[1] for ws in wins.values() for w in ws]
    worst = max(zs) if zs else None
    jumps = tuple(outage_jumps(est, drive))
    flags = tuple(_jump_line(j) for j in jumps)
    for kind, ws in wins.items():
        why = _verdict(kind, ws) or _lost(kind, tg, resid[kind])
        if why:
            return SelfCheck(True, why, worst, n, jumps, flags)
    lost = [j for j in jumps if j["jump_m"] > LOST_M]
    if lost:
        return SelfCheck(True, _jump_line(lost[0]) + f": more than {LOST_M:.0f} m off for "
                         "the length of the outage", worst, n, jumps, flags)
    return SelfCheck(False, None, worst, n, jumps, flags)


def _jump_line(j: dict[str, Any]) -> str:
    sd = j["sigma_m"]
    z = f"{j['jump_m'] / sd:.0f} x its own sigma of {sd:.3g} m" if sd > 0 else "no sigma reported"
    return (f"{j['kind']} jump of {j['jump_m']:.0f} m to the first GNSS fix after a "
            f"{j['outage_s']:.0f} s outage at t = {j['t_s']:.0f} s ({z}; limit "
            f"{JUMP_SIGMA:g} sigma + {JUMP_FLOOR_M:.0f} m)")


def outage_jumps(est: Estimate, drive: Drive) -> list[dict[str, Any]]:
    """The jumps beyond ``JUMP_SIGMA`` σ + ``JUMP_FLOOR_M`` to the first fix after each GNSS
    outage of ``drive`` (module docstring): dicts with ``t_s`` (the fix), ``outage_s``,
    ``kind`` ("height" or "horizontal"), ``jump_m``, ``sigma_m`` (√(σ_fix² + σ_est²); σ_est
    0 where the estimate has no covariance) and ``limit_m``. An outage the estimate has no
    epoch inside (an IMU gap as well) or no epoch within reach of the returning fix is not
    judged."""
    g = drive.gnss
    tr = est.trajectory
    if g is None or len(g) < 2 or tr.t.size < 2:
        return []
    from ..nav.error_state import component

    reach = max(NEAR_S, 5.0 * float(np.median(np.diff(tr.t))))
    out: list[dict[str, Any]] = []
    for i in np.flatnonzero(np.diff(g.t) > OUTAGE_MIN_S):
        tb = float(g.t[i + 1])
        j = int(np.searchsorted(tr.t, tb, side="left")) - 1  # last epoch before the fix
        if j < 0 or tb - tr.t[j] > reach or tr.t[j] <= g.t[i]:
            continue
        te = np.array([tr.t[j]])

        def var(comp: int, te: FloatArray = te) -> float:
            # the variance the answer reported at its latest covariance epoch at or before
            # te (graph-isam2's real-time output has covariances at its keyframes only)
            if est.cov is None or est.t_cov is None:
                return 0.0
            v = est.cov[:, comp, comp]
            ok = np.flatnonzero(np.isfinite(v) & (est.t_cov <= te[0] + 1e-9))
            return float(max(v[ok[-1]], 0.0)) if ok.size else 0.0

        pairs = [("height", abs(float(tr.lla[j, 2] - g.lla[i + 1, 2])),
                  float(g.pos_sd[i + 1, 2]) ** 2 + var(component("pos_n", 2)))]
        if "pos_h" in est.provides:
            from ..geo.frames import lla_to_ned

            d = lla_to_ned(np.vstack([tr.lla[j], g.lla[i + 1]]), drive.origin_lla)
            pairs.append(("horizontal", float(np.hypot(*(d[0, :2] - d[1, :2]))),
                          float(np.sum(g.pos_sd[i + 1, :2] ** 2)) + var(component("pos_n", 0))
                          + var(component("pos_n", 1))))
        for kind, r, v in pairs:
            sd = float(np.sqrt(v))
            limit = JUMP_SIGMA * sd + JUMP_FLOOR_M
            if np.isfinite(r) and r > limit:
                out.append({"t_s": tb - float(drive.imu.t[0]), "outage_s": float(tb - g.t[i]),
                            "kind": kind, "jump_m": r, "sigma_m": sd, "limit_m": limit})
    return out


def far_off(maxima: dict[str, float | None], basis: str) -> str | None:
    """The reason an answer is not one when any of its largest errors ``maxima`` (name →
    max |error| [m] against ``basis``, e.g. truth or the withheld fixes) exceeds ``LOST_M``;
    None otherwise."""
    for name, v in maxima.items():
        if v is not None and np.isfinite(v) and v > LOST_M:
            return (f"{name} error up to {v:.0f} m against {basis} (limit {LOST_M:.0f} m): "
                    "not an answer")
    return None


def check_answers(est: Estimate, online: Estimate | None, drive: Drive) -> SelfCheck:
    """:func:`self_check` of the final trajectory ``est`` and of the causal answer
    ``online`` (``metrics.causal_view(est, "online")``; None where there is none); diverged
    when either is, the reason prefixed "online answer: " when only the causal one is. Its
    flags are added to the final answer's, prefixed the same way."""
    final = self_check(est, drive)
    view = online
    if view is None:
        return final
    onl = self_check(view, drive)
    flags = final.flags + tuple(f"online answer: {f}" for f in onl.flags
                                if f not in final.flags)
    diverged, reason = final.diverged, final.reason
    if not diverged and onl.diverged:
        diverged, reason = True, f"online answer: {onl.reason}"
    return SelfCheck(diverged, reason, final.worst_z, final.windows, final.jumps, flags, onl)
