"""Does the forward/backward separation of ekf-rts track its actual error?

Usage::

    python benchmarks/fb_separation.py --seeds 10 --out bench-results/fb

For each scenario and seed, ekf-rts (default settings) reports ``fb_separation``
{alt_p95_m, horiz_p95_m}, the 95th percentiles of the distance between its forward filter and
the filter run backward (``vnav_graph.estimators.ekf.backward``); the simulation truth gives
the 95th percentiles of the smoothed trajectory's own error. Writes ``fb_separation.json``:
per scenario the rows (seed, separation, error) and the correlation over seeds (Pearson and
Spearman) of separation with error, altitude and horizontal, and the same pooled over every
run (where scenarios of different difficulty also enter) — with the ratio error/separation,
which says whether the separation can stand in for the error's size, not only its ranking.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np
from scipy.stats import pearsonr, spearmanr

SCENARIOS = ("default", "cold-start-phone", "urban")


def one_run(scenario: str, seed: int, duration_s: float | None) -> dict[str, Any]:
    from vnav_graph.estimators.ekf.filter import EKFRTS
    from vnav_graph.evaluation.metrics import errors_vs_truth
    from vnav_graph.simulation.scenario import simulate

    over = {} if duration_s is None else {"duration_s": duration_s}
    d = simulate(scenario, seed, **over)
    est = EKFRTS().run(d)
    sep = est.info.get("fb_separation")
    err = errors_vs_truth(est, d)
    return {"seed": seed,
            "sep_alt_p95_m": None if sep is None else sep["alt_p95_m"],
            "sep_horiz_p95_m": None if sep is None else sep["horiz_p95_m"],
            "err_alt_p95_m": float(np.percentile(np.abs(err.alt), 95)),
            "err_horiz_p95_m": (None if err.horiz is None else
                                float(np.percentile(np.abs(err.horiz), 95)))}


def correlation(rows: list[dict[str, Any]], axis: str) -> dict[str, Any]:
    pairs = [(r[f"sep_{axis}_p95_m"], r[f"err_{axis}_p95_m"]) for r in rows
             if r[f"sep_{axis}_p95_m"] is not None and r[f"err_{axis}_p95_m"] is not None]
    if len(pairs) < 3:
        return {"n": len(pairs), "pearson": None, "spearman": None, "err_over_sep_median": None}
    s, e = np.array(pairs).T
    same = np.ptp(s) == 0 or np.ptp(e) == 0
    return {"n": len(pairs),
            "pearson": None if same else float(pearsonr(s, e)[0]),
            "spearman": None if same else float(spearmanr(s, e)[0]),
            "err_over_sep_median": float(np.median(e / np.maximum(s, 1e-12)))}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--scenarios", default=",".join(SCENARIOS))
    ap.add_argument("--duration", type=float, default=None, help="drive length [s]")
    ap.add_argument("--out", required=True)
    a = ap.parse_args(argv)
    if a.seeds < 3:
        print("fb_separation.py: --seeds must be at least 3 (a correlation)", file=sys.stderr)
        return 2
    doc: dict[str, Any] = {"schema": "vnav_graph.fb_separation/1", "seeds": a.seeds,
                           "duration_s": a.duration, "scenarios": {}}
    every: list[dict[str, Any]] = []
    for sc in a.scenarios.split(","):
        rows = [one_run(sc, seed, a.duration) for seed in range(a.seeds)]
        every += rows
        doc["scenarios"][sc] = {"runs": rows, "alt": correlation(rows, "alt"),
                                "horiz": correlation(rows, "horiz")}
        print(sc, json.dumps({k: doc["scenarios"][sc][k] for k in ("alt", "horiz")}),
              flush=True)
    doc["pooled"] = {"alt": correlation(every, "alt"), "horiz": correlation(every, "horiz")}
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "fb_separation.json").write_text(json.dumps(doc, indent=1))
    print("pooled", json.dumps(doc["pooled"]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
