"""Every full estimator on the two real drives with an RTK reference, scored against it.

    python benchmarks/truth_logs.py [--data DIR] [--out DIR] [--estimators a,b]
                                    [--markdown docs/truth_logs.md]

Drives (``rtk/`` of the shared data, read with ``examples/maps/<folder>.toml``):

- ``car_drive_0708``: GNSS input is the RTK solution itself. Scored inside GNSS windows
  withheld from it: ``holdout`` windows of 30 s and of 60 s (``evaluation.holdout``'s default
  lead-in and spacing), and the source repository's simulated outages: 15 s windows repeating
  every 45 s from 40 s after the first ``.pos`` epoch, ending 30 s before the last (11).
- ``walk_0827``: GNSS input is the single-point solution ``gnss_1730_spp.pos``; scored
  against the RTK solution over the whole walk, and inside the source's outages (15 s every
  45 s from 25 s after the first epoch, ending 45 s before the last: 2 windows).

Against the source repository's own filter (``PEER``): both recordings with the RTK solution
as GNSS input (the walk through ``examples/maps/walk_0827_rtk.toml``), the source's outages
withheld, scored at the RTK-fixed epochs only; its numbers are quoted, not re-run here (its
code is not part of this repository), and each goal of ``PEER_GOALS`` is checked cell by cell.

Scores (``evaluation.reference_score``): altitude and horizontal RMSE and maxima against the
reference at its epochs inside the windows, NEES/dof there, and the heading error against the
reference's course at its epochs where it moves faster than 1 m/s (the car's body points
along its course; a hand-held device need not, so the walk's is an upper bound). Wall times
per estimator run. Writes ``DIR/truth_logs.json``, prints Markdown and, with ``--markdown``,
writes it to that file.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_real_logs import data_root  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
ESTIMATORS = ("ekf", "ekf-rts", "graph-isam2", "graph-batch")
DRIVES = {
    "car_drive_0708": {"truth": "gnss_1934_sf.pos", "source_outages": (40.0, 30.0)},
    "walk_0827": {"truth": "gnss_1730_sf.pos", "source_outages": (25.0, 45.0)},
}
SOURCE_OUTAGE_S, SOURCE_PERIOD_S = 15.0, 45.0
# The source repository's GNSS/IMU filter (loosely coupled, after Groves; zero-velocity
# updates, yaw from the GNSS course, noise tuned for this IMU), run with its own configuration
# on the RTK input with the outages above withheld, scored at the withheld RTK-fixed epochs:
# (max, RMS) [m] per recording and axis. Quoted from a run of its code at the snapshot the
# data README names.
PEER = {
    "peer forward (causal)": {
        ("walk", "horizontal"): (5.61, 2.26), ("walk", "vertical"): (2.47, 0.88),
        ("car", "horizontal"): (12.81, 3.09), ("car", "vertical"): (1.40, 0.41)},
    "peer forward with velocity matching": {
        ("walk", "horizontal"): (0.55, 0.29), ("walk", "vertical"): (0.10, 0.04),
        ("car", "horizontal"): (0.68, 0.30), ("car", "vertical"): (0.32, 0.09)},
}
# ours against the peer output it should match or beat, in every cell
PEER_GOALS = {"ekf": "peer forward (causal)", "ekf-rts": "peer forward with velocity matching",
              "graph-batch": "peer forward with velocity matching"}
# recording -> (folder, column map, reference, source outage start/end margins [s])
PEER_DRIVES = {"walk": ("walk_0827", "walk_0827_rtk", "gnss_1730_sf.pos", (25.0, 45.0)),
               "car": ("car_drive_0708", "car_drive_0708", "gnss_1934_sf.pos", (40.0, 30.0))}
PEER_KEYS = {"horizontal": ("horiz_max_m", "horiz_rmse_m"),
             "vertical": ("alt_max_abs_m", "alt_rmse_m")}


def source_windows(t_first: float, t_last: float, start_s: float, end_s: float
                   ) -> list[tuple[float, float]]:
    """The source repository's simulated outages on the drive clock [s]."""
    out = []
    s = t_first + start_s
    while s + SOURCE_OUTAGE_S <= t_last - end_s + 1e-9:
        out.append((s, s + SOURCE_OUTAGE_S))
        s += SOURCE_PERIOD_S
    return out


def heading_rmse_deg(est: Any, drive: Any, windows: list[tuple[float, float]]) -> float | None:
    """RMS of estimate yaw − reference course [deg] at moving reference epochs in windows."""
    from vnav_graph.geo.frames import quat_to_rph
    from vnav_graph.io.reference import COURSE_MIN_SPEED

    tr, ref = est.trajectory, drive.truth
    if tr.q_nb is None or "att" not in est.provides:
        return None
    m = np.zeros(ref.t.size, dtype=bool)
    for a, b in windows:
        m |= (ref.t >= a) & (ref.t <= b)
    m &= (ref.t >= tr.t[0]) & (ref.t <= tr.t[-1])
    m &= np.hypot(ref.vel_n[:, 0], ref.vel_n[:, 1]) > COURSE_MIN_SPEED
    if not m.any():
        return None
    q = tr.at(ref.t[m]).q_nb
    yaw = quat_to_rph(q)[:, 2]
    course = np.arctan2(ref.vel_n[m, 1], ref.vel_n[m, 0])
    d = (yaw - course + np.pi) % (2 * np.pi) - np.pi
    return float(np.degrees(np.sqrt(np.mean(d**2))))


