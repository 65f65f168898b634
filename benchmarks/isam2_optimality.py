"""How close graph-isam2's online and fixed-lag estimates are to what the data allow.

Usage::

    python benchmarks/isam2_optimality.py [--seeds 5] [--duration 300] [--every 20]
        [--scenarios hill-drive,sortie] [--config FILE] --out DIR

Writes ``DIR/isam2_optimality.json`` (schema ``vnav_graph.isam2_optimality/1``) and prints
one line per scenario.

The optimum of a causal estimate at time t is the smoothed answer of the drive cut at t:
the same model solved by graph-batch on the data up to t, every term relinearised. The
optimum of the fixed-lag estimate at t − L is the same solve read at t − L. Per (scenario,
seed), graph-isam2 runs once on the whole drive; at cut times t_c = 60, 60 + every, … s
graph-batch runs on the drive cut at t_c. At each cut, against the truth (horizontal and
altitude error [m]):

- ``online``: graph-isam2's online estimate at t_c; ``filter_optimum``: the cut solve at t_c;
  ``ekf``: the forward ekf's online estimate at t_c (the filter it is compared with);
- ``lag``: graph-isam2's lag estimate at t_c − L; ``lag_optimum``: the cut solve at t_c − L;
  ``smoother``: graph-batch on the whole drive at t_c − L; ``final``: graph-isam2's final
  trajectory there (the same data as ``smoother``, its own fix selection: ``docs/graph.md``,
  "Online GNSS gate").

and the distance of graph-isam2 from its optimum (``online_gap``, ``lag_gap``) and of its
final trajectory from graph-batch's (``final_gap``). RMS over the
cuts and seeds. ``lag`` ≈ ``lag_optimum`` with both far above ``smoother`` means the gap of
the lag goal is information the lag has not seen (a GNSS outage longer than L), not the
incremental solver; a large ``lag_gap`` would be the solver's. Every estimator runs with
``benchmarks/hard_scenarios.toml`` (``--config``: another file of the same form). Cut
drives end with every stream and the truth at t_c (``Drive.until``).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

SCHEMA = "vnav_graph.isam2_optimality/1"
REPO = Path(__file__).resolve().parent.parent
CONFIG = REPO / "benchmarks" / "hard_scenarios.toml"
FIRST_CUT_S = 60.0
KEYS = ("online", "filter_optimum", "ekf", "lag", "lag_optimum", "smoother", "final",
        "online_gap", "lag_gap", "final_gap")


def ned_at(traj: Any, t: float, origin: Any) -> np.ndarray | None:
    """NED position [m] of ``traj`` at ``t`` (None outside its span, beyond 1 ms)."""
    from vnav_graph.geo.frames import lla_to_ned

    if traj is None or t < traj.t[0] - 1e-3 or t > traj.t[-1] + 1e-3:
        return None
    return lla_to_ned(traj.at(np.array([t])).lla, origin)[0]


def run_one(job: tuple[str, int, float, float, str]) -> dict[str, Any]:
    """One (scenario, seed): the errors of every estimate at every cut (module docstring)."""
    from vnav_graph.estimators.configfile import load_configs
    from vnav_graph.evaluation.montecarlo import shorten_scenario
    from vnav_graph.geo.frames import lla_to_ned
    from vnav_graph.run.runner import run_one as run_estimator
    from vnav_graph.simulation import simulate

    scenario, seed, duration, every, config = job
    configs = load_configs(Path(config))
    drive = simulate(shorten_scenario(scenario, duration), seed)
    o, t0 = drive.origin_lla, float(drive.imu.t[0])
    full = {n: run_estimator(n, drive, configs.get(n), interrupts=False)
            for n in ("ekf", "graph-isam2", "graph-batch")}
    bad = {n: r.error for n, r in full.items() if r.estimate is None}
    out: dict[str, Any] = {"scenario": scenario, "seed": seed, "cuts": [], "error": bad}
    if bad:
        return out
    g, ekf, gb = (full[n].estimate for n in ("graph-isam2", "ekf", "graph-batch"))
    lag_s = float(g.info["lag_s"])
    for tc in np.arange(t0 + FIRST_CUT_S, float(drive.imu.t[-1]) - 1.0, every):
        r = run_estimator("graph-batch", drive.until(float(tc)), configs.get("graph-batch"),
                          interrupts=False)
        if r.estimate is None:
            out["cuts"].append({"t_s": float(tc - t0), "error": r.error})
            continue
        kf = int(np.argmin(np.abs(g.online.t - tc)))
        tk = float(g.online.t[kf])  # the keyframe at the cut
        tl = tk - lag_s
        tr = r.estimate.trajectory
        pos = {"online": ned_at(g.online, tk, o), "filter_optimum": ned_at(tr, tk, o),
               "ekf": ned_at(ekf.online, tk, o), "lag": ned_at(g.lag, tl, o),
               "lag_optimum": ned_at(tr, tl, o),
               "smoother": ned_at(gb.trajectory, tl, o), "final": ned_at(g.trajectory, tl, o)}
        truth = {t: lla_to_ned(drive.truth.at(np.array([t])).lla, o)[0] for t in (tk, tl)}
        row: dict[str, Any] = {"t_s": tk - t0}
        for k, p in pos.items():
            ref = truth[tk] if k in ("online", "filter_optimum", "ekf") else truth[tl]
            row[k] = None if p is None else {"horiz_m": float(np.hypot(*(p - ref)[:2])),
                                             "alt_m": float(abs((p - ref)[2]))}
        for k, a, b in (("online_gap", "online", "filter_optimum"),
                        ("lag_gap", "lag", "lag_optimum"), ("final_gap", "final", "smoother")):
            pa, pb = pos[a], pos[b]
            row[k] = None if pa is None or pb is None else {
                "horiz_m": float(np.hypot(*(pa - pb)[:2])), "alt_m": float(abs((pa - pb)[2]))}
        out["cuts"].append(row)
    return out


def summarise(runs: list[dict[str, Any]]) -> dict[str, Any]:
    """RMS over cuts and seeds, per scenario and estimate (``KEYS``)."""
    out: dict[str, Any] = {}
    for sc in dict.fromkeys(r["scenario"] for r in runs):
        rows = [c for r in runs if r["scenario"] == sc for c in r["cuts"] if "error" not in c]
        s: dict[str, Any] = {"cuts": len(rows)}
        for k in KEYS:
            for m in ("horiz_m", "alt_m"):
                v = np.array([c[k][m] for c in rows if c.get(k) is not None])
                s[f"{k}_{m}"] = float(np.sqrt(np.mean(v ** 2))) if v.size else None
        out[sc] = s
    return out


def line(sc: str, s: dict[str, Any]) -> str:
    f = "{:.3f}".format

    def h(k: str) -> str:
        v = s[f"{k}_horiz_m"]
        return "—" if v is None else f(v)

    return (f"{sc}: {s['cuts']} cuts, horizontal RMS [m]: online {h('online')} vs filter "
            f"optimum {h('filter_optimum')} (gap {h('online_gap')}), ekf {h('ekf')}; lag "
            f"{h('lag')} vs lag optimum {h('lag_optimum')} (gap {h('lag_gap')}), whole-drive "
            f"smoother {h('smoother')}, final graph-isam2 {h('final')} (from it "
            f"{h('final_gap')})")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--duration", type=float, default=300.0, help="drive length [s]")
    ap.add_argument("--every", type=float, default=20.0, help="spacing of the cuts [s]")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--scenarios", default="hill-drive,sortie")
    ap.add_argument("--config", type=Path, default=CONFIG,
                    help="estimator configurations (default benchmarks/hard_scenarios.toml)")
    ap.add_argument("--out", type=Path, required=True)
    a = ap.parse_args(argv)
    if a.seeds < 1 or a.workers < 1 or a.every <= 0 or a.duration <= FIRST_CUT_S:
        print("isam2_optimality: --seeds, --workers, --every must be positive and --duration "
              f"> {FIRST_CUT_S:.0f} s", file=sys.stderr)
        return 2
    jobs = [(s, k, a.duration, a.every, str(a.config)) for s in a.scenarios.split(",") if s
            for k in range(a.seeds)]
    t0 = time.perf_counter()
    runs = []
    with ProcessPoolExecutor(max_workers=a.workers) as pool:
        for r in pool.map(run_one, jobs):
            runs.append(r)
            print(f"{r['scenario']} seed {r['seed']}: {len(r['cuts'])} cuts"
                  f"{'; failed: ' + str(r['error']) if r['error'] else ''}",
                  file=sys.stderr, flush=True)
    summary = summarise(runs)
    doc = {"schema": SCHEMA, "config": {**{k: getattr(a, k) for k in
                                           ("seeds", "duration", "every", "scenarios")},
                                        "configuration": (
                                            "benchmarks/hard_scenarios.toml"
                                            if a.config == CONFIG else a.config.name),
                                        "wall_s": time.perf_counter() - t0},
           "summary": summary, "runs": runs}
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / "isam2_optimality.json").write_text(json.dumps(doc, indent=1) + "\n")
    print("\n".join(line(sc, s) for sc, s in summary.items()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
