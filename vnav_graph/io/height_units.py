"""GNSS height unit check (run by ``io.sanity.check_drive``): feet, or another scale error.

Evidence: how fast the GNSS height climbs against two references that do not depend on its
unit,

- the barometer's altitude (after the baro checks, so a baro in feet is already converted);
- the integral of the GNSS vertical velocity ``−v_down`` (where the log has one; receivers
  report it in m/s from Doppler, apart from the height).

Both streams are averaged over consecutive ``WINDOW_S`` windows (averaging takes out the
white part of the GNSS height noise), and the climb ratio ρ = Δh_gnss / Δh_ref between
neighbouring windows is fitted through the origin: started at the least-absolute-deviation
slope (robust to glitches covering up to half the climb), then least squares over the
windows within 3 robust σ of it. Window pairs spanning a logging gap of either stream
(``GAP_S``) are left out. A reference *decides* when its fit holds ``MIN_WINDOWS`` windows,
its standard error is at most ``MAX_REL_SD`` of ρ, the reference climbs ``MIN_TOTAL_CLIMB_M``
over the windows kept, and the fit kept ``MIN_KEPT`` of the windows (a unit error scales
every window alike; a fit that had to drop more is following a glitch).

Each deciding ρ is put in a band of ±``BAND`` (the physical bound of a barometer's scale
error, ±25 %, also used by the baro-scale check), on a log scale:

- around 1, or outside it by less than ``Z_OUT`` standard errors: metres, nothing to do;
- around 3.2808: feet → the height is multiplied by 0.3048 (an absolute unit: the datum
  converts with it), with a warning;
- around 0.3048: metres divided by 3.2808 (converted to feet twice) → × 3.2808, warned;
- closer to 1 than to either unit ratio (0.55-1.81): a scale error, not a unit: warned;
- anything else: a scale error no conversion explains → the drive is refused.

:func:`verdict` combines the two references: a height that agrees with its own vertical
velocity is in metres whatever the baro says (a receiver fault moves both: the estimators
gate it), unless the baro sees feet (then both may be in feet: warned); references that decide
differently are warned about without a repair. On a conversion the origin height moves with
the fixes when it came from them, and a log's baro, which the readers put into the GNSS
height datum, is moved by the same change over their alignment window.

Measured (ρ ± standard error against the baro / the velocity): simulated scenarios, seeds
0-2: 0.97-1.09 (hot-baro 1.08-1.09: its scale error) and 0.99-1.01 where they decide
(urban's multipath: 1.07-1.40 ± 0.15, undecided); the shared logs near 1, and a receiver
fault that moves heights and velocity together decides nothing against the baro
(docs/real_logs.md, "GNSS screens"). The corpus DataFlash log with heights in feet:
3.28 ± 0.09 and 3.28 ± 0.08.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from ..types import Drive
from ..types.streams import BaroStream, FloatArray, GnssStream, IntArray
from .findings import Findings, reject

WINDOW_S = 5.0
MIN_TOTAL_CLIMB_M = 20.0
MIN_RESIDUAL_M = 0.3  # floor of the trimming scale (a climb difference's rounding) [m]
MIN_WINDOWS = 5
MAX_REL_SD = 0.1
Z_OUT = 2.0  # standard errors beyond the metres band before a ratio counts as off
MIN_KEPT = 0.8  # a unit scales every window: a fit that had to drop more is a glitch
BAND = 0.25
FEET = 0.3048
ALIGN_WINDOW_S = 10.0  # the readers' baro datum window after the first fix [s]
GAP_S = 2.0  # a stream interval longer than this (and 3 median intervals) is a gap


def _gaps(t: FloatArray) -> FloatArray:
    """(K, 2) start and end of every logging gap of a stream."""
    if t.size < 2:
        return np.zeros((0, 2))
    dt = np.diff(t)
    k = np.flatnonzero(dt > max(GAP_S, 3.0 * float(np.median(dt))))
    return np.column_stack([t[k], t[k + 1]])


@dataclass(frozen=True)
class Climb:
    """A climb ratio fit: ρ, its standard error, the windows it kept of the usable ones and
    the reference's total climb over the kept windows [m]."""

    ratio: float
    sd: float
    kept: int
    usable: int
    climb_m: float

    @property
    def decides(self) -> bool:
        """Well determined (``MAX_REL_SD``, ``MIN_TOTAL_CLIMB_M``) and uniform over the drive
        (``MIN_KEPT``)."""
        return (self.sd <= MAX_REL_SD * abs(self.ratio) and self.climb_m >= MIN_TOTAL_CLIMB_M
                and self.kept >= MIN_KEPT * self.usable)

    def text(self, ref: str) -> str:
        return (f"{self.ratio:.2f}x (± {self.sd:.2f}, {self.kept} of {self.usable} windows of "
                f"{WINDOW_S:g} s) as fast as {ref}")