def scored_case(drive: Any, windows: list[tuple[float, float]], names: list[str],
                withhold_gnss: bool) -> dict[str, Any]:
    from vnav_graph.evaluation.holdout import withhold
    from vnav_graph.evaluation.reference_score import reference_block
    from vnav_graph.run.runner import run_estimators

    held = withhold(drive, windows) if withhold_gnss else drive
    out: dict[str, Any] = {"windows": [list(w) for w in windows], "estimators": {}}
    for r in run_estimators(held, names, progress=False, desc="truth_logs"):
        if r.estimate is None:
            out["estimators"][r.name] = {"status": r.status, "error": r.error,
                                         "runtime_s": r.runtime_s}
            continue
        b = reference_block(r.estimate, drive, windows) or {}
        b.pop("per_window", None)
        b.update(status="ok", runtime_s=float(r.estimate.runtime_s),
                 heading_rmse_deg=heading_rmse_deg(r.estimate, drive, windows),
                 gnss_rejected=r.estimate.info.get("gnss_rejected"))
        out["estimators"][r.name] = b
    return out


def run_drive(root: Path, folder: str, names: list[str]) -> dict[str, Any]:
    from vnav_graph.evaluation.holdout import choose_windows
    from vnav_graph.io.reference import load_scored

    cfg = DRIVES[folder]
    path = root / "rtk" / folder
    drive = load_scored(path, REPO / "examples" / "maps" / f"{folder}.toml",
                        truth=path / cfg["truth"])
    g, ref = drive.gnss, drive.truth
    doc: dict[str, Any] = {"reference": drive.meta["reference"], "cases": {}}
    t_first, t_last = float(ref.t[0]), float(ref.t[-1])
    src = source_windows(t_first, t_last, *cfg["source_outages"])
    if drive.meta["reference"]["is_gnss_input"]:
        for outage in (30.0, 60.0):
            doc["cases"][f"withheld {outage:g} s"] = scored_case(
                drive, choose_windows(g.t, outage), names, True)
    else:
        whole = [(max(t_first, float(drive.imu.t[0])), min(t_last, float(drive.imu.t[-1])))]
        doc["cases"]["whole drive, GNSS input"] = scored_case(drive, whole, names, False)
    doc["cases"]["source outages 15 s"] = scored_case(drive, src, names, True)
    return doc


def run_peer_cases(root: Path, names: list[str]) -> dict[str, Any]:
    """Our estimators on the peer's footing (module docstring): {recording: scored_case}."""
    from vnav_graph.io.reference import attach_reference, load_scored

    out = {}
    for rec, (folder, cmap, truth, margins) in PEER_DRIVES.items():
        path = root / "rtk" / folder
        if not path.is_dir():
            continue
        cm = REPO / "examples" / "maps" / f"{cmap}.toml"
        base = load_scored(path, cm)  # the logs are read once; the reference twice:
        # the windows are placed on the file's span (every epoch), the scores use its fixes
        ref_all = attach_reference(base, path / truth, path, cm).truth
        drive = attach_reference(base, path / truth, path, cm, fix_only=True)
        src = source_windows(float(ref_all.t[0]), float(ref_all.t[-1]), *margins)
        out[rec] = scored_case(drive, src, names, True)
    return out


def _peer_cell(case: dict[str, Any] | None, name: str, axis: str) -> tuple[float, float] | None:
    b = (case or {}).get("estimators", {}).get(name) or {}
    if b.get("status") != "ok":
        return None
    mx, rms = (b.get(k) for k in PEER_KEYS[axis])
    return None if mx is None or rms is None else (float(mx), float(rms))


