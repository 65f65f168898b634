"""The GNSS velocity σ that a log's own positions support.

A receiver reports σ for its positions and velocities; nothing makes the two agree with each
other. Between consecutive fixes k, k+1 (interval Δt) the mean velocity is the position
difference over Δt, and the trapezoid of the two reported velocities estimates the same
thing, so per NED axis

    r_k = (p_{k+1} − p_k)/Δt − (v_k + v_{k+1})/2
    var r_k = (σp_k² + σp_{k+1}²)/Δt² + (σv_k² + σv_{k+1}²)/4      (white errors)

(the trapezoid's own error, Δt²·jerk/12, is below a millimetre per second at 4 Hz and a
car's manoeuvres). The ratio R = Σ min(r²/var, ``WINSOR``)/n is 1 for a receiver whose σ
hold, below 1 where its errors are correlated in time (a Gauss-Markov position error makes
the differences smaller). Where R exceeds ``VEL_CONSISTENCY_LIMIT`` the reported σ do not
hold, and the velocities get the missing variance: each fix's σv² on that axis is raised by
Δ = 2(R − 1)·mean var r (the velocities enter var r with weight 1/2). The positions keep
their σ: a position σ too small would show as the estimators refusing the positions, and the
velocity is where an interval-averaged or late-stamped velocity shows.

Two cases where R says nothing about the velocities:

- a position outlier at fix k moves r_{k−1} by +e/Δt and r_k by −e/Δt: both pairs beyond
  5σ (χ²₃ > ``SPIKE_Z``) and pointing opposite ways (whitened cosine < −0.5) mark fix k as a
  position spike, and both pairs are left out (a velocity error at k moves both pairs the
  *same* way; a lagged velocity in a turn moves consecutive pairs alike). 10 % of the fixes
  of a 10 Hz drive moved by 10–40 m (σp 1 m) gave R ≈ 4 with them, ≈ 1 without;
- where the velocities' share of var r is below ``MIN_VEL_SHARE`` (fast fixes with metre
  σp: 0.5 % at 10 Hz, σp 1 m, σv 0.1 m/s) the positions' differences cannot tell a velocity
  error from a position σ too small, and raising σv by R·var r would make the velocities
  worthless (36 m/s in that case): R is reported, nothing is added (``unattributed``).

What the rule is for: a receiver that reports the mean velocity over the interval before its
epoch, not the velocity at it, is late by half an interval, an error of a·Δt/2 at an
acceleration a. In a vehicle's turns that is several times a centimetre-level RTK velocity
σ, and an estimator that trusts the velocities then refuses the consistent positions and
sits off them with a σ of centimetres. A receiver whose errors are correlated in time (a
single-point solution of metre σp) gives R well below 1, and its σ are kept. Simulated drives
with white errors of the stated σ (hill-drive and sortie seeds 0–2) give R = 0.96–1.06, σ
kept. Measured on the RTK drives of ``benchmarks/truth_logs.py``: docs/real_logs.md, "GNSS
velocity σ against the positions".

Units: SI (m, m/s, s); axes north, east, down.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..types.streams import FloatArray

# R above which the reported velocity σ are raised: the simulated drives' R stays within
# 0.96–1.06, a receiver whose velocity σ holds at ≤ 1.5 has it within its own claim
VEL_CONSISTENCY_LIMIT = 1.5
# r²/var is capped at this before the mean (5σ): one position glitch of 100 m at 1 Hz
# (σp 3 m) among 300 pairs then moves R by 0.17, not by 3.7 (its two pairs); an excess
# spread over the whole drive, as a late-stamped velocity gives, barely moves (docs/real_logs.md,
# "GNSS velocity σ against the positions")
WINSOR = 25.0
# both pairs of a fix beyond this whitened χ²₃ (5σ) and opposite: a position spike
SPIKE_Z = 25.0
# the velocities' share of var r below which an excess R is not attributed to them
MIN_VEL_SHARE = 0.1
# pairs further apart than this are not compared (a GNSS outage, a withheld window) [s]
MAX_PAIR_DT_S = 2.5
# fewer compared pairs than this: no verdict, σ kept
MIN_PAIRS = 20


@dataclass(frozen=True)
class VelocityConsistency:
    """R per NED axis (``ratio``), the variance added to each velocity σ² [m²/s²]
    (``added_var``, 0 where R ≤ ``VEL_CONSISTENCY_LIMIT`` or the axis is ``unattributed``),
    the number of pairs compared and of fixes left out as position spikes."""

    ratio: FloatArray
    added_var: FloatArray
    pairs: int
    spikes: int = 0
    unattributed: tuple[bool, bool, bool] = (False, False, False)

    @property
    def raised(self) -> bool:
        return bool(np.any(self.added_var > 0))

    def summary(self) -> dict[str, Any]:
        return {"ratio": [float(x) for x in self.ratio],
                "added_sd": [float(x) for x in np.sqrt(self.added_var)],
                "pairs": int(self.pairs), "spikes": int(self.spikes),
                "unattributed": [bool(x) for x in self.unattributed]}


def velocity_consistency(t: FloatArray, pos_n: FloatArray, pos_sd: FloatArray,
                         vel_n: FloatArray, vel_sd: FloatArray) -> VelocityConsistency | None:
    """R and the added velocity variance (module docstring) of fixes at times t (N,) [s] with
    positions pos_n (N, 3) [m, NED about any fixed origin], their σ pos_sd (N, 3) [m],
    velocities vel_n (N, 3) [m/s] and σ vel_sd (N, 3) [m/s]. None with fewer than
    ``MIN_PAIRS`` comparable pairs (consecutive, finite, Δt in (0, ``MAX_PAIR_DT_S``])."""
    t = np.asarray(t, dtype=float)
    if t.size < 2:
        return None
    dt = np.diff(t)
    ok = (dt > 0) & (dt <= MAX_PAIR_DT_S)
    dts = np.where(ok, dt, 1.0)[:, None]
    r = (pos_n[1:] - pos_n[:-1]) / dts - 0.5 * (vel_n[1:] + vel_n[:-1])
    var_v = 0.25 * (vel_sd[1:] ** 2 + vel_sd[:-1] ** 2)  # the velocities' part of var r
    var = (pos_sd[1:] ** 2 + pos_sd[:-1] ** 2) / dts**2 + var_v
    ok &= np.all(np.isfinite(r), axis=1) & np.all(np.isfinite(var) & (var > 0), axis=1)
    spike = _position_spikes(r, var, ok)
    ok &= ~spike[1:] & ~spike[:-1]  # pairs k−1 → k and k → k+1 of a spike at fix k
    n = int(ok.sum())
    if n < MIN_PAIRS:
        return None
    z = np.minimum(r[ok] ** 2 / var[ok], WINSOR)
    ratio = np.mean(z, axis=0)
    mean_var = np.mean(var[ok], axis=0)
    excess = ratio > VEL_CONSISTENCY_LIMIT
    unattributed = excess & (np.mean(var_v[ok], axis=0) / mean_var < MIN_VEL_SHARE)
    added = np.where(excess & ~unattributed, 2.0 * (ratio - 1.0) * mean_var, 0.0)
    return VelocityConsistency(ratio=ratio, added_var=added, pairs=n,
                               spikes=int(spike.sum()),
                               unattributed=tuple(bool(x) for x in unattributed))


def _position_spikes(r: FloatArray, var: FloatArray, ok: np.ndarray) -> np.ndarray:
    """(N,) bool over fixes: interior fixes whose two pairs (residuals r (N−1, 3), variances
    var) are both comparable, beyond ``SPIKE_Z`` and opposite (module docstring)."""
    w = np.where(ok[:, None], r, 0.0) / np.sqrt(np.where(ok[:, None], var, 1.0))
    z = np.sum(w**2, axis=1)
    big = ok & (z > SPIKE_Z)
    cos = np.sum(w[:-1] * w[1:], axis=1) / np.sqrt(np.maximum(z[:-1] * z[1:], 1e-300))
    spike = np.zeros(r.shape[0] + 1, dtype=bool)
    spike[1:-1] = big[:-1] & big[1:] & (cos < -0.5)
    return spike
