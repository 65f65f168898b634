"""IMU logging gaps: one rule for every estimator, and the constant-velocity bridge.

A sample spacing Δt_i = t_{i+1} − t_i is a *logging gap* when it exceeds
max(``GAP_MIN_S``, ``GAP_FACTOR`` × the median spacing): 5 samples missing in a row, and
never less than 0.25 s (at 1 Hz an averaged phone log would otherwise count every second
missed sample). Jitter below the threshold is integrated normally.

Across a gap there is no inertial information. Every filter bridges it at constant velocity
with an unknown acceleration of PSD q = ``GAP_ACCEL_SD``² [(m/s²)²/Hz] per axis, which adds
(Groves, *Principles of GNSS, Inertial and Multisensor Integrated Navigation Systems*, 2nd
ed., §3.4.1, the constant-velocity model) q·T³/3 to the position variance, q·T²/2 to the
position-velocity covariance and q·T to the velocity variance over a gap of T seconds
(:func:`cv_bridge_noise`). The graph smoothers use the same gap rule; their gap factor bounds
the velocity change by a sustained acceleration instead (``graph.problem.GAP_ACCEL_LEVEL``).
"""

from __future__ import annotations

import numpy as np
from numba import njit

GAP_FACTOR = 5.0
GAP_MIN_S = 0.25  # s
GAP_ACCEL_SD = 1.0  # m/s²/√s, the unknown motion during a gap


def gap_threshold(t: np.ndarray) -> float:
    """The spacing [s] above which an IMU interval of the time stamps ``t`` is a gap."""
    dt = np.diff(np.asarray(t, dtype=float))
    if dt.size == 0:
        return float("inf")
    return max(GAP_MIN_S, GAP_FACTOR * float(np.median(dt)))


def imu_gaps(t: np.ndarray) -> np.ndarray:
    """Indices i (int64, ascending) whose interval t[i] → t[i+1] is a logging gap."""
    dt = np.diff(np.asarray(t, dtype=float))
    if dt.size == 0:
        return np.zeros(0, dtype=np.int64)
    return np.flatnonzero(dt > gap_threshold(t)).astype(np.int64)


@njit(cache=True)
def cv_bridge_noise(q: float, dt: float) -> tuple[float, float, float]:
    """(var position, cov position-velocity, var velocity) added over a gap of dt [s] by an
    unknown acceleration of PSD q [(m/s²)²/Hz] (module docstring); signs are the caller's
    (a down-velocity state against an up-height state flips the covariance)."""
    return q * dt**3 / 3.0, q * dt**2 / 2.0, q * dt