def _window_means(t: FloatArray, h: FloatArray, t0: float, t1: float, window_s: float
                  ) -> tuple[IntArray, FloatArray]:
    """(window index, mean of ``h``) of every occupied ``window_s`` window in [t0, t1): only
    occupied windows are held (a stamp far in the future costs nothing)."""
    m = (t >= t0) & (t < t1)
    k = np.floor((t[m] - t0) / window_s).astype(np.int64)
    win, inv = np.unique(k, return_inverse=True)
    return win, np.bincount(inv, weights=h[m]) / np.bincount(inv)


def _weighted_median(x: FloatArray, w: FloatArray) -> float:
    o = np.argsort(x)
    c = np.cumsum(w[o])
    return float(x[o][np.searchsorted(c, 0.5 * c[-1])])


def climb_ratio(t_g: FloatArray, h_g: FloatArray, t_r: FloatArray, h_r: FloatArray,
                window_s: float = WINDOW_S) -> Climb | None:
    """The climb of ``h_g`` against ``h_r`` (:class:`Climb`), or None when fewer than
    ``MIN_WINDOWS`` pairs of windows are usable (module docstring)."""
    ok_g, ok_r = np.isfinite(h_g), np.isfinite(h_r)
    t_g, h_g, t_r, h_r = t_g[ok_g], h_g[ok_g], t_r[ok_r], h_r[ok_r]
    if t_g.size < 3 or t_r.size < 3:
        return None
    t0, t1 = max(t_g[0], t_r[0]), min(t_g[-1], t_r[-1])
    if t1 - t0 < (MIN_WINDOWS + 1) * window_s:
        return None
    wg, mg = _window_means(t_g, h_g, t0, t1, window_s)
    wr, mr = _window_means(t_r, h_r, t0, t1, window_s)
    win, ig, ir = np.intersect1d(wg, wr, return_indices=True)  # windows both streams fill
    mg, mr = mg[ig], mr[ir]
    if win.size < MIN_WINDOWS + 1:
        return None
    a = t0 + window_s * win[:-1]  # a pair of neighbouring windows spans [a, a + 2 W)
    keep = np.diff(win) == 1
    for gs in (_gaps(t_g), _gaps(t_r)):
        for g0, g1 in gs:
            keep &= ~((a < g1) & (a + 2.0 * window_s > g0))
    dg, dr = np.diff(mg), np.diff(mr)
    use = keep.copy()
    if use.sum() < MIN_WINDOWS or np.sum(dr[use] ** 2) == 0.0:
        return None
    # start: the least-absolute-deviation slope through the origin (the |Δr|-weighted median
    # of the ratios; robust to glitches covering up to half the climb), then trimmed LS
    big = use & (dr != 0.0)
    s = _weighted_median(dg[big] / dr[big], np.abs(dr[big]))
    w = use.copy()
    for _ in range(5):
        res = dg - s * dr
        mad = 1.4826 * float(np.median(np.abs(res[w])))
        w_new = use & (np.abs(res) <= 3.0 * max(mad, MIN_RESIDUAL_M))
        if w_new.sum() < MIN_WINDOWS or np.sum(dr[w_new] ** 2) == 0.0:
            break
        done = np.array_equal(w_new, w)
        w = w_new
        s = float(np.sum(dg[w] * dr[w]) / np.sum(dr[w] ** 2))
        if done:
            break
    s = float(np.sum(dg[w] * dr[w]) / np.sum(dr[w] ** 2))
    res = dg[w] - s * dr[w]
    sd = float(np.sqrt(np.sum(res**2) / max(int(w.sum()) - 1, 1) / np.sum(dr[w] ** 2)))
    return Climb(s, sd, int(w.sum()), int(use.sum()), float(np.sum(np.abs(dr[w]))))


def _band(rho: float, sd: float) -> str:
    """"metres", "feet", "twice" (within ±``BAND`` of 1, 3.2808, 0.3048), "near" (closer to
    metres than to a unit error: a scale error, not a unit) or "other". A ratio outside the
    metres band by less than ``Z_OUT`` standard errors counts as metres (not shown to be
    off)."""
    band = np.log(1.0 + BAND)
    if rho <= 0 or abs(np.log(rho)) - band <= Z_OUT * sd / rho:
        return "metres" if rho > 0 else "other"
    for name, c in (("feet", 1.0 / FEET), ("twice", FEET)):
        if abs(np.log(rho / c)) <= band:
            return name
    if abs(np.log(rho)) <= 0.5 * np.log(1.0 / FEET):
        return "near"
    return "other"


