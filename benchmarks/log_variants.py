"""Generalisation check: the GNSS-outage holdout on *variants* of the shared real logs.

    python benchmarks/log_variants.py --out DIR [--data DIR] [--only N,M,...]

The project is judged on logs it has not seen, so the shared logs are also run as a user
with a different receiver, IMU or recording would give them: GNSS decimated to 1 Hz, a
position-only receiver (no GNSS velocity), the IMU at half rate, no magnetometer, only the
first part of a recording, a 60 s +15 m GNSS height plateau in mid-log (multipath held by
the receiver), and other outage lengths (30 s, 90 s). Each variant runs ``run_holdout``
with graph-batch, graph-isam2, ekf-rts and ekf and records, per estimator, status, altitude
/ horizontal RMSE, baro scale and warnings, plus graph-batch's altitude RMSE over
ekf-rts's (the real-log goal's ratio). Writes ``DIR/log_variants.json`` and prints one line per
variant and every warning. Absent logs are skipped. Nothing here is tuned to these
variants: they are a check, like the hidden logs.

The variants are physical changes of the recording, not new data: a plateau is added to
the GNSS height only (the baro is untouched), decimation keeps every fix ≥ 0.999 s after
the last kept one, the IMU keeps every second sample.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_real_logs import data_root  # noqa: E402

LOGS = {"218": "erle_pxf_218/218.BIN", "loiter_rtl": "erle_pxf_loiter_rtl/Loiter_RTL.bin",
        "ski": "ski_iphone_100hz",
        "car 07-18": "car_phone_1hz_2025-07-18/2025-07-18_23-13-43.csv",
        "car 03-01a": "car_phone_1hz_2025-03-01a/2025-03-01_15-04-26.csv"}
ESTIMATORS = ("graph-batch", "graph-isam2", "ekf-rts", "ekf")


def gnss_1hz(d: Any) -> Any:
    g = d.gnss
    keep = np.zeros(g.t.size, bool)
    last = -np.inf
    for i, t in enumerate(g.t):
        if t - last >= 0.999:
            keep[i], last = True, t
    return d.replace(gnss=g.select(keep))


def position_only(d: Any) -> Any:
    return d.replace(gnss=dataclasses.replace(d.gnss, vel_n=None, vel_sd=None))


def imu_half_rate(d: Any) -> Any:
    from vnav_graph.types.streams import ImuStream

    i = d.imu
    return d.replace(imu=ImuStream(i.t[::2], i.gyro_b[::2], i.accel_b[::2], i.spec))


def no_mag(d: Any) -> Any:
    return d.replace(mag=None)


def first(seconds: float) -> Callable[[Any], Any]:
    def cut(d: Any) -> Any:
        t1 = d.imu.t[0] + seconds
        return d.replace(imu=d.imu.slice(d.imu.t[0], t1), gnss=d.gnss.select(d.gnss.t <= t1),
                         baro=None if d.baro is None else d.baro.select(d.baro.t <= t1),
                         mag=None if d.mag is None else d.mag.select(d.mag.t <= t1))
    return cut


def height_plateau(d: Any, off: float = 15.0, length: float = 60.0) -> Any:
    g = d.gnss
    lla = g.lla.copy()
    mid = g.t[0] + 0.5 * (g.t[-1] - g.t[0])
    lla[(g.t > mid) & (g.t < mid + length), 2] += off
    return d.replace(gnss=dataclasses.replace(g, lla=lla))


def same(d: Any) -> Any:
    return d


# (log, variant, transform, outage [s])
VARIANTS: tuple[tuple[str, str, Callable[[Any], Any], float], ...] = (
    ("218", "GNSS 1 Hz", gnss_1hz, 60.0),
    ("218", "position-only receiver", position_only, 60.0),
    ("218", "IMU half rate", imu_half_rate, 60.0),
    ("218", "no magnetometer", no_mag, 60.0),
    ("218", "height plateau +15 m, 60 s", height_plateau, 60.0),
    ("218", "30 s outages", same, 30.0),
    ("218", "90 s outages", same, 90.0),
    ("loiter_rtl", "GNSS 1 Hz", gnss_1hz, 60.0),
    ("loiter_rtl", "90 s outages", same, 90.0),
    ("ski", "first 200 s", first(200.0), 60.0),
    ("ski", "IMU half rate", imu_half_rate, 60.0),
    ("ski", "30 s outages", same, 30.0),
    ("car 07-18", "first 900 s", first(900.0), 60.0),
    ("car 07-18", "90 s outages", same, 90.0),
    ("car 03-01a", "height plateau +15 m, 60 s", height_plateau, 60.0),
    ("car 03-01a", "30 s outages", same, 30.0),
)


def _block(b: dict[str, Any]) -> dict[str, Any]:
    s = (b.get("baro") or {}).get("scale") or {}
    return {"status": b.get("status"), "error": b.get("error"),
            "alt_rmse_m": b.get("alt_rmse_m"), "horiz_rmse_m": b.get("horiz_rmse_m"),
            "scale": s.get("est"), "scale_sd": s.get("sd"),
            "warnings": list(b.get("warnings") or [])}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", required=True, type=Path)
    ap.add_argument("--data", default=None)
    ap.add_argument("--only", default=None, help="comma-separated variant numbers")
    a = ap.parse_args(argv)
    from vnav_graph.io.readers import read_log
    from vnav_graph.run.runner import run_holdout

    root = data_root(a.data)
    only = None if a.only is None else {int(x) for x in a.only.split(",")}
    cache: dict[str, Any] = {}
    rows = []
    for n, (log, what, f, outage) in enumerate(VARIANTS):
        if only is not None and n not in only:
            continue
        path = root / LOGS[log]
        if not path.exists():
            continue
        if log not in cache:
            cache[log] = read_log(path)
        t0 = time.perf_counter()
        row: dict[str, Any] = {"n": n, "log": log, "variant": what, "outage_s": outage}
        try:
            doc = run_holdout(f(cache[log]), list(ESTIMATORS), outage_s=outage).doc
        except Exception as exc:  # a variant that breaks the holdout is a finding, not a stop
            row["error"] = f"{type(exc).__name__}: {exc}"
            rows.append(row)
            print(f"[{n}] {log}, {what}: FAILED {row['error']}", flush=True)
            continue
        est = {k: _block(v) for k, v in doc["estimators"].items()}
        gb, er = est["graph-batch"], est["ekf-rts"]
        ok = gb["status"] == er["status"] == "ok"
        row.update(estimators=est, runtime_s=time.perf_counter() - t0,
                   excluded=doc["reference_screening"]["excluded"],
                   alt_ratio=gb["alt_rmse_m"] / er["alt_rmse_m"] if ok else None,
                   warnings=sum(len(b["warnings"]) for b in est.values()))
        rows.append(row)
        cells = " | ".join(
            f"{k} {b['alt_rmse_m']:.2f}/{b['horiz_rmse_m'] or 0:.0f} m" if b["status"] == "ok"
            else f"{k} {b['status']}" for k, b in est.items())
        ratio = "—" if row["alt_ratio"] is None else f"{row['alt_ratio']:.2f}"
        print(f"[{n}] {log}, {what} ({outage:.0f} s): ratio {ratio}, warnings "
              f"{row['warnings']}, excluded {row['excluded']} | {cells}", flush=True)
        for k, b in est.items():
            for w in b["warnings"]:
                print(f"    {k}: {w}", flush=True)
    failed = [r for r in rows if "error" in r or any(
        b["status"] != "ok" for b in r.get("estimators", {}).values())]
    summary = {"variants": len(rows), "failed": len(failed),
               "with_warnings": sum(1 for r in rows if r.get("warnings")),
               "alt_ratio_above_1.05": sum(1 for r in rows
                                           if (r.get("alt_ratio") or 0.0) > 1.05)}
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / "log_variants.json").write_text(json.dumps(
        {"schema": "vnav_graph.log_variants/1", "summary": summary, "variants": rows},
        indent=1, default=float))
    print(json.dumps(summary))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
