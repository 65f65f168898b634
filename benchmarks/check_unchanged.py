"""Fingerprint every output of the CLI, and compare two fingerprints.

A refactoring that should not change any result is checked by fingerprinting the outputs
before and after it:

    python benchmarks/check_unchanged.py --out before.json [--log LOG]
    ... change the code ...
    python benchmarks/check_unchanged.py --out after.json [--log LOG]
    python benchmarks/check_unchanged.py --compare before.json after.json

The fingerprint runs, through ``python -m vnav_graph`` of the working tree, with BLAS on one
thread (so that the arithmetic does not depend on thread scheduling):

- ``run`` on the simulated default drive and on ``--scenario hill-drive`` (every estimator);
- with ``--log``: ``run LOG`` (which includes the holdout scoring of a real log),
  ``holdout LOG`` and ``calibrate-baro LOG``; without it, or when the file is absent, these
  are skipped with a message;
- ``bench --quick --scenarios hill-drive --seeds 1 --workers 1`` (``--no-bench`` leaves it out).

It records every number of ``summary.json``, ``holdout.json`` and ``bench.json`` (as its exact
``float.hex``), every column of the ``estimates/*.parquet`` tables (SHA-256 of the bytes, and
for float columns their length, NaN count, sum, sum of absolute values and up to 201 evenly
spaced samples) and the text ``calibrate-baro`` prints. Timings (``runtime_s``,
``realtime_factor``, ``jit_s``, ``wall_s``) vary from run to run and are left out.

``--compare`` prints each difference and a count per kind: ``bitwise`` (identical),
``within 1e-9`` (every compared number within 1e-9 relative) or ``differs``; exit code 1 when
anything differs or is missing on one side.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import os
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parent.parent
VOLATILE = {"runtime_s", "realtime_factor", "jit_s", "wall_s", "isam2_update_p99_ms"}
REL_TOL = 1e-9
ABS_FLOOR = 1e-300
N_SAMPLES = 201


def _cli(args: list[str], cwd: Path) -> subprocess.CompletedProcess[str]:
    env = dict(os.environ)
    for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
        env[var] = "1"
    env["PYTHONPATH"] = str(REPO) + os.pathsep + env.get("PYTHONPATH", "")
    cmd = [sys.executable, "-m", "vnav_graph", *args]
    print("check_unchanged: " + " ".join(args), file=sys.stderr, flush=True)
    return subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, check=False)


def _num(v: float) -> str:
    return float(v).hex()


def flatten_json(doc: Any, prefix: str = "") -> dict[str, Any]:
    """``{"a.b.0.c": value}`` of a JSON document; floats as ``float.hex``, timings left out."""
    out: dict[str, Any] = {}
    if isinstance(doc, dict):
        for k, v in doc.items():
            if k in VOLATILE:
                continue
            out.update(flatten_json(v, f"{prefix}.{k}" if prefix else str(k)))
    elif isinstance(doc, list):
        for i, v in enumerate(doc):
            out.update(flatten_json(v, f"{prefix}.{i}"))
    elif isinstance(doc, float):
        out[prefix] = {"f": _num(doc)}
    else:
        out[prefix] = doc
    return out


def column_print(values: np.ndarray) -> dict[str, Any]:
    """SHA-256 of a column's bytes; for floats also length, NaN count, sums and samples."""
    a = np.ascontiguousarray(values)
    fp: dict[str, Any] = {"dtype": str(a.dtype), "n": int(a.size)}
    if a.dtype.kind in "fiub":
        fp["sha256"] = hashlib.sha256(a.tobytes()).hexdigest()
    else:
        fp["sha256"] = hashlib.sha256("\n".join(map(str, a)).encode()).hexdigest()
        return fp
    x = a.astype(float)
    fin = np.isfinite(x)
    fp["nan"] = int((~fin).sum())
    fp["sum"] = _num(float(np.sum(x[fin])))
    fp["abs_sum"] = _num(float(np.sum(np.abs(x[fin]))))
    idx = np.unique(np.linspace(0, max(a.size - 1, 0), min(N_SAMPLES, a.size)).astype(int))
    fp["samples"] = [_num(v) for v in x[idx]] if a.size else []
    return fp


def parquet_prints(folder: Path) -> dict[str, Any]:
    import pandas as pd

    out: dict[str, Any] = {}
    for p in sorted(folder.glob("*.parquet")):
        df = pd.read_parquet(p)
        out[p.stem] = {c: column_print(df[c].to_numpy()) for c in df.columns}
    return out


def run_case(name: str, args: list[str], work: Path, prints: dict[str, Any]) -> None:
    out = work / name
    res = _cli([*args, "--out", str(out), "--no-progress"], REPO)
    case: dict[str, Any] = {"exit_code": res.returncode}
    if (out / "summary.json").exists():
        case["summary"] = flatten_json(json.loads((out / "summary.json").read_text()))
        case["estimates"] = parquet_prints(out / "estimates")
    if (out / "holdout.json").exists():
        case["holdout"] = flatten_json(json.loads((out / "holdout.json").read_text()))
    if (out / "bench.json").exists():
        case["bench"] = flatten_json(json.loads((out / "bench.json").read_text()))
    if res.returncode not in (0, 3):
        case["stderr"] = res.stderr.strip().splitlines()[-1:] if res.stderr.strip() else []
    prints[name] = case


