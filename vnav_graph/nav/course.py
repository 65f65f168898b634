"""Heading from the GNSS course over ground: the one rule of the ekf's acquisition
(``estimators.ekf.alignment.track_heading``) and the graph's initial attitude
(``estimators.graph.model.initial_guess``).

A body that moves along its x axis has the heading ψ = atan2(v_E, v_N) of its horizontal
velocity v_h. With white velocity noise of σ_v per axis the course's error is the
cross-track noise over the speed, σ_v/|v_h| (first order), and the body's own angle to its
path (sideslip of a car in a turn, the sway of a hand-held device at each step, a mounting
that is not quite along x) adds σ_β:

    σ_ψ² = σ_v² / |v_h|² + σ_β².

Test statistic and threshold. At a standstill |v_h|²/σ_v² is χ² with 2 degrees of freedom,
P(|v_h| > k σ_v) = exp(−k²/2); a course is used only where |v_h| > ``COURSE_SNR`` σ_v
(k = 5: 3.7e-6 per fix that noise alone passes; a walker at 1.2 m/s passes it with σ_v up
to 0.24 m/s), where its first term is at most 1/k = 11.5°. Elsewhere σ_ψ = π (no course).

σ_β from the data (``sway_sd``). The angle of the body to its path is measured, up to a
constant, by the course minus the heading the gyro carries: over the ``SWAY_WINDOW_S``
before a fix, their circular scatter. A car on a straight road gives a degree or two; a
hand-held device tens of degrees, its body swinging at each step about the path
(docs/real_logs.md, "Standstills and course on the RTK drives"). The σ_β used is
the larger of the configured floor (``sideslip_sd``: the mean angle, which no scatter shows)
and that scatter, so a hand-held device gets an honest σ and a car keeps the floor.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..types.streams import FloatArray

# a course counts when the horizontal speed exceeds this many σ of its velocity noise
COURSE_SNR = 5.0
# the σ_β floor: a car's sideslip in ordinary driving [rad] (``EkfConfig.sideslip_sd``)
SIDESLIP_SD = np.radians(2.0)
# the window [s] over which the scatter of course minus gyro heading measures the sway
SWAY_WINDOW_S = 2.0
# fewest usable courses in that window for a scatter (fewer: no course)
SWAY_MIN_FIXES = 3


@dataclass(frozen=True)
class Course:
    """Per-fix course over ground: yaw [rad], horizontal speed [m/s], yaw one-sigma [rad]
    (π where the course is no heading)."""

    yaw: FloatArray
    speed: FloatArray
    yaw_sd: FloatArray


def course_sd(speed: FloatArray, vel_sd: FloatArray, sideslip_sd: FloatArray | float
              ) -> FloatArray:
    """σ_ψ = √(σ_v²/|v_h|² + σ_β²) [rad] (module docstring), π where |v_h| ≤ ``COURSE_SNR``
    σ_v. ``vel_sd``: the velocity noise per horizontal axis [m/s]."""
    speed = np.asarray(speed, dtype=float)
    vel_sd = np.asarray(vel_sd, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        sd = np.sqrt((vel_sd / np.maximum(speed, 1e-9)) ** 2 + np.square(sideslip_sd))
    return np.where(speed > COURSE_SNR * vel_sd, np.minimum(sd, np.pi), np.pi)


def gyro_yaw(t_imu: FloatArray, gyro_z: FloatArray, t_q: FloatArray) -> FloatArray:
    """The heading turned since the first IMU sample [rad] at times ``t_q``: the body z rate
    integrated (trapezoid; a level body, whose z axis is down)."""
    if t_imu.size < 2:
        return np.zeros(np.shape(t_q))
    yaw = np.concatenate([[0.0], np.cumsum(0.5 * (gyro_z[1:] + gyro_z[:-1]) * np.diff(t_imu))])
    return np.interp(t_q, t_imu, yaw)


def sway_sd(t: FloatArray, yaw: FloatArray, usable: np.ndarray, yaw_gyro: FloatArray,
            window_s: float = SWAY_WINDOW_S) -> FloatArray:
    """Circular scatter [rad] of course minus gyro heading over the usable fixes of the
    ``window_s`` up to each fix (causal), √(−2 ln R) with R the mean resultant length; NaN
    where fewer than ``SWAY_MIN_FIXES`` usable fixes are in the window."""
    d = np.where(usable, yaw - yaw_gyro, 0.0)
    c = np.concatenate([[0.0], np.cumsum(np.where(usable, np.cos(d), 0.0))])
    s = np.concatenate([[0.0], np.cumsum(np.where(usable, np.sin(d), 0.0))])
    n = np.concatenate([[0], np.cumsum(usable.astype(np.int64))])
    lo = np.searchsorted(t, t - window_s, side="left")
    hi = np.arange(t.size) + 1
    cnt = n[hi] - n[lo]
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.hypot(c[hi] - c[lo], s[hi] - s[lo]) / cnt
        out = np.sqrt(-2.0 * np.log(np.clip(r, 1e-12, 1.0)))
    return np.where(cnt >= SWAY_MIN_FIXES, out, np.nan)


def course_heading(t: FloatArray, vel_ne: FloatArray, vel_sd: FloatArray,
                   sideslip_sd: float, yaw_gyro: FloatArray | None = None) -> Course:
    """The course of every fix as a heading (module docstring), from data up to the fix.

    ``t`` (N,) fix times [s]; ``vel_ne`` (N, 2) horizontal velocity [m/s]; ``vel_sd`` (N,)
    its noise per axis [m/s]; ``sideslip_sd`` the σ_β floor [rad]; ``yaw_gyro`` (N,) the
    gyro-carried heading at the fixes (``gyro_yaw``), with which σ_β grows to the sway's
    scatter and a fix needs ``SWAY_MIN_FIXES`` usable courses in its window (``SWAY_WINDOW_S``,
    or 2.5 fix intervals when longer; None: the floor alone)."""
    vel_ne = np.asarray(vel_ne, dtype=float)
    vel_sd = np.asarray(vel_sd, dtype=float)
    speed = np.hypot(vel_ne[:, 0], vel_ne[:, 1])
    yaw = np.arctan2(vel_ne[:, 1], vel_ne[:, 0])
    usable = speed > COURSE_SNR * vel_sd
    beta: FloatArray | float = sideslip_sd
    if yaw_gyro is not None:
        t = np.asarray(t, dtype=float)
        # long enough for SWAY_MIN_FIXES fixes of a slow receiver (1 Hz: 2.5 s)
        dt = float(np.median(np.diff(t))) if t.size > 1 else 0.0
        window = max(SWAY_WINDOW_S, (SWAY_MIN_FIXES - 0.5) * dt)
        sway = sway_sd(t, yaw, usable, yaw_gyro, window)
        beta = np.where(np.isnan(sway), np.inf, np.maximum(sway, sideslip_sd))
    return Course(yaw, speed, course_sd(speed, vel_sd, beta))
