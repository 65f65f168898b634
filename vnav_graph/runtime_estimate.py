"""How long a run will take, said before it starts (``run_hint``).

A per-sample cost model per estimator, seconds = a·(IMU samples / 10⁴) + b·(keyframes / 100)
+ c·(keyframes × heading factors / 10⁵), fitted by non-negative least squares to runs of
every estimator on three simulated scenarios, four shared real logs and five hill-drive
lengths with and without a magnetometer (``benchmarks/runtime_model.py`` measures the runs,
fits the table and writes the predicted/measured ratio of every run). Keyframes: one per
second, one per 5 s on averaged ≤ 2 Hz IMU logs (the graph smoothers' rule); heading factors:
one per second of a drive whose magnetometer is usable. The last term is graph-isam2's: each
magnetometer heading factor is a Python ``CustomFactor`` that iSAM2's C++ relinearisation
calls with a copy of all the variables, so its cost grows as keyframes × factors
(hill-drive-mag 120 / 240 / 480 s: 17 / 53 / 192 s, against 20 / 19 / 48 s without the
magnetometer).

The coefficients were measured on a 2-core machine shared with other jobs; the predictions
are within a factor of 0.3–3 of the measured runtimes (graph-isam2: 0.26 on the ski log,
1.45 on the default drive, 0.7–1.2 elsewhere), which is what a hint needs: on a real log
graph-isam2 takes most of the run (75 of 78 s on 218.BIN, 128 of 135 s on the ski log).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .types import Drive

# seconds per (10⁴ IMU samples, 100 keyframes, 10⁵ keyframe × heading-factor pairs)
COST: dict[str, tuple[float, float, float]] = {
    "observer1d": (0.0914, 0.0282, 0.0),
    "loop2": (0.122, 0.0206, 0.0),
    "loop3": (0.123, 0.0194, 0.0),
    "loop3-adaptive": (0.123, 0.0209, 0.0),
    "vkf4": (0.104, 0.0425, 0.0),
    "vekf7": (0.225, 0.00609, 0.0),
    "ekf": (0.113, 0.0667, 0.0),
    "ekf-rts": (0.151, 0.0923, 0.0),
    "graph-isam2": (1.83, 7.49, 41.5),
    "graph-batch": (0.196, 0.332, 0.0),
}
LOW_RATE_DT = 0.5  # median IMU spacing [s] from which keyframes are 5 s apart (graph settings)
LONG_RUN_S = 60.0  # a predicted run at least this long gets the hint


def features(drive: Drive) -> tuple[float, float, float]:
    """(IMU samples / 10⁴, keyframes / 100, keyframes × heading factors / 10⁵) of ``drive``."""
    from .sensors.magnetometer import MAG_INTERVAL_S, usable

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
