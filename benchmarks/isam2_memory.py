"""Is graph-isam2's online pass flat in memory as the drive grows?

    python benchmarks/isam2_memory.py [--hours 1,6] [--seed 0] --out DIR

For each drive length, in a fresh process of its own, a hill-drive (200 Hz IMU, the estimator
never reads the truth) is simulated and graph-isam2 run on it once, after a warm-up run on a
60 s drive (numba's kernels and GTSAM loaded, not counted). The resident memory
(``/proc/self/status`` VmRSS) is read after every ``SAMPLE_EVERY``-th online update, so the
memory is known against the keyframe reached, not against wall time. Writes
``DIR/isam2_memory.json``::

    {"schema": "vnav_graph.isam2_memory/1", "window_s": ..., "runs": [
        {"hours", "keyframes", "rss_before_mb", "online_peak_growth_mb",
         "run_peak_growth_mb", "slope_mb_per_h", "records_mb_per_h",
         "online_s", "samples": [[keyframe, rss_mb], ...]}],
     "online_peak_growth_ratio": <longest / shortest online_peak_growth_mb>}

- ``online_peak_growth_mb``: the largest sampled RSS during the online pass minus the RSS
  before the run (the drive, the interpreter, GTSAM and numba's kernels excluded).
- ``run_peak_growth_mb``: the process high-water mark over the whole run (final rounds, the
  batch check and the outputs included; the mark is reset before the run, Linux only) minus
  the RSS before it.
- ``slope_mb_per_h``: least-squares slope of the sampled RSS over the second half of the
  online pass, in MB per hour of drive: what the pass keeps per keyframe once the window
  is full.
- ``records_mb_per_h``: the part of it the answers must keep, per hour of drive: the online
  and lag covariances (``Estimate.online_cov``, ``lag_cov``), the online trajectory, and the
  conditionals of the keyframes that left the window (``Window``: ``r``, ``s``, ``d``).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_graph import StagePeaks  # noqa: E402

SAMPLE_EVERY = 100


def rss_mb() -> float:
    return StagePeaks.status_mb("VmRSS:") or float("nan")


def records_mb(est: Any, window: Any) -> float:
    """Megabytes of the O(keyframes) records an estimate's answers need."""
    n = 0
    for a in (est.online_cov, est.lag_cov):
        n += a.nbytes if a is not None else 0
    if est.online is not None:
        n += sum(v.nbytes for v in vars(est.online).values() if isinstance(v, np.ndarray))
    if window is not None:
        n += sum(c.r.nbytes + c.s.nbytes + c.d.nbytes
                 for conds, _ in window.groups for c in conds)
    return n / 1e6


def run_one(hours: float, seed: int) -> dict[str, Any]:
    from vnav_graph.estimators.graph import GraphISAM2
    from vnav_graph.estimators.graph.isam2.online import OnlinePass
    from vnav_graph.simulation.scenario import simulate

    GraphISAM2().run(simulate("hill-drive", seed, duration_s=60.0, imu_rate_hz=200.0))
    drive = simulate("hill-drive", seed, duration_s=3600.0 * hours,
                     imu_rate_hz=200.0).replace(truth=None, baro_truth=None)
    samples: list[tuple[int, float]] = []
    windows: list[Any] = []
    original = OnlinePass.update

    def sampled(self: Any, k: int) -> None:
        original(self, k)
        if k % SAMPLE_EVERY == 0:
            samples.append((k, rss_mb()))
            if not windows or windows[-1] is not self.win:
                windows.append(self.win)

    stages = StagePeaks()
    stages.start()  # collect, trim the C heap, reset the high-water mark
    before = rss_mb()
    OnlinePass.update = sampled
    try:
        t0 = time.perf_counter()
        est = GraphISAM2().run(drive)
        wall = time.perf_counter() - t0
    finally:
        OnlinePass.update = original
    stages.end("graph-isam2")
    kf = np.array([k for k, _ in samples], float)
    mb = np.array([m for _, m in samples])
    n_kf = int(est.info["keyframes"])
    half = kf >= 0.5 * n_kf
    per_kf = float(np.polyfit(kf[half], mb[half], 1)[0]) if half.sum() >= 3 else None
    kf_per_h = n_kf / (3600.0 * hours)
    window = windows[-1] if windows else None
    return {"hours": hours, "keyframes": n_kf, "rss_before_mb": before,
            "online_peak_growth_mb": float(mb.max() - before),
            "run_peak_growth_mb": stages.growth["graph-isam2"],
            "slope_mb_per_h": None if per_kf is None else per_kf * kf_per_h * 3600.0,
            "records_mb_per_h": records_mb(est, window) / hours,
            "online_s": float(est.info["online_s"]), "run_s": wall,
            "samples": [[int(k), round(m, 1)] for k, m in samples]}


def main(argv: list[str] | None = None) -> dict[str, Any]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hours", default="1,6", help="drive lengths [h], comma-separated")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path)
    ap.add_argument("--single", type=float, default=None, help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.single is not None:  # one length, in this process (the parent starts one per length)
        print(json.dumps(run_one(a.single, a.seed)))
        return {}
    if a.out is None:
        ap.exit(2, "isam2_memory: --out is required\n")
    try:
        hours = sorted(float(h) for h in a.hours.split(",") if h.strip())
    except ValueError:
        ap.exit(2, f"isam2_memory: --hours must be numbers, got {a.hours!r}\n")
    if not hours or min(hours) <= 0:
        ap.exit(2, "isam2_memory: --hours must be positive\n")
    from vnav_graph.estimators.graph import GraphConfig

    runs = []
    for h in hours:
        proc = subprocess.run([sys.executable, __file__, "--single", str(h), "--seed",
                               str(a.seed)], capture_output=True, text=True, check=False)
        if proc.returncode != 0:
            ap.exit(2, f"isam2_memory: the {h} h run failed: "
                       f"{(proc.stderr.strip().splitlines() or ['?'])[-1]}\n")
        r = json.loads(proc.stdout.strip().splitlines()[-1])
        print(json.dumps({k: v for k, v in r.items() if k != "samples"}), file=sys.stderr)
        runs.append(r)
    out = {"schema": "vnav_graph.isam2_memory/1", "window_s": GraphConfig().isam2_window_s,
           "runs": runs,
           "online_peak_growth_ratio": runs[-1]["online_peak_growth_mb"]
           / runs[0]["online_peak_growth_mb"]}
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / "isam2_memory.json").write_text(json.dumps(out, indent=2) + "\n")
    print(json.dumps({k: v for k, v in out.items() if k != "runs"}, indent=2))
    return out


if __name__ == "__main__":
    main()
