"""IMU units decided on the raw samples (``unit_fixes``), before any reader's range screen:
specific force in g (× g0) or in g·g0 (÷ g0) from its median magnitude, a gyro in deg/s
(× π/180) from its 1 s block means. Every reader (DataFlash, ULog, Sensor Logger, ``.npz``)
calls it; ``imu_checks`` holds the checks that follow (axes, hostile samples) and decides
units for a drive that reaches ``sanity.check_drive`` another way."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..geo.earth import G0
from ..types.streams import FloatArray

ACCEL_IN_G = (0.6, 1.4)
ACCEL_TWICE = (60.0, 140.0)
DEG_BUSY = 8.0  # rad/s: 99.9th pct of 1 s mean |ω| above this (458 deg/s held 1 s) → deg/s
DEG_QUIET = 0.5  # rad/s: even the quietest seconds turn at 29 deg/s → deg/s


def block_means(t: FloatArray, x: FloatArray, block_s: float) -> tuple[FloatArray, FloatArray]:
    # np.unique, not bincount over the raw index: one stamp far in the future (a flipped
    # bit) must not allocate an array as long as the time it spans
    _, k = np.unique(np.floor((t - t[0]) / block_s), return_inverse=True)
    n = np.bincount(k)
    tm = np.bincount(k, weights=t) / n
    xm = np.column_stack([np.bincount(k, weights=x[:, j]) / n for j in range(x.shape[1])])
    return tm, xm


def gyro_in_degrees(st: dict[str, float]) -> bool:
    """Do the 1 s block statistics of :func:`rotation_stats` (``busy``, ``quiet``,
    ``blocks``) say the gyro is in deg/s? (``DEG_BUSY``, ``DEG_QUIET``; at least 5 blocks)"""
    return st["blocks"] >= 5 and (st["busy"] > DEG_BUSY or st["quiet"] > DEG_QUIET)


@dataclass(frozen=True)
class UnitFix:
    """One unit conversion decided on raw samples: multiply ``field`` (``"gyro"`` or
    ``"accel"``) by ``factor``; ``reason`` is the ``meta["repaired"]`` key, ``warning`` the
    ``meta["warnings"]`` line."""

    field: str
    factor: float
    reason: str
    warning: str


GYRO_DEG_REASON = "gyro in deg/s: multiplied by pi/180"
ACCEL_G_REASON = "specific force in g: multiplied by 9.80665"
ACCEL_G2_REASON = "specific force multiplied by g twice: divided by 9.80665"


def unit_fixes(t: FloatArray, gyro: FloatArray, accel: FloatArray) -> list[UnitFix]:
    """The unit conversions the raw IMU samples need (module docstring), decided before any
    range screen: specific force in g (× g0) or in g·g0 (÷ g0) from its median magnitude,
    gyro in deg/s (× π/180) from its 1 s block means. Rows with a non-finite value or stamp
    are ignored; the stamps may be unsorted. The gyro is left undecided (no fix) when the
    median sample interval is outside [5e-5, 2] s: stamps in the wrong unit, which
    ``sanity`` refuses. A magnitude that is neither g units nor m/s² gives no fix here
    (``check_drive`` refuses it)."""
    t = np.asarray(t, dtype=float)
    gyro = np.asarray(gyro, dtype=float)
    accel = np.asarray(accel, dtype=float)
    ok = np.isfinite(t) & np.all(np.isfinite(gyro), axis=1) & np.all(np.isfinite(accel), axis=1)
    if ok.sum() < 10:
        return []
    t, gyro, accel = t[ok], gyro[ok], accel[ok]
    fixes: list[UnitFix] = []
    mag = float(np.median(np.linalg.norm(accel, axis=1)))
    if ACCEL_IN_G[0] <= mag <= ACCEL_IN_G[1]:
        fixes.append(UnitFix("accel", G0, ACCEL_G_REASON,
                             f"imu: median |specific force| {mag:.3g} is g units, not m/s^2: "
                             "converted (x 9.80665)"))
    elif ACCEL_TWICE[0] <= mag <= ACCEL_TWICE[1]:
        fixes.append(UnitFix("accel", 1.0 / G0, ACCEL_G2_REASON,
                             f"imu: median |specific force| {mag:.4g} m/s^2 is about g^2: "
                             "converted twice to m/s^2; divided by 9.80665"))
    ts = np.sort(t)
    dt = float(np.median(np.diff(ts))) if ts.size > 1 else 0.0
    if 5e-5 <= dt <= 2.0:
        _, wm = block_means(t - ts[0], gyro, 1.0)
        n = np.linalg.norm(wm, axis=1)
        st = {"quiet": float(np.percentile(n, 2)), "busy": float(np.percentile(n, 99.9)),
              "blocks": float(n.size)}
        if gyro_in_degrees(st):
            fixes.append(UnitFix("gyro", np.pi / 180.0, GYRO_DEG_REASON,
                                 f"imu: gyro rates look like deg/s (quietest second "
                                 f"{st['quiet']:.2g}, busiest {st['busy']:.3g} 'rad/s'): "
                                 "converted (x pi/180) before any range check"))
    return fixes
