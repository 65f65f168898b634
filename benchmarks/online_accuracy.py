"""Online (causal) accuracy: graph-isam2's online estimate against the forward ekf, paired
per seed on ``hill-drive`` and ``sortie``.

Both estimators run on the same simulated drive; their *online* trajectories are scored
against the truth

- at common epochs: graph-isam2's keyframes (the ekf's IMU-rate output is interpolated
  there), so that one epoch weighs the same in both scores;
- from the time of the ekf's ``START_FIXES``-th GNSS fix on: the ekf starts at the median of
  its first ``START_FIXES`` fixes, so its estimate before that fix uses later data and is not
  causal. The score over the whole drive is reported too (``*_all``).

Reported per seed: horizontal and vertical RMSE [m] of both; aggregates: their means, the
ratios of the means, the number of seeds where graph-isam2 ≤ ekf, and the paired difference
graph-isam2 − ekf (mean over seeds and its standard error, ``diff_mean`` / ``diff_se``).
Goal: the online graph at least as accurate as the ekf, horizontally and
vertically.

Usage::

    python benchmarks/online_accuracy.py [--seeds N] [--duration S] [--workers W]
        [--scenarios hill-drive,sortie] --out DIR

Writes ``DIR/online_accuracy.json``.
"""

from __future__ import annotations

import argparse
import json
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

SCHEMA = "vnav_graph.online_accuracy/1"


def _ned_err(drive: Any, traj: Any, t: np.ndarray) -> np.ndarray:
    from vnav_graph.geo.frames import lla_to_ned

    ned = lla_to_ned(traj.lla, drive.origin_lla)
    at = np.column_stack([np.interp(t, traj.t, ned[:, i]) for i in range(3)])
    return at - lla_to_ned(drive.truth.at(t).lla, drive.origin_lla)


def _rmse(e: np.ndarray) -> tuple[float, float]:
    return (float(np.sqrt(np.mean(e[:, 0] ** 2 + e[:, 1] ** 2))),
            float(np.sqrt(np.mean(e[:, 2] ** 2))))


def run_one(job: tuple[str, int, float]) -> dict[str, Any]:
    """Score the online estimates of graph-isam2 and ekf on ``scenario`` / ``seed``."""
    from vnav_graph.estimators.base import create
    from vnav_graph.estimators.ekf.alignment import START_FIXES
    from vnav_graph.simulation.scenario import load_scenario, simulate

    scenario, seed, duration = job
    drive = simulate(load_scenario(scenario, duration_s=duration), seed=seed)
    t0 = time.perf_counter()
    g = create("graph-isam2").run(drive)
    t_graph = time.perf_counter() - t0
    t0 = time.perf_counter()
    e = create("ekf").run(drive)
    t_ekf = time.perf_counter() - t0
    assert g.online is not None
    t = g.online.t
    t_causal = float(drive.gnss.t[min(START_FIXES, len(drive.gnss.t)) - 1])
    m = t >= t_causal
    eg, ee = _ned_err(drive, g.online, t), _ned_err(drive, e.trajectory, t)
    out: dict[str, Any] = {"scenario": scenario, "seed": seed, "duration_s": duration,
                           "t_causal_s": t_causal - float(t[0]), "epochs": int(m.sum()),
                           "runtime_s": {"graph-isam2": t_graph, "ekf": t_ekf},
                           "trajectory_source": g.info.get("trajectory_source")}
    for name, err in (("graph-isam2", eg), ("ekf", ee)):
        h, v = _rmse(err[m])
        ha, va = _rmse(err)
        out[name] = {"horiz_rmse_m": h, "vert_rmse_m": v,
                     "horiz_rmse_all_m": ha, "vert_rmse_all_m": va}
    return out


def aggregate(runs: list[dict[str, Any]]) -> dict[str, Any]:
    agg: dict[str, Any] = {}
    for scen in sorted({r["scenario"] for r in runs}):
        rs = [r for r in runs if r["scenario"] == scen]
        a: dict[str, Any] = {"n_seeds": len(rs)}
        for key in ("horiz_rmse_m", "vert_rmse_m", "horiz_rmse_all_m", "vert_rmse_all_m"):
            g = np.array([r["graph-isam2"][key] for r in rs])
            e = np.array([r["ekf"][key] for r in rs])
            d = g - e
            a[key] = {"graph-isam2": float(g.mean()), "ekf": float(e.mean()),
                      "ratio": float(g.mean() / e.mean()),
                      "seeds_graph_le_ekf": int(np.sum(g <= e)),
                      # paired per seed: the mean difference and its standard error
                      "diff_mean": float(d.mean()),
                      "diff_se": float(d.std(ddof=1) / np.sqrt(d.size)) if d.size > 1
                      else None}
        a["goal_met"] = bool(a["horiz_rmse_m"]["ratio"] <= 1.0
                             and a["vert_rmse_m"]["ratio"] <= 1.0)
        agg[scen] = a
    return agg


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--duration", type=float, default=600.0)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--scenarios", default="hill-drive,sortie")
    ap.add_argument("--out", type=Path, required=True)
    a = ap.parse_args(argv)
    jobs = [(s, k, a.duration) for s in a.scenarios.split(",") for k in range(a.seeds)]
    with ProcessPoolExecutor(max_workers=a.workers) as pool:
        runs = []
        for r in pool.map(run_one, jobs):
            runs.append(r)
            print(f"{r['scenario']} seed {r['seed']}: graph-isam2 "
                  f"{r['graph-isam2']['horiz_rmse_m']:.3f} / {r['graph-isam2']['vert_rmse_m']:.3f}"
                  f" m, ekf {r['ekf']['horiz_rmse_m']:.3f} / {r['ekf']['vert_rmse_m']:.3f} m",
                  flush=True)
    res = {"schema": SCHEMA, "seeds": a.seeds, "duration_s": a.duration, "runs": runs,
           "aggregate": aggregate(runs)}
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / "online_accuracy.json").write_text(json.dumps(res, indent=1))
    print(json.dumps(res["aggregate"], indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
