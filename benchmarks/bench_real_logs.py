"""Runtime of the GNSS-outage holdout on the shared real logs (moved out of the tests).

    python benchmarks/bench_real_logs.py --out DIR [--estimators a,b] [--data DIR]

For every shared log present (``$VNAV_DATA`` or ``../shared/data``), runs
``vnav_graph.run.runner.run_holdout`` with the given estimators (default
``ekf-rts,graph-isam2,graph-batch``) and writes ``DIR/real_log_perf.json``:
``{"logs": {LOG: {ESTIMATOR: {"status", "runtime_s", "alt_rmse_m"}}},
"missing": [...]}``. Each estimator first runs once, untimed, on the first log, so numba's
compilation does not land on the first log. Absent logs are listed in ``missing``, not
errors. Reference points: the 93-min 1 Hz car log took 213 s in graph-isam2 before its
low-rate settings and ~7 s after.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any

LOGS = ("erle_pxf_218/218.BIN", "erle_pxf_loiter_rtl/Loiter_RTL.bin",
        "erle_pxf_181_gps_glitch/181.BIN", "ski_iphone_100hz",
        "car_phone_1hz_2025-07-18/2025-07-18_23-13-43.csv",
        "car_phone_1hz_2025-03-01a/2025-03-01_15-04-26.csv")


def data_root(arg: str | None) -> Path:
    if arg:
        return Path(arg)
    env = os.environ.get("VNAV_DATA")
    return Path(env) if env else Path(__file__).resolve().parents[1].parent / "shared" / "data"


def select_logs(names: str | None, logs: Sequence[str] = LOGS) -> list[str]:
    """The logs of ``logs`` whose names contain one of the comma-separated parts ``names``
    (all of them when ``names`` is empty or None)."""
    wanted = [w for w in (names or "").split(",") if w]
    return [rel for rel in logs if not wanted or any(w in rel for w in wanted)]


def present_logs(root: Path, missing: list[str] | None = None,
                 logs: Sequence[str] = LOGS) -> Iterator[tuple[str, Path]]:
    """(relative name, path) of each of ``logs`` present under ``root``. An absent one is
    appended to ``missing`` when given, else reported on stderr as ``missing: <name>``."""
    for rel in logs:
        p = root / rel
        if p.exists():
            yield rel, p
        elif missing is not None:
            missing.append(rel)
        else:
            print(f"missing: {rel}", file=sys.stderr)


def write_logs_json(doc: Any, has_logs: bool, out: str | Path, name: str) -> bool:
    """Write ``doc`` as ``out/name`` (indented JSON) when a shared log was present
    (``has_logs``); else say so on stderr, write nothing and return False."""
    if not has_logs:
        print("no shared logs found", file=sys.stderr)
        return False
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    (out / name).write_text(json.dumps(doc, indent=1, default=str) + "\n")
    return True


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("--estimators", default="ekf-rts,graph-isam2,graph-batch")
    ap.add_argument("--data", default=None)
    a = ap.parse_args(argv)
    from vnav_graph.io import load_drive
    from vnav_graph.run.runner import run_holdout

    names = [n for n in a.estimators.split(",") if n]
    root = data_root(a.data)
    doc: dict = {"estimators": names, "logs": {}, "missing": []}
    for rel, p in present_logs(root, doc["missing"]):
        drive = load_drive(p)
        if not doc["logs"]:
            run_holdout(drive, names)  # untimed, first log only: kernels compiled / loaded
        res = run_holdout(drive, names)
        doc["logs"][rel] = {n: {k: b.get(k) for k in ("status", "runtime_s", "alt_rmse_m")}
                            for n, b in res.doc["estimators"].items()}
        print(rel, {n: round(b["runtime_s"], 2) for n, b in res.doc["estimators"].items()},
              flush=True)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "real_log_perf.json").write_text(json.dumps(doc, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