BARO = "the baro"
VEL = "its vertical velocity"
WARNINGS = {
    "near": f"a scale error beyond a barometer's ±{100 * BAND:.0f} % but no unit error",
    "disagree": "the references disagree (a unit or scale error in one of them?)",
    "both-feet": "its vertical velocity agrees with it: height and velocity both in feet?",
}


def verdict(found: dict[str, Climb]) -> tuple[str, str]:
    """(kind, the evidence in words) from the climb fits against ``BARO`` and ``VEL``.

    kind: "none" (nothing decides), "metres", "feet" / "twice" (convert), "near" / "other"
    (a scale error: warned / refused), "disagree" or "both-feet" (warned). A height that
    agrees with its own vertical velocity is in metres whatever the baro says (a receiver
    fault moves heights and velocity together while the baro is right, and the estimators
    gate it), unless the baro sees feet (both in feet).
    """
    dec = {k: v for k, v in found.items() if v.decides}
    what = ", ".join(v.text(k) for k, v in dec.items())
    bands = {k: _band(v.ratio, v.sd) for k, v in dec.items()}
    if not bands:
        return "none", what
    if bands.get(VEL) == "metres":
        return ("both-feet" if bands.get(BARO) == "feet" else "metres"), what
    if bands.get(BARO) == "metres":
        return "metres", what  # the height is right; the velocity is not this check's
    kinds = set(bands.values())
    if len(kinds) > 1:
        return "disagree", what
    return kinds.pop(), what


def check_gnss_height_units(drive: Drive, f: Findings) -> Drive | None:
    """The GNSS height unit check (module docstring); a repaired Drive, None, or ValueError."""
    g = drive.gnss
    if g is None or len(g) < 10 or float(np.ptp(g.lla[:, 2])) == 0.0:
        return None
    h = g.lla[:, 2]
    found: dict[str, Climb] = {}
    b = drive.baro
    if b is not None and len(b) >= 10:
        r = climb_ratio(g.t, h, b.t, np.asarray(b.altitude, dtype=float))
        if r is not None:
            found[BARO] = r
    if g.vel_n is not None:
        vd = np.asarray(g.vel_n[:, 2], dtype=float)
        ok = np.isfinite(vd)
        if ok.sum() >= 10:
            tv = g.t[ok]
            z = np.concatenate([[0.0], np.cumsum(-0.5 * (vd[ok][1:] + vd[ok][:-1])
                                                 * np.diff(tv))])
            r = climb_ratio(g.t, h, tv, z)
            if r is not None:
                found[VEL] = r
    f.diag["gnss_height_climb_ratio"] = {k: asdict(v) for k, v in found.items()}
    kind, what = verdict(found)
    if kind in ("metres", "none"):
        return None
    if kind in ("near", "disagree", "both-feet"):
        f.warn(f"gnss: height climbs {what}: {WARNINGS[kind]}; not repaired")
        return None
    if kind == "other":
        raise reject("gnss", f"height climbs {what}: a scale error that neither metres nor "
                     "feet explain (wrong field or unit in the log?)")
    factor = FEET if kind == "feet" else 1.0 / FEET
    how = ("feet, not metres; converted (x 0.3048)" if kind == "feet" else
           "metres divided by 3.2808 (converted to feet twice?); converted (x 3.2808)")
    lla = g.lla.copy()
    lla[:, 2] *= factor
    out = drive.replace(gnss=GnssStream(g.t, lla, g.pos_sd, g.vel_n, g.vel_sd, g.lever_arm_b,
                                        g.spec))
    o = drive.origin_lla
    if abs(o[2] - h[0]) < abs(o[2] - lla[0, 2]):  # the origin height came from the fixes
        out = out.replace(origin_lla=np.array([o[0], o[1], o[2] * factor]))
    notes = f.meta.get("notes") or []
    if b is not None and any("datum aligned to GNSS height" in str(n) for n in notes):
        # the reader put the baro into the GNSS datum: it moves with the converted heights
        # (the median change over the readers' alignment window)
        first = g.t <= g.t[0] + ALIGN_WINDOW_S
        shift = float(np.median(lla[first, 2] - h[first]))
        out = out.replace(baro=BaroStream(b.t, None, np.asarray(b.altitude) + shift, b.spec))
        how += f", baro datum moved {shift:+.1f} m with it"
    f.repair("gnss", f"height scaled by {factor:.6g} (unit)", len(g),
             f"gnss: height climbs {what}: {how}")
    return out
