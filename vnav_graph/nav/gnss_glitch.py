"""GNSS position glitches: fixes that jump away faster than any vehicle moves, and come back.

A step between consecutive fixes faster than ``max_speed`` is impossible motion. When such a
step leaves fix ``i`` and a later step returns to a fix ``j + 1`` that is reachable from fix
``i`` at ``max_speed`` (``|p[j+1] − p[i]| ≤ max_speed · (t[j+1] − t[i])``) within ``max_s``
seconds, the fixes ``i + 1 .. j`` in between are a glitch: the receiver (multipath, a
wrong ambiguity, spoofing) reported another place for a while. One fix out and back is the
isolated spike; a block of fixes (a 10 km jump held for 5 s) is the same pattern.

A fast step with no return inside ``max_s`` (a lasting shift) is not repaired here: which
side of it is right cannot be told from the positions alone.

Horizontal and vertical differ: GNSS height has the barometer to be checked against (every
estimator gates it), horizontal position has nothing but this speed test. Callers therefore
pass horizontal positions for glitches of any length and take only isolated spikes
(``max_fixes=1``) from the 3-D positions: a block of wrong heights lasting tens of seconds
(docs/real_logs.md, "GNSS screens") is left to the estimators' height gates, and reported
by the input checks.

Used by the input checks (``vnav_graph.io.sanity``: the fixes are dropped with a warning)
and by the factor graph's GNSS pre-gate (``estimators.graph.problem``), so that a drive that
did not pass the input checks (a simulated one) is gated the same way.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

# no vehicle of this package moves faster between fixes [m/s]; the input checks' limit
MAX_SPEED = 150.0
# the longest glitch repaired [s]: a receiver that reports a wrong place for longer than a
# minute is more likely a lasting change (a datum switch) than a glitch
MAX_GLITCH_S = 60.0


def glitch_mask(t: NDArray[np.float64], pos: NDArray[np.float64],
                max_speed: float = MAX_SPEED, max_s: float = MAX_GLITCH_S,
                max_fixes: int | None = None) -> NDArray[np.bool_]:
    """True for the fixes inside out-and-back glitches (module docstring).

    ``t`` (N,) increasing time [s]; ``pos`` (N, 2 or 3) positions in a local metric frame [m]
    (rows with NaN are never glitches and never end one); ``max_fixes``: the most fixes one
    glitch may hold (1: isolated spikes only; None: any number inside ``max_s``).
    """
    n = int(t.size)
    bad = np.zeros(n, dtype=bool)
    if n < 3:
        return bad
    ok = np.all(np.isfinite(pos), axis=1) & np.isfinite(t)
    idx = np.flatnonzero(ok)
    if idx.size < 3:
        return bad
    tt, pp = t[idx], pos[idx]
    dt = np.diff(tt)
    with np.errstate(divide="ignore", invalid="ignore"):
        fast = np.linalg.norm(np.diff(pp, axis=0), axis=1) > max_speed * np.maximum(dt, 0.0)
    out = np.flatnonzero(fast)
    k = 0
    while k < out.size:
        i = int(out[k])  # the step i -> i + 1 leaves
        end = -1
        for j in out[k + 1:]:
            j = int(j)
            if tt[j + 1] - tt[i] > max_s or (max_fixes is not None and j - i > max_fixes):
                break
            if np.linalg.norm(pp[j + 1] - pp[i]) <= max_speed * (tt[j + 1] - tt[i]):
                end = j  # the step j -> j + 1 returns
                break
        if end < 0:
            k += 1
            continue
        bad[idx[i + 1:end + 1]] = True
        k = int(np.searchsorted(out, end, side="right"))
    return bad


def causal_glitch_mask(t: NDArray[np.float64], pos: NDArray[np.float64],
                       max_speed: float = MAX_SPEED,
                       max_s: float = MAX_GLITCH_S) -> NDArray[np.bool_]:
    """``glitch_mask``'s rule decided fix by fix from the fixes up to each one (a real-time
    answer's pre-gate: it may not wait for a glitch's return).

    A step faster than ``max_speed`` from the last kept fix ``i`` opens a glitch: that fix and
    the following ones are refused until a fast step lands back within reach of fix ``i``
    (``|p[j] − p[i]| ≤ max_speed · (t[j] − t[i])``), which is kept and closes it. A glitch
    still open ``max_s`` after fix ``i`` is taken as a lasting shift: from the first fix past
    ``max_s`` on, fixes are kept again (the refused ones stay refused: they were decided when
    they arrived). On an out-and-back glitch shorter than ``max_s`` the refused fixes are
    ``glitch_mask``'s; on a lasting shift ``glitch_mask`` refuses none and this rule the fixes
    of its first ``max_s`` seconds.
    """
    n = int(t.size)
    bad = np.zeros(n, dtype=bool)
    ok = np.all(np.isfinite(pos), axis=1) & np.isfinite(t)
    idx = np.flatnonzero(ok)
    if idx.size < 2:
        return bad
    tt, pp_arr = t[idx].tolist(), pos[idx]
    anchor = -1  # the last kept fix before an open glitch (−1: none open)
    prev = 0  # the previous finite fix
    for j in range(1, idx.size):
        dt = max(tt[j] - tt[prev], 0.0)
        fast = float(np.linalg.norm(pp_arr[j] - pp_arr[prev])) > max_speed * dt
        if anchor < 0:
            if fast:
                anchor = prev
                bad[idx[j]] = True
        elif tt[j] - tt[anchor] > max_s:
            anchor = -1  # a lasting shift: kept from here on
        elif fast and (float(np.linalg.norm(pp_arr[j] - pp_arr[anchor]))
                       <= max_speed * (tt[j] - tt[anchor])):
            anchor = -1  # back within reach of the last kept fix: the glitch closes
        else:
            bad[idx[j]] = True
        prev = j
    return bad
