"""What ``gnss_gm_auto`` decides on the shared real logs, and what it does to their holdout.

    python benchmarks/gnss_gm_auto_logs.py [--data DIR] [--out DIR]

For every shared log present: the holdout (``runner.run_holdout``: 60 s windows, default
spacing, screened withheld GNSS) of ``ekf-rts`` and ``graph-batch`` with their defaults
(the Gauss-Markov GNSS error state off) and with ``gnss_gm_auto = true`` at the σ and τ of
``benchmarks/hard_scenarios.toml`` (2.5 m north/east, 4 m down, τ 30 s; nothing else
changed). Per log and estimator: the first pass's residual autocorrelations at 5 s and the
decision (``info["gnss_gm_auto"]``), altitude and horizontal RMSE against the withheld fixes,
and the altitude's mean (error/σ)² over them (σ² = the estimate's own height variance plus
the fix's, the holdout's ``alt_sd``: 1 when σ covers the error). Writes
``DIR/gnss_gm_auto_logs.json`` and prints the table of ``docs/real_logs.md``.

The withheld reference is GNSS and carries its own correlated error, which biases the score
against the state (``benchmarks/gnss_gm_study.py``): a gain on it is a real gain, a loss is
not proof of harm.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_real_logs import data_root, present_logs, write_logs_json  # noqa: E402
from real_logs_table import NAMES  # noqa: E402

ESTIMATORS = ("ekf-rts", "graph-batch")
GM = {"gnss_gm_sd_h": 2.5, "gnss_gm_sd_v": 4.0, "gnss_gm_tau_s": 30.0, "gnss_gm_auto": True}


def configs() -> dict[str, Any]:
    from vnav_graph.estimators.ekf.filter import EkfConfig
    from vnav_graph.estimators.graph import GraphConfig

    return {"ekf-rts": EkfConfig(**GM), "graph-batch": GraphConfig(**GM)}


def scores(res: Any) -> dict[str, Any]:
    """Per estimator: the holdout block's scores, the decision and the altitude (err/σ)²."""
    out = {}
    for e, b in res.doc["estimators"].items():
        s = res.series.get(e)
        z2 = None
        if s is not None and s.alt_sd is not None:
            w = s.withheld & np.isfinite(s.alt_err) & np.isfinite(s.alt_sd)
            z2 = float(np.mean((s.alt_err[w] / s.alt_sd[w]) ** 2)) if w.any() else None
        out[e] = {k: b.get(k) for k in ("status", "error", "alt_rmse_m", "horiz_rmse_m",
                                        "gnss_rejected", "gnss_gm_auto")} | {"alt_z2": z2}
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=None)
    ap.add_argument("--out", default="gnss-gm-auto-logs")
    args = ap.parse_args(argv)
    from vnav_graph.io import load_drive
    from vnav_graph.run.runner import run_holdout

    root = data_root(args.data)
    doc: dict[str, Any] = {"config": GM, "logs": {}}
    for rel, p in present_logs(root):
        drive = load_drive(p)
        doc["logs"][rel.split("/")[0]] = {
            "off": scores(run_holdout(drive, ESTIMATORS)),
            "auto": scores(run_holdout(drive, ESTIMATORS, configs=configs()))}
        print(f"{rel}: done", file=sys.stderr, flush=True)
    if not write_logs_json(doc, bool(doc["logs"]), args.out, "gnss_gm_auto_logs.json"):
        return 2
    print(render(doc))
    return 0


def _f(x: Any, spec: str = ".2f") -> str:
    return "—" if x is None else format(x, spec)


def render(doc: dict[str, Any]) -> str:
    out = ["| log | estimator | autocorr 5 s N,E / D | threshold | state | alt RMSE m off → auto "
           "| horiz RMSE m off → auto | alt (err/σ)² off → auto |",
           "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for log, row in doc["logs"].items():
        for e in ESTIMATORS:
            a, b = row["off"][e], row["auto"][e]
            d = b.get("gnss_gm_auto") or {}
            out.append(
                f"| {NAMES.get(log, log)} | {e} | {_f(d.get('autocorr_h'))} / "
                f"{_f(d.get('autocorr_v'))} | {_f(d.get('threshold'))} | "
                f"{'on' if d.get('on') else 'off'} | {_f(a['alt_rmse_m'])} → "
                f"{_f(b['alt_rmse_m'])} | {_f(a['horiz_rmse_m'], '.1f')} → "
                f"{_f(b['horiz_rmse_m'], '.1f')} | {_f(a['alt_z2'])} → {_f(b['alt_z2'])} |")
    return "\n".join(out)


if __name__ == "__main__":
    sys.exit(main())
