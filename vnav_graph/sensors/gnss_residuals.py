"""GNSS residual autocorrelation: a truth-free sign that a drive's GNSS errors are correlated.

With white GNSS errors, the fixes' residuals against a smoothed trajectory are white too: their
autocorrelation at a lag of a few seconds is near 0. Errors correlated over tens of seconds
(``sensors.gnss_model``'s Gauss-Markov model) leave residuals whose autocorrelation at that lag
is large. ``gnss_residual_autocorr`` measures it on an estimate that does not model them
(the Gauss-Markov GNSS error state off): the number that says, on a real log, whether the
state should be carried (``docs/design.md``, "GNSS error state").
"""

from __future__ import annotations

from typing import Any

import numpy as np

from ..geo.frames import lla_to_ned, quat_to_mat
from ..types.streams import FloatArray

RESIDUAL_LAG_S = 5.0  # lag of the autocorrelation [s]
MIN_PAIRS = 20  # fewer fix pairs at that lag: no value (None)


def gnss_residuals(est: Any, drive: Any) -> tuple[FloatArray, FloatArray]:
    """(fix times (M,) [s], residuals fix − estimated antenna position (M, 3) NED at the
    drive's origin [m]) of the fixes inside the estimate's span (lever arm from the
    estimate's attitude when it has one)."""
    g = drive.gnss
    tr = est.trajectory
    t_fix = g.t - float(getattr(g.spec, "latency_s", 0.0) or 0.0)
    m = (t_fix >= tr.t[0]) & (t_fix <= tr.t[-1]) & np.all(np.isfinite(g.lla), axis=1)
    t = t_fix[m]
    at = tr.at(t)
    ant = at.pos_n(drive.origin_lla)
    lever = np.asarray(g.lever_arm_b, dtype=float)
    if np.any(lever) and at.q_nb is not None:
        ant = ant + np.einsum("nij,j->ni", quat_to_mat(at.q_nb), lever)
    return t, lla_to_ned(g.lla[m], drive.origin_lla) - ant


def lag_pairs(t: FloatArray, lag_s: float) -> tuple[np.ndarray, np.ndarray]:
    """(i, j): the fix pairs whose second fix lies within half a fix interval of t_i + lag."""
    dt = float(np.median(np.diff(t)))
    j = np.clip(np.searchsorted(t, t + lag_s), 0, t.size - 1)
    ok = np.abs(t[j] - (t + lag_s)) <= 0.5 * dt
    return np.flatnonzero(ok), j[ok]


def autocorr_at(t: FloatArray, x: FloatArray, lag_s: float) -> float | None:
    """Autocorrelation of the demeaned series x (M,) at lag ``lag_s``: Σ x_i x_j / Σ x_i²
    over the pairs whose second fix lies within half a fix interval of t_i + lag."""
    if t.size < MIN_PAIRS + 1:
        return None
    x = x - np.mean(x)
    i, j = lag_pairs(t, lag_s)
    if i.size < MIN_PAIRS:
        return None
    den = float(np.sum(x[i] ** 2))
    return float(np.sum(x[i] * x[j]) / den) if den > 0 else None


def gnss_residual_autocorr(est: Any, drive: Any, lag_s: float = RESIDUAL_LAG_S
                           ) -> dict[str, float | None] | None:
    """{"horiz": mean of the north and east residual autocorrelations, "vert": the down
    one, "lag_s", "pairs": the number of fix pairs at that lag (a white series gives ρ̂ of
    σ 1/√pairs)} at ``lag_s``; None without GNSS."""
    if drive.gnss is None or len(drive.gnss) == 0:
        return None
    t, r = gnss_residuals(est, drive)
    ac = [autocorr_at(t, r[:, a], lag_s) for a in range(3)]
    h = [a for a in ac[:2] if a is not None]
    pairs = int(lag_pairs(t, lag_s)[0].size) if t.size > 1 else 0
    return {"horiz": float(np.mean(h)) if h else None, "vert": ac[2], "lag_s": float(lag_s),
            "pairs": pairs}