def render_peer(peer: dict[str, Any], names: list[str]) -> list[str]:
    """The table against the peer and one line per goal of ``PEER_GOALS``: met, or each
    cell where ours is above the peer's."""
    cells = [(rec, axis) for rec in PEER_DRIVES for axis in PEER_KEYS]
    n_win = {rec: len((peer.get(rec) or {}).get("windows", [])) for rec in PEER_DRIVES}
    lines = ["## Against the source repository's filter", "",
             "Both recordings with the RTK solution as GNSS input, the source's 15 s outages "
             f"withheld ({n_win['walk']} on the walk, {n_win['car']} on the car), scored at "
             "the RTK-fixed epochs inside them; max / RMS [m]. The peer's rows are quoted "
             "from a run of its own code and configuration (``PEER`` in "
             "`benchmarks/truth_logs.py`); ours are measured by this benchmark.", "",
             "| in the withheld windows | " + " | ".join(f"{r} {a}" for r, a in cells) + " |",
             "|---" * (len(cells) + 1) + "|"]
    for label, vals in PEER.items():
        lines.append(f"| {label} | " + " | ".join(
            f"{vals[c][0]:.2f} / {vals[c][1]:.2f}" for c in cells) + " |")
    for name in names:
        row = [_peer_cell(peer.get(r), name, a) for r, a in cells]
        lines.append(f"| {name} | " + " | ".join(
            "—" if v is None else f"{v[0]:.2f} / {v[1]:.2f}" for v in row) + " |")
    lines += ["", "Goals (each of ours at or below the named peer output in every cell):", ""]
    for name, target in PEER_GOALS.items():
        if name not in names:
            continue
        misses = []
        for rec, axis in cells:
            ours = _peer_cell(peer.get(rec), name, axis)
            theirs = PEER[target][(rec, axis)]
            if ours is None:
                misses.append(f"{rec} {axis}: no score")
                continue
            misses += [f"{rec} {axis} {what} {o:.2f} > {t:.2f} m"
                       for what, o, t in zip(("max", "RMS"), ours, theirs, strict=True)
                       if round(o, 2) > t]
        verdict = "met" if not misses else "missed: " + "; ".join(misses)
        lines.append(f"- {name} against {target}: {verdict}")
    return lines + [""]


def render(doc: dict[str, Any]) -> str:
    def f(v: Any, spec: str = ".2f") -> str:
        return "—" if v is None else format(v, spec)

    lines = ["# Real drives against their RTK reference", "",
             "Generated by `python benchmarks/truth_logs.py --markdown docs/truth_logs.md` "
             "(module docstring: drives, windows, scoring). Errors are against the receiver's "
             "RTK solution at its epochs inside the windows; heading against its course while "
             "it moves faster than 1 m/s.", "",
             "Reading the tables: on the car the input is the RTK solution, so every error is "
             "an outage error against an independent centimetre truth. On the walk the input "
             "is the single-point solution, whose own error against the RTK is 8.2 m "
             "horizontal (a bias of about 5.9 m north and 5.5 m east) and 5.9 m vertical "
             "RMSE; no estimator can remove a bias that the only position input shares, and "
             "NEES/dof far above 1 says the file's σ (about 3 m) does not cover it. The "
             "walk's device is hand-held, so its heading against the course of travel is an "
             "upper bound, not a heading error. The car's receiver reports each velocity as "
             "the mean over the interval before its epoch: the shared sensor model widens "
             "its velocity σ to what the positions support (sensors/gnss_consistency.py, "
             "the estimators' gnss_vel_note), and NEES/dof counts the reference velocity's "
             "own lag (about 0.1 m/s per axis) as error.", ""]
    for folder, d in doc["drives"].items():
        ref = d["reference"]
        qual = ", ".join(f"{k} {v}" for k, v in ref["quality"].items())
        lines += [f"## {folder}", "", f"Reference {ref['file']} ({qual}); heights "
                  f"{ref['height']}; lever arm: {ref['lever_arm']}.", ""]
        for case, c in d["cases"].items():
            lines += [f"### {case} ({len(c['windows'])} window(s))", "",
                      "| estimator | horiz RMSE m | horiz max m | alt RMSE m | alt max m "
                      "| heading RMSE deg | NEES/dof | run s |",
                      "|---|---|---|---|---|---|---|---|"]
            for name, b in c["estimators"].items():
                if b.get("status") != "ok":
                    lines.append(f"| {name} | {b.get('status')}: {b.get('error')} |||||||")
                    continue
                nd = b["nees_mean"] / b["nees_dof"] if b.get("nees_dof") else None
                lines.append(f"| {name} | {f(b['horiz_rmse_m'])} | {f(b['horiz_max_m'])} | "
                             f"{f(b['alt_rmse_m'])} | {f(b['alt_max_abs_m'])} | "
                             f"{f(b['heading_rmse_deg'], '.1f')} | {f(nd)} | "
                             f"{f(b['runtime_s'], '.1f')} |")
            lines.append("")
    if doc.get("peer"):
        lines += render_peer(doc["peer"], doc["estimators"])
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=None)
    ap.add_argument("--out", default="truth-logs")
    ap.add_argument("--estimators", default=",".join(ESTIMATORS))
    ap.add_argument("--markdown", default=None)
    args = ap.parse_args(argv)
    root = data_root(args.data)
    names = [n for n in args.estimators.split(",") if n]
    doc: dict[str, Any] = {"estimators": names, "drives": {}}
    for folder in DRIVES:
        if not (root / "rtk" / folder).is_dir():
            print(f"missing: rtk/{folder}", file=sys.stderr)
            continue
        doc["drives"][folder] = run_drive(root, folder, names)
        print(f"rtk/{folder}: done", file=sys.stderr, flush=True)
    doc["peer"] = run_peer_cases(root, names)
    print("peer cases: done", file=sys.stderr, flush=True)
    if not doc["drives"]:
        print("no shared RTK drives found", file=sys.stderr)
        return 2
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "truth_logs.json").write_text(json.dumps(doc, indent=1, default=str) + "\n")
    md = render(doc)
    if args.markdown:
        Path(args.markdown).write_text(md + "\n")
    print(md)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
