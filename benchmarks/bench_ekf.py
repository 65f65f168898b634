"""Speed of the reference EKF (the speed baseline of docs/design.md).

``bench_ekf(duration_s, imu_rate_hz) -> dict`` simulates a hill-drive of that length and rate
and times ``ekf`` (and ``ekf-rts``) on it after a warm-up run (numba compilation excluded).
``benchmarks/bench_graph.py`` imports it for the ``ekf_s`` / ``ekf_realtime_factor`` fields of
``graph_perf.json``. Run alone it writes ``ekf_perf.json``:

    python benchmarks/bench_ekf.py [--quick] [--duration S] --out DIR
"""

from __future__ import annotations

import argparse
import json
import resource
import time
from pathlib import Path
from typing import Any

from vnav_graph.estimators.ekf.filter import EKF, EKFRTS
from vnav_graph.simulation.scenario import simulate


def bench_ekf(duration_s: float = 3600.0, imu_rate_hz: float = 200.0, seed: int = 0,
              with_rts: bool = True, drive: Any = None) -> dict[str, Any]:
    """Time ``ekf`` (and ``ekf-rts``) on a simulated hill-drive; returns a JSON-able dict.
    ``drive``: that hill-drive when the caller already has it (``bench_graph.py``), else it
    is simulated here."""
    warm = simulate("hill-drive", seed, duration_s=60.0, imu_rate_hz=imu_rate_hz)
    EKF().run(warm)
    EKFRTS().run(warm)
    del warm
    if drive is None:
        drive = simulate("hill-drive", seed, duration_s=duration_s, imu_rate_hz=imu_rate_hz)
    t0 = time.perf_counter()
    est = EKF().run(drive)
    ekf_s = time.perf_counter() - t0
    out: dict[str, Any] = {
        "drive_duration_s": drive.duration_s,
        "imu_rate_hz": imu_rate_hz,
        "imu_samples": len(drive.imu),
        "ekf_s": ekf_s,
        "ekf_realtime_factor": drive.duration_s / ekf_s,
        "ekf_cov_rate_hz": est.info["cov_rate_hz"],
    }
    if with_rts:
        t0 = time.perf_counter()
        EKFRTS().run(drive)
        rts_s = time.perf_counter() - t0
        out["ekf_rts_s"] = rts_s
        out["ekf_rts_realtime_factor"] = drive.duration_s / rts_s
    out["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    return out


def main(argv: list[str] | None = None) -> dict[str, Any]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="10-minute drive instead of 1 hour")
    ap.add_argument("--duration", type=float, default=None, help="drive length [s]")
    ap.add_argument("--rate", type=float, default=200.0, help="IMU rate [Hz]")
    ap.add_argument("--out", type=Path, required=True)
    a = ap.parse_args(argv)
    dur = a.duration if a.duration is not None else (600.0 if a.quick else 3600.0)
    res = bench_ekf(dur, a.rate)
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / "ekf_perf.json").write_text(json.dumps(res, indent=2))
    print(json.dumps(res, indent=2))
    return res


if __name__ == "__main__":
    main()
