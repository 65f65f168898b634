"""Does the Gauss-Markov GNSS height state help on the shared real logs?

    python benchmarks/gnss_gm_study.py [--data DIR] [--out DIR] [--sd M] [--tau S ...]

For every shared log present: the holdout (``runner.run_holdout``: 60 s windows,
default spacing, screened withheld GNSS) of ``ekf-rts`` and ``graph-batch`` without the state
and with it (σ ``--sd``, each τ of ``--tau``), the same windows and references for all.
Writes ``DIR/gnss_gm_study.json`` and prints the altitude-RMSE table (graph-batch's solver
warnings noted).

What the score can and cannot show: the withheld reference is GNSS, whose correlated error
g(t) is in it. Without the state an estimator follows GNSS (g included) up to a window and
bridges it; with the state it estimates the height without g, and the score then also
counts g's change since the window's edges. The holdout is therefore biased against the
state by about the change of g over a window (σ·√(2(1 − e^{−Δt/τ})) for a lag Δt): a win for
the state on it is a real win, a small loss is not proof of harm.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_real_logs import data_root, present_logs, write_logs_json  # noqa: E402

ESTIMATORS = ("ekf-rts", "graph-batch")


def configs(sd: float, tau: float) -> dict[str, Any]:
    from vnav_graph.estimators.ekf.filter import EkfConfig
    from vnav_graph.estimators.graph import GraphConfig

    return {"ekf-rts": EkfConfig(gnss_gm_sd_v=sd, gnss_gm_tau_s=tau),
            "graph-batch": GraphConfig(gnss_gm_sd_v=sd, gnss_gm_tau_s=tau)}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=None)
    ap.add_argument("--out", default="gnss-gm-study")
    ap.add_argument("--sd", type=float, default=3.0, help="GM σ [m]")
    ap.add_argument("--tau", type=float, nargs="+", default=[120.0, 600.0], help="GM τ [s]")
    args = ap.parse_args(argv)
    from vnav_graph.io import load_drive
    from vnav_graph.run.runner import run_holdout

    root = data_root(args.data)
    variants = [("off", None)] + [(f"σ {args.sd:g} m τ {t:g} s", (args.sd, t))
                                  for t in args.tau]
    doc: dict[str, Any] = {"sd_m": args.sd, "tau_s": args.tau, "logs": {}}
    for rel, p in present_logs(root):
        drive = load_drive(p)
        row: dict[str, Any] = {}
        for name, v in variants:
            t0 = time.perf_counter()
            cfg = None if v is None else configs(*v)
            res = run_holdout(drive, ESTIMATORS, configs=cfg).doc
            row[name] = {e: {k: b.get(k) for k in ("status", "alt_rmse_m", "horiz_rmse_m",
                                                    "error")}
                         | {"warnings": b.get("warnings"), "baro": b.get("baro")}
                         for e, b in res["estimators"].items()}
            row[name]["_gnss_sd_v_median_m"] = res.get("gnss_sd_v_median_m")
            print(f"{rel} {name}: {time.perf_counter() - t0:.0f} s", file=sys.stderr,
                  flush=True)
        doc["logs"][rel.split("/")[0]] = row
    if not write_logs_json(doc, bool(doc["logs"]), args.out, "gnss_gm_study.json"):
        return 2
    print(render(doc, [n for n, _ in variants]))
    return 0


def _cell(b: dict[str, Any]) -> str:
    if b.get("status") != "ok":
        return str(b.get("status"))
    w = " ⚠" if b.get("warnings") else ""
    return f"{b['alt_rmse_m']:.2f}{w}"


def render(doc: dict[str, Any], variants: list[str]) -> str:
    head = "| log | " + " | ".join(f"{e} {v}" for v in variants for e in ESTIMATORS) + " |"
    out = [head, "| --- " * (1 + len(variants) * len(ESTIMATORS)) + "|"]
    for log, row in doc["logs"].items():
        out.append(f"| {log} | " + " | ".join(_cell(row[v][e]) for v in variants
                                               for e in ESTIMATORS) + " |")
    return "\n".join(out)


if __name__ == "__main__":
    sys.exit(main())
