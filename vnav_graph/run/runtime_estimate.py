"""How long a run will take, said before it starts (``run_hint``).

A per-sample cost model per estimator, seconds = a·(IMU samples / 10⁴) + b·(keyframes / 100)
+ c·(keyframes × heading factors / 10⁵), fitted by non-negative least squares to runs of
every estimator on the default, cold-start-phone and sortie scenarios, hill-drive (120, 480 s),
hill-drive-mag (120, 240, 480 s) and four shared real logs (``benchmarks/runtime_model.py``
measures the runs, fits the table and writes the predicted/measured ratio of every run).
Keyframes: one per second, one per 5 s on averaged ≤ 2 Hz IMU logs (the graph smoothers'
rule); heading factors: one per second of a drive whose magnetometer is usable. The last
term is graph-isam2's: each magnetometer heading factor is a Python ``CustomFactor`` that
iSAM2's C++ relinearisation calls with a copy of all the variables, so its cost grows as
keyframes × factors
(hill-drive-mag 120 / 240 / 480 s: 11.6 / 37.0 / 107 s, against 8.8 / 36.1 s for
hill-drive 120 / 480 s without the magnetometer).

The coefficients were measured on a 2-core machine shared with other jobs (one measurement of
each run, so the load shows: the same run can take twice as long). The fitted model is within
a factor 0.32–1.62 of every measured graph-isam2 run and 0.4–3.3 of the much shorter other
runs, which is what a hint needs: on every real log graph-isam2 takes most of the run, as its
custom terms grow with the keyframes (docs/real_logs.md, "Run-time model").
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..types import Drive

# seconds per (10⁴ IMU samples, 100 keyframes, 10⁵ keyframe × heading-factor pairs)
COST: dict[str, tuple[float, float, float]] = {
    "observer1d": (0.0953, 0.0136, 0.0),
    "loop2": (0.101, 0.0118, 0.0),
    "loop3": (0.103, 0.0114, 0.0),
    "loop3-adaptive": (0.102, 0.0118, 0.0),
    "vkf4": (0.102, 0.0335, 0.0),
    "vekf7": (0.13, 0.0982, 0.0),
    "ekf": (0.101, 0.0484, 0.0),
    "ekf-rts": (0.0891, 0.127, 0.0),
    "graph-isam2": (0.109, 4.93, 43.1),
    "graph-batch": (0.0957, 0.348, 0.0),
}
LOW_RATE_DT = 0.5  # median IMU spacing [s] from which keyframes are 5 s apart (graph settings)
LONG_RUN_S = 60.0  # a predicted run at least this long gets the hint


def features(drive: Drive) -> tuple[float, float, float]:
    """(IMU samples / 10⁴, keyframes / 100, keyframes × heading factors / 10⁵) of ``drive``."""
    from ..sensors.magnetometer import MAG_INTERVAL_S, usable

    n_imu = len(drive.imu)
    dt = np.diff(drive.imu.t)
    kf_dt = 5.0 if dt.size and float(np.median(dt)) >= LOW_RATE_DT else 1.0
    k = drive.duration_s / kf_dt
    m = drive.duration_s / MAG_INTERVAL_S if usable(drive.mag)[0] else 0.0
    return n_imu / 1e4, k / 100.0, k * m / 1e5


def predict(drive: Drive, names: Sequence[str]) -> dict[str, float | None]:
    """Predicted runtime [s] of each estimator on ``drive`` (None for one not in ``COST``,
    e.g. a plugin)."""
    f = features(drive)
    return {n: (float(np.dot(COST[n], f)) if n in COST else None) for n in names}


def _duration(s: float) -> str:
    return f"{s:.0f} s" if s < 90 else f"{s / 60:.1f} min"


def run_hint(drive: Drive, names: Sequence[str], holdout: bool) -> str | None:
    """One line when the run of ``names`` on ``drive`` (twice with a real log's holdout run)
    is predicted to take at least ``LONG_RUN_S``: the total, the slowest estimator's share
    and the ``--estimators`` list without it; None otherwise."""
    times = {n: t for n, t in predict(drive, names).items() if t is not None}
    runs = 2 if holdout else 1
    total = runs * sum(times.values())
    if total < LONG_RUN_S or not times:
        return None
    slow = max(times, key=times.__getitem__)
    rest = [n for n in names if n != slow]
    twice = " (the run and the holdout run; --no-holdout: one)" if holdout else ""
    line = (f"this run will take about {_duration(total)}{twice}, {slow} "
            f"{_duration(runs * times[slow])} of it")
    if rest and runs * times[slow] >= 0.5 * total:
        line += f"; --estimators {','.join(rest)} skips it"
    return line
