"""First contact: how long a new user waits (issue: "a first run under a minute").

    python benchmarks/bench_first_run.py --out DIR [--runs N]

Writes ``DIR/first_run.json``:

- ``help_s``, ``list_s``: wall time of ``vnav-graph --help`` and ``vnav-graph list`` (median of
  ``--runs``);
- ``cold_run_s``: wall time of ``vnav-graph run`` (default drive, all estimators) with an
  empty numba cache (a fresh ``VNAV_CACHE_DIR``): what the first run after installing costs,
  compilation included; ``cold_jit_s``: the compile time that run reports (``jit_s`` summed
  over ``summary.json``);
- ``warm_run_s``, ``warm_jit_s``: the same command again with the now-filled cache;
- ``cold_runtime_ok``: every estimator's ``runtime_s`` of the cold run is within 2× + 0.5 s of
  the warm run's (compile time is not charged to the estimator that met it first);
- ``goal_cold_run_s`` (60), ``goal_help_s`` (1), ``goal_list_s`` (2) for comparison.

Cold and warm runs are taken side by side in one invocation; on a shared machine compare
them with each other rather than with another day's numbers. ``nproc`` and the load average
at the start are recorded.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def _cli() -> list[str]:
    exe = Path(sys.executable).with_name("vnav-graph")
    return [str(exe)] if exe.exists() else [sys.executable, "-m", "vnav_graph"]


def _timed(args: list[str], env: dict[str, str]) -> float:
    t0 = time.perf_counter()
    subprocess.run(_cli() + args, env=env, check=True, stdout=subprocess.DEVNULL,
                   stderr=subprocess.DEVNULL)
    return time.perf_counter() - t0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("--runs", type=int, default=3, help="repeats of --help and list")
    a = ap.parse_args(argv)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix="vnav-first-run-"))
    env = {**os.environ, "VNAV_CACHE_DIR": str(work / "cache"), "MPLBACKEND": "Agg"}
    env.pop("NUMBA_CACHE_DIR", None)
    try:
        load = os.getloadavg()[0]
        help_s = statistics.median(_timed(["--help"], env) for _ in range(a.runs))
        list_s = statistics.median(_timed(["list"], env) for _ in range(a.runs))
        runs = {}
        for kind in ("cold", "warm"):
            d = work / kind
            wall = _timed(["run", "--out", str(d), "--no-progress"], env)
            s = json.loads((d / "summary.json").read_text())["estimators"]
            runs[kind] = (wall, s)
        (cold_s, cold), (warm_s, warm) = runs["cold"], runs["warm"]
        ok = all(cold[n]["runtime_s"] <= 2 * warm[n]["runtime_s"] + 0.5 for n in warm)
        doc = {
            "nproc": os.cpu_count(), "loadavg_1min_at_start": load,
            "help_s": help_s, "list_s": list_s,
            "cold_run_s": cold_s, "cold_jit_s": sum(m.get("jit_s") or 0 for m in cold.values()),
            "warm_run_s": warm_s, "warm_jit_s": sum(m.get("jit_s") or 0 for m in warm.values()),
            "cold_runtime_ok": ok,
            "runtime_s": {n: [cold[n]["runtime_s"], warm[n]["runtime_s"]] for n in warm},
            "goal_cold_run_s": 60.0, "goal_help_s": 1.0, "goal_list_s": 2.0,
        }
    finally:
        shutil.rmtree(work, ignore_errors=True)
    (out / "first_run.json").write_text(json.dumps(doc, indent=2) + "\n")
    print(json.dumps({k: v for k, v in doc.items() if k != "runtime_s"}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
