"""What graph-isam2's relinearisation costs and what it buys, on the shared real logs.

    python benchmarks/isam2_relin_cost.py --out DIR [--data DIR] [--logs 218,ski] [--repeat 2]

For each shared log present (the full-rate ones: the averaged 1 Hz car logs run with their own
low-rate settings, which any other setting turns off), the GNSS-outage holdout
(``vnav_graph.run.runner.run_holdout``, as ``holdout`` runs it) is run ``--repeat`` times with
graph-batch and graph-isam2 under three relinearisation settings, in one process, the
variants alternated so that the machine's load falls on all of them alike:

- ``default``: ``GraphConfig``'s thresholds;
- ``coarse``: the rotation threshold ten times larger (``relinearize_typed[0]``), for iSAM2's
  own factors, the interval terms and the extensions' factors (the compass's);
- ``off``: ``relinearize_threshold = 0``: nothing is relinearised, neither by iSAM2 nor by the
  term books, and the final rounds cannot make iSAM2's estimate the optimum.

Writes ``DIR/isam2_relin_cost.json``::

    {"schema": "vnav_graph.isam2_relin_cost/1", "repeat": n,
     "logs": {LOG: {"graph_batch_runtime_s": [...],
                    VARIANT: {"runtime_s": [...], "over_batch": [...],
                              "relinearized", "reeliminated", "terms_rebuilt", "update_ms",
                              "alt_rmse_m", "horiz_rmse_m", "online_alt_rmse_m",
                              "online_horiz_rmse_m", "warnings"}}}}

``over_batch``: graph-isam2's ``runtime_s`` over graph-batch's in the same holdout run. The
per-update means (``relinearized``, ``reeliminated``: variables; ``terms_rebuilt``: interval
terms swapped; ``update_ms``: ``ISAM2.update`` alone) come from ``info["update_breakdown"]``
of the last repeat; the scores do not depend on the repeat.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_real_logs import LOGS as ALL_LOGS  # noqa: E402
from bench_real_logs import data_root, present_logs, select_logs, write_logs_json  # noqa: E402

# the full-rate logs: the averaged 1 Hz car logs run with their own low-rate settings
LOGS = tuple(rel for rel in ALL_LOGS if not rel.startswith("car_phone_1hz"))
VARIANTS = ("default", "coarse", "off")
COARSE = 10.0  # the rotation threshold's factor in the "coarse" variant


def variant_config(name: str) -> Any:
    from vnav_graph.estimators.graph import GraphConfig

    cfg = GraphConfig()
    if name == "coarse":
        typed = cfg.relinearize_typed
        return dataclasses.replace(cfg, relinearize_typed=(COARSE * typed[0], *typed[1:]))
    if name == "off":
        return dataclasses.replace(cfg, relinearize_threshold=0.0)
    return cfg


def _score(block: dict[str, Any], key: str) -> float | None:
    v = block.get(key)
    return None if v is None else round(float(v), 3)


def run_variant(drive: Any, name: str) -> tuple[float, dict[str, Any]]:
    """One holdout run of graph-batch and graph-isam2 (``name``'s settings): graph-batch's
    runtime and graph-isam2's row."""
    from vnav_graph.run import runner

    kept: dict[str, Any] = {}
    plain = runner.run_estimators

    def keeping(*args: Any, **kwargs: Any) -> Any:  # graph-isam2's Estimate, for its info
        for r in plain(*args, **kwargs):
            kept[r.name] = r.estimate
            yield r

    runner.run_estimators = keeping
    try:
        res = runner.run_holdout(drive, ["graph-isam2", "graph-batch"],
                                 configs={"graph-isam2": variant_config(name)})
    finally:
        runner.run_estimators = plain
    est = res.doc["estimators"]
    g, b = est["graph-isam2"], est["graph-batch"]
    row: dict[str, Any] = {"status": g.get("status"), "runtime_s": float(g["runtime_s"])}
    if g.get("status") == "ok":
        online = g.get("online") or {}
        row |= {"alt_rmse_m": _score(g, "alt_rmse_m"), "horiz_rmse_m": _score(g, "horiz_rmse_m"),
                "online_alt_rmse_m": _score(online, "alt_rmse_m"),
                "online_horiz_rmse_m": _score(online, "horiz_rmse_m"),
                "warnings": len(g.get("warnings") or [])}
        brk = np.asarray((kept["graph-isam2"].info or {}).get("update_breakdown"))
        if brk.ndim == 2 and brk.shape[0]:
            m = brk.mean(axis=0)
            row |= {"update_ms": round(float(m[2]), 2), "relinearized": round(float(m[4]), 1),
                    "reeliminated": round(float(m[5]), 1),
                    "terms_rebuilt": round(float(m[6]), 1)}
    return float(b["runtime_s"]), row


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("--data", default=None)
    ap.add_argument("--logs", default=None,
                    help="comma-separated parts of log names to run (default: all four)")
    ap.add_argument("--repeat", type=int, default=2)
    a = ap.parse_args(argv)
    if a.repeat < 1:
        ap.exit(2, "isam2_relin_cost: --repeat must be at least 1\n")
    from vnav_graph.io import load_drive

    logs = select_logs(a.logs, LOGS)
    doc: dict[str, Any] = {"schema": "vnav_graph.isam2_relin_cost/1", "repeat": a.repeat,
                           "coarse_factor": COARSE, "logs": {}, "missing": []}
    warmed = False
    for rel, path in present_logs(data_root(a.data), doc["missing"], logs):
        drive = load_drive(path)
        if not warmed:  # numba's kernels compiled / loaded outside the timed runs
            run_variant(drive, "off")
            warmed = True
        entry: dict[str, Any] = {"graph_batch_runtime_s": []}
        for _ in range(a.repeat):
            for name in VARIANTS:
                t_b, row = run_variant(drive, name)
                entry["graph_batch_runtime_s"].append(round(t_b, 3))
                v = entry.setdefault(name, {"runtime_s": [], "over_batch": []})
                v["runtime_s"].append(round(row.pop("runtime_s"), 3))
                v["over_batch"].append(round(v["runtime_s"][-1] / t_b, 2))
                v |= row
        doc["logs"][rel] = entry
        print(rel, {n: (entry[n]["over_batch"], entry[n].get("online_horiz_rmse_m"),
                        entry[n].get("horiz_rmse_m")) for n in VARIANTS}, flush=True)
    return 0 if write_logs_json(doc, bool(doc["logs"]), a.out, "isam2_relin_cost.json") else 1


if __name__ == "__main__":
    sys.exit(main())
