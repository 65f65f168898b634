"""What the keyframe spacing costs and buys: graph-isam2's speed and both smoothers' accuracy.

    python benchmarks/isam2_keyframe_spacing.py --out DIR [--hours 1] [--spacings 1,2,4]
        [--seed 0] [--logs 218,ski] [--data DIR]

One hill-drive (200 Hz IMU, as ``bench_graph.py``) is simulated; for each keyframe spacing
(``GraphConfig.keyframe_dt`` [s], for both graphs) graph-isam2 and graph-batch run on it in
this process, after a warm-up on a 60 s drive. Writes ``DIR/isam2_keyframe_spacing.json``::

    {"schema": "vnav_graph.isam2_keyframe_spacing/1", "hours", "seed", "epochs",
     "runs": [{"keyframe_dt", "keyframes", "isam2_s", "isam2_realtime_factor",
               "isam2_online_s", "isam2_update_p99_ms", "batch_s", "warnings",
               "online_horiz_m", "online_alt_m", "final_horiz_m", "final_alt_m",
               "batch_horiz_m", "batch_alt_m"}]}

- ``isam2_realtime_factor``: drive duration over graph-isam2's whole run (``runtime_s``), as
  ``bench_graph.py`` defines it; ``batch_s``: graph-batch's whole run.
- The RMSE [m] against the truth are taken at the same ``epochs`` for every spacing: the
  online epochs of the coarsest spacing from 60 s on (keyframes of every spacing when the
  spacings divide the coarsest), so the online estimate is read where it was computed, never
  interpolated between keyframes. ``online``: graph-isam2's causal estimate; ``final``: its
  final trajectory; ``batch``: graph-batch's.

With ``--logs`` (parts of the names of ``bench_real_logs.LOGS``; the averaged 1 Hz car logs
have their own spacing, ``isam2.LOW_RATE_SETTINGS``, and are not meant here), each shared log
present also runs the GNSS-outage holdout (``run_holdout``, as ``holdout`` runs it) with both
graphs at each spacing: ``"logs": {LOG: [{"keyframe_dt", "isam2_s", "batch_s",
"over_batch", "alt_rmse_m", "horiz_rmse_m", "batch_alt_rmse_m", "batch_horiz_rmse_m",
"online_alt_rmse_m", "online_horiz_rmse_m"}]}`` (scores against the withheld fixes).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

FIRST_S = 60.0  # scores from here on (the online estimates' opening)
sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_real_logs import data_root, present_logs, select_logs  # noqa: E402


def rmse(p: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    """Horizontal and altitude RMSE [m] of NED positions ``p`` against ``truth``."""
    e = p - truth
    return (float(np.sqrt(np.mean(np.sum(e[:, :2] ** 2, axis=1)))),
            float(np.sqrt(np.mean(e[:, 2] ** 2))))


def real_logs(which: str, data: str | None, spacings: list[float]) -> dict[str, Any]:
    """The holdout of each shared log named in ``which`` with both graphs at each spacing."""
    from vnav_graph.estimators.graph import GraphConfig
    from vnav_graph.io import load_drive
    from vnav_graph.run.runner import run_holdout

    logs = select_logs(which)
    out: dict[str, Any] = {}
    for rel, path in present_logs(data_root(data), None, logs):
        drive = load_drive(path)
        rows = []
        for dt in spacings:
            cfg = GraphConfig(keyframe_dt=dt)
            doc = run_holdout(drive, ["graph-isam2", "graph-batch"],
                              configs={"graph-isam2": cfg, "graph-batch": cfg}).doc
            g, b = doc["estimators"]["graph-isam2"], doc["estimators"]["graph-batch"]
            on = g.get("online") or {}
            rows.append({"keyframe_dt": dt, "isam2_s": g["runtime_s"], "batch_s": b["runtime_s"],
                         "over_batch": g["runtime_s"] / b["runtime_s"],
                         "alt_rmse_m": g.get("alt_rmse_m"), "horiz_rmse_m": g.get("horiz_rmse_m"),
                         "batch_alt_rmse_m": b.get("alt_rmse_m"),
                         "batch_horiz_rmse_m": b.get("horiz_rmse_m"),
                         "online_alt_rmse_m": on.get("alt_rmse_m"),
                         "online_horiz_rmse_m": on.get("horiz_rmse_m")})
            print(rel, json.dumps(rows[-1]), file=sys.stderr, flush=True)
        out[rel] = rows
    return out


def main(argv: list[str] | None = None) -> dict[str, Any]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True, type=Path)
    ap.add_argument("--hours", type=float, default=1.0)
    ap.add_argument("--spacings", default="1,2,4", help="keyframe spacings [s], comma-separated")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--logs", default=None,
                    help="also the holdout of these shared logs (comma-separated name parts)")
    ap.add_argument("--data", default=None)
    a = ap.parse_args(argv)
    try:
        spacings = sorted(float(s) for s in a.spacings.split(",") if s.strip())
    except ValueError:
        ap.exit(2, f"isam2_keyframe_spacing: --spacings must be numbers, got {a.spacings!r}\n")
    if not spacings or min(spacings) <= 0 or not a.hours > 0:
        ap.exit(2, "isam2_keyframe_spacing: --spacings and --hours must be positive\n")
    from vnav_graph.estimators.graph import GraphBatch, GraphConfig, GraphISAM2
    from vnav_graph.geo.frames import lla_to_ned
    from vnav_graph.simulation.scenario import simulate

    GraphISAM2().run(simulate("hill-drive", a.seed, duration_s=60.0, imu_rate_hz=200.0))
    drive = simulate("hill-drive", a.seed, duration_s=3600.0 * a.hours, imu_rate_hz=200.0)
    origin = drive.origin_lla
    est: dict[float, tuple[Any, Any]] = {}
    for dt in spacings:
        cfg = GraphConfig(keyframe_dt=dt)
        est[dt] = (GraphISAM2(cfg).run(drive), GraphBatch(cfg).run(drive))
        print(f"keyframe_dt {dt:g} s: graph-isam2 {est[dt][0].runtime_s:.1f} s, graph-batch "
              f"{est[dt][1].runtime_s:.1f} s", file=sys.stderr, flush=True)
    t_on = est[spacings[-1]][0].online.t
    epochs = t_on[t_on >= float(drive.imu.t[0]) + FIRST_S]
    truth = lla_to_ned(drive.truth.at(epochs).lla, origin)
    runs = []
    for dt in spacings:
        gi, gb = est[dt]
        row: dict[str, Any] = {
            "keyframe_dt": dt, "keyframes": int(gi.info["keyframes"]),
            "isam2_s": float(gi.runtime_s),
            "isam2_realtime_factor": float(drive.duration_s) / float(gi.runtime_s),
            "isam2_online_s": float(gi.info["online_s"]),
            "isam2_update_p99_ms": float(gi.info["update_p99_ms"]),
            "batch_s": float(gb.runtime_s), "warnings": len(gi.info.get("warnings") or [])}
        for name, tr in (("online", gi.online), ("final", gi.trajectory),
                         ("batch", gb.trajectory)):
            h, v = rmse(lla_to_ned(tr.at(epochs).lla, origin), truth)
            row[f"{name}_horiz_m"], row[f"{name}_alt_m"] = h, v
        runs.append(row)
    out = {"schema": "vnav_graph.isam2_keyframe_spacing/1", "hours": a.hours, "seed": a.seed,
           "epochs": int(epochs.size), "runs": runs}
    if a.logs:
        del est, drive
        out["logs"] = real_logs(a.logs, a.data, spacings)
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / "isam2_keyframe_spacing.json").write_text(json.dumps(out, indent=2) + "\n")
    for r in runs:
        print(json.dumps({k: round(v, 3) if isinstance(v, float) else v for k, v in r.items()}))
    return out


if __name__ == "__main__":
    main()
