"""Measure every estimator's runtime and fit the cost model of ``vnav_graph.run.runtime_estimate``.

    python benchmarks/runtime_model.py --out DIR [--quick] [--data DIR]

Runs every built-in estimator (``runner.run_estimators``, so ``runtime_s`` excludes numba's
compile time) on simulated drives — default, cold-start-phone, sortie, hill-drive 120 / 480 s,
hill-drive-mag 120 / 240 / 480 s (``--quick``: default and hill-drive-mag 120 s) — and on the
shared real logs present (218.BIN, Loiter_RTL.bin, the ski log, car 07-18; ``$VNAV_DATA`` or
``../shared/data``). Fits, per estimator, seconds = a·(IMU samples / 10⁴) + b·(keyframes /
100) + c·(keyframes × heading factors / 10⁵) by non-negative least squares weighted by
1 / max(runtime, 0.5 s) (c only for graph-isam2), and writes ``DIR/runtime_model.json``:
``{"runs": [{"drive", "features", "runtime_s", "predicted_s" (the package's COST table),
"fitted_s"}], "fitted": {ESTIMATOR: [a, b, c]}, "cost": COST, "ratio_range": {ESTIMATOR:
[min, max] of predicted / measured}}``. Copy ``fitted`` into ``COST`` when it moves.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_real_logs import data_root, present_logs  # noqa: E402

SIMULATED = [("default", None), ("cold-start-phone", None), ("sortie", None),
             ("hill-drive", 120.0), ("hill-drive", 480.0), ("hill-drive-mag", 120.0),
             ("hill-drive-mag", 240.0), ("hill-drive-mag", 480.0)]
QUICK = [("default", None), ("hill-drive-mag", 120.0)]
LOGS = ("erle_pxf_218/218.BIN", "erle_pxf_loiter_rtl/Loiter_RTL.bin", "ski_iphone_100hz",
        "car_phone_1hz_2025-07-18/2025-07-18_23-13-43.csv")


def drives(quick: bool, root: Path):
    from vnav_graph.io import load_drive
    from vnav_graph.simulation import simulate

    for sc, dur in QUICK if quick else SIMULATED:
        yield f"{sc}" + ("" if dur is None else f"-{dur:.0f}"), (
            lambda sc=sc, dur=dur: simulate(sc, 0, **({} if dur is None else
                                                       {"duration_s": dur})))
    if not quick:
        for rel, p in present_logs(root, missing=[], logs=LOGS):
            yield Path(rel).name, lambda p=p: load_drive(p)


def fit(runs: list[dict], names: list[str]) -> dict[str, list[float]]:
    from scipy.optimize import nnls

    out = {}
    for n in names:
        rows = [r for r in runs if r["runtime_s"].get(n) is not None]
        a = np.array([r["features"] for r in rows], float)
        if n != "graph-isam2":
            a[:, 2] = 0.0
        y = np.array([r["runtime_s"][n] for r in rows])
        w = 1.0 / np.maximum(y, 0.5)
        out[n] = nnls(a * w[:, None], y * w)[0].tolist() if rows else [0.0, 0.0, 0.0]
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--data", default=None)
    args = ap.parse_args(argv)
    from vnav_graph.estimators.base import available
    from vnav_graph.run.runner import run_estimators
    from vnav_graph.run.runtime_estimate import COST, features, predict

    names = [n for n in available() if n in COST]
    runs = []
    for label, make in drives(args.quick, data_root(args.data)):
        d = make()
        res = run_estimators(d, names, progress=False)
        runs.append({"drive": label, "features": list(features(d)),
                     "runtime_s": {r.name: (r.runtime_s if r.estimate is not None else None)
                                   for r in res},
                     "predicted_s": predict(d, names)})
        print(f"{label}: " + ", ".join(f"{k} {v:.1f} s" for k, v in runs[-1]["runtime_s"].items()
                                       if v is not None), file=sys.stderr, flush=True)
    fitted = fit(runs, names)
    ratio = {}
    for r in runs:
        r["fitted_s"] = {n: float(np.dot(fitted[n], r["features"])) for n in names}
        for n in names:
            m = r["runtime_s"].get(n)
            if m:
                ratio.setdefault(n, []).append(r["predicted_s"][n] / m)
    doc = {"runs": runs, "fitted": fitted, "cost": {k: list(v) for k, v in COST.items()},
           "ratio_range": {n: [min(v), max(v)] for n, v in ratio.items()}}
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "runtime_model.json").write_text(json.dumps(doc, indent=1))
    print(f"wrote {out / 'runtime_model.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
