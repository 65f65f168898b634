"""EKF vs factor graph on one simulated drive: filtering, smoothing and relinearisation.

The same drive goes through the error-state EKF (``ekf``), the EKF followed by a
Rauch-Tung-Striebel smoother (``ekf-rts``) and the GTSAM batch smoother (``graph-batch``).
The differences isolate two effects (the same decomposition ``docs/results.md`` reports over
many seeds):

- ekf → ekf-rts: the **smoothing gain** (future measurements, same linearisation);
- ekf-rts → graph-batch: the **relinearisation / modelling gain** (the graph relinearises the
  whole trajectory at every iteration and models the baro factor exactly).

Run: ``python examples/ex_compare_ekf_graph.py`` (prints the table, writes a report to
``ex_compare_out/``).
"""

from __future__ import annotations

from typing import Any

from vnav_graph.estimators.base import available
from vnav_graph.evaluation.montecarlo import shorten_scenario
from vnav_graph.run.pipeline import run_estimators, summarize
from vnav_graph.simulation import simulate

REQUIRES = ("ekf", "graph-batch")
NAMES = ("ekf", "ekf-rts", "graph-batch")


def main(duration_s: float = 240.0, seed: int = 0, scenario: str = "hill-drive"
         ) -> dict[str, Any]:
    """Returns ``{"summary": summary.json document, "results": [RunResult], "drive": Drive,
    "gains": {"smoothing_m": ekf − ekf-rts alt RMSE, "graph_m": ekf-rts − graph-batch}}``."""
    drive = simulate(shorten_scenario(scenario, duration_s), seed)
    names = [n for n in NAMES if n in available()]
    results = run_estimators(drive, names, progress=False)
    summary = summarize(drive, results)
    rmse = {n: m["alt_rmse_m"] for n, m in summary["estimators"].items()}

    def diff(a: str, b: str) -> float | None:
        return None if rmse.get(a) is None or rmse.get(b) is None else rmse[a] - rmse[b]

    return {"summary": summary, "results": results, "drive": drive,
            "gains": {"smoothing_m": diff("ekf", "ekf-rts"),
                      "graph_m": diff("ekf-rts", "graph-batch")}}


if __name__ == "__main__":
    from pathlib import Path

    from vnav_graph.report import write_report
    from vnav_graph.run.pipeline import format_table, write_outputs

    res = main(duration_s=600.0)
    print(format_table(res["summary"]))
    print("altitude RMSE gains [m]:", res["gains"])
    write_outputs(Path("ex_compare_out"), res["summary"], res["results"], res["drive"],
                  [write_report])
    print("report: ex_compare_out/report.html")
