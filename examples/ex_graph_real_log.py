"""Run the factor-graph smoother on a real phone log (Sensor Logger export).

The log is read by ``vnav_graph.io.load_drive`` (format detected from content), optionally
cut to its first ``duration_s`` seconds, and smoothed by ``graph-batch``. There is no truth
on a real log: the altitude is compared with the GNSS fixes (RMS of estimate − GNSS, which
includes the GNSS vertical noise), and the baro parameters come with their σ.

Where the log comes from, first found wins: a Sensor Logger folder committed under
``tests/data``, ``$VNAV_DATA/ski_iphone_100hz``, ``../shared/data/ski_iphone_100hz`` beside the
repository. Run: ``python examples/ex_graph_real_log.py [LOG]``.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from vnav_graph.estimators.base import available
from vnav_graph.io import load_drive
from vnav_graph.run.pipeline import run_estimators, summarize
from vnav_graph.types import Drive

REQUIRES = ("graph-batch",)
REPO = Path(__file__).resolve().parent.parent


def find_log() -> Path | None:
    """A Sensor Logger export (folder) to run on, or None."""
    from vnav_graph.io.readers.sensorlogger import is_sensorlogger_folder

    tdata = REPO / "tests" / "data"
    cands = sorted(p for p in tdata.rglob("*") if p.is_dir()) if tdata.is_dir() else []
    for env in (os.environ.get("VNAV_DATA"), str(REPO.parent / "shared" / "data")):
        if env:
            cands.append(Path(env) / "ski_iphone_100hz")
    for c in cands:
        if c.is_dir() and is_sensorlogger_folder(c):
            return c
    return None


def head(drive: Drive, duration_s: float | None) -> Drive:
    """The first ``duration_s`` seconds of a drive (all streams cut on the common clock)."""
    if duration_s is None:
        return drive
    t1 = drive.imu.t[0] + duration_s
    gnss = None if drive.gnss is None else drive.gnss.select(drive.gnss.t <= t1)
    baro = None if drive.baro is None else drive.baro.select(drive.baro.t <= t1)
    return drive.replace(imu=drive.imu.slice(drive.imu.t[0], t1), gnss=gnss, baro=baro)


def main(duration_s: float | None = 120.0, log: str | Path | None = None) -> dict[str, Any]:
    """Returns ``{"drive", "summary", "results", "alt_vs_gnss_rms_m": {name: m}}``."""
    path = Path(log) if log is not None else find_log()
    if path is None:
        raise FileNotFoundError("no Sensor Logger log found (tests/data, $VNAV_DATA or "
                                "../shared/data)")
    drive = head(load_drive(path), duration_s)
    names = [n for n in ("graph-batch", "ekf") if n in available()]
    results = run_estimators(drive, names, progress=False)
    summary = summarize(drive, results)
    g = drive.gnss
    rms = {}
    for r in results:
        if r.estimate is not None:
            tr = r.estimate.trajectory
            m = (g.t >= tr.t[0]) & (g.t <= tr.t[-1])
            e = np.interp(g.t[m], tr.t, tr.alt) - g.lla[m, 2]
            rms[r.name] = float(np.sqrt(np.mean(e**2)))
    return {"drive": drive, "summary": summary, "results": results, "alt_vs_gnss_rms_m": rms}


if __name__ == "__main__":
    import sys

    from vnav_graph.run.pipeline import format_table

    res = main(duration_s=None, log=sys.argv[1] if len(sys.argv) > 1 else None)
    print(format_table(res["summary"]))
    print("altitude RMS vs GNSS [m]:", res["alt_vs_gnss_rms_m"])