def fingerprint(log: Path | None, bench: bool, work: Path) -> dict[str, Any]:
    prints: dict[str, Any] = {}
    run_case("run-default", ["run"], work, prints)
    run_case("run-hill-drive", ["run", "--scenario", "hill-drive"], work, prints)
    if log is None:
        print("check_unchanged: no --log given: real-log cases skipped", file=sys.stderr)
    elif not log.exists():
        print(f"check_unchanged: {log} not found: real-log cases skipped", file=sys.stderr)
    else:
        run_case("run-log", ["run", str(log)], work, prints)
        run_case("holdout-log", ["holdout", str(log)], work, prints)
        res = _cli(["calibrate-baro", str(log)], REPO)
        prints["calibrate-baro-log"] = {"exit_code": res.returncode, "stdout": res.stdout}
    if bench:
        run_case("bench-quick", ["bench", "--quick", "--scenarios", "hill-drive", "--seeds",
                                 "1", "--workers", "1"], work, prints)
    return {"log": None if log is None else log.name, "cases": prints}


def _close(a: str, b: str) -> bool:
    x, y = float.fromhex(a), float.fromhex(b)
    if math.isnan(x) and math.isnan(y):
        return True
    if math.isinf(x) or math.isinf(y):
        return x == y
    return abs(x - y) <= max(REL_TOL * max(abs(x), abs(y)), ABS_FLOOR)


def _compare_values(a: Any, b: Any) -> str:
    """'bitwise', 'within' or 'differs' for two flattened values or column prints."""
    if a == b:
        return "bitwise"
    if isinstance(a, dict) and isinstance(b, dict):
        if "f" in a and "f" in b:
            return "within" if _close(a["f"], b["f"]) else "differs"
        if "samples" in a and "samples" in b:
            if a["n"] != b["n"] or a["nan"] != b["nan"] or a["dtype"] != b["dtype"]:
                return "differs"
            pairs = [(a["sum"], b["sum"]), (a["abs_sum"], b["abs_sum"]),
                     *zip(a["samples"], b["samples"], strict=True)]
            return "within" if all(_close(x, y) for x, y in pairs) else "differs"
    return "differs"


def _leaves(case: dict[str, Any]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for part, val in case.items():
        if part == "estimates":
            for est, cols in val.items():
                for col, fp in cols.items():
                    out[f"estimates/{est}.parquet:{col}"] = fp
        elif isinstance(val, dict):
            for k, v in val.items():
                out[f"{part}:{k}"] = v
        else:
            out[part] = val
    return out


def compare(a: dict[str, Any], b: dict[str, Any]) -> int:
    counts = {"bitwise": 0, "within": 0, "differs": 0, "missing": 0}
    for name in sorted(set(a["cases"]) | set(b["cases"])):
        ca, cb = a["cases"].get(name), b["cases"].get(name)
        if ca is None or cb is None:
            counts["missing"] += 1
            print(f"{name}: only in {'the first' if cb is None else 'the second'} fingerprint")
            continue
        la, lb = _leaves(ca), _leaves(cb)
        for key in sorted(set(la) | set(lb)):
            if key not in la or key not in lb:
                counts["missing"] += 1
                print(f"{name} {key}: only in {'the first' if key not in lb else 'the second'}")
                continue
            kind = _compare_values(la[key], lb[key])
            counts[kind] += 1
            if kind != "bitwise":
                print(f"{name} {key}: {kind}: {la[key]!r:.200} vs {lb[key]!r:.200}")
    print(f"compare: {counts['bitwise']} bitwise, {counts['within']} within {REL_TOL:g} relative,"
          f" {counts['differs']} differ, {counts['missing']} missing on one side")
    return 1 if counts["differs"] or counts["missing"] else 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, help="fingerprint JSON to write")
    ap.add_argument("--log", type=Path, default=None, help="a real log (e.g. an ArduPilot .BIN)")
    ap.add_argument("--no-bench", action="store_true", help="leave out the bench case")
    ap.add_argument("--work", type=Path, default=None, help="output folder of the runs "
                    "(default: a temporary folder, removed afterwards)")
    ap.add_argument("--compare", nargs=2, type=Path, metavar=("A", "B"))
    args = ap.parse_args(argv)
    if args.compare:
        a, b = (json.loads(p.read_text()) for p in args.compare)
        return compare(a, b)
    if args.out is None:
        ap.error("give --out FILE or --compare A B")
    if args.work is not None:
        args.work.mkdir(parents=True, exist_ok=True)
        doc = fingerprint(args.log, not args.no_bench, args.work)
    else:
        with tempfile.TemporaryDirectory(prefix="check-unchanged-") as tmp:
            doc = fingerprint(args.log, not args.no_bench, Path(tmp))
    args.out.write_text(json.dumps(doc, indent=0, sort_keys=True) + "\n")
    codes = {k: v["exit_code"] for k, v in doc["cases"].items()}
    print(f"check_unchanged: wrote {args.out}; exit codes {codes}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
