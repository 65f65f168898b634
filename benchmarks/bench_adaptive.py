"""When does the adaptive 3rd-order loop (seed 000) help against the fixed loop3?

Cases on the simulated ``sortie`` (climbs/descents up to 15 m/s):
- ``baro_step``: a +15 m step added to the baro altitude at mid-drive (a baro glitch or a
  QNH change): settling time to within 10 % of the step of (loop altitude − undisturbed
  loop altitude) and altitude RMSE over the 120 s after it;
- ``dynamics``: altitude RMSE over the epochs with |v_z| > 5 m/s (fast climbs/descents);
- ``latency``: the same drive with a 0.3 s baro latency, altitude RMSE in dynamics;
- ``cruise``: altitude RMSE over the epochs with |v_z| < 0.5 m/s, no step.
"loop" errors are against the barometer's noiseless undelayed reading h0 + (1+s)(h − h0) + b
(what a perfect damping loop outputs: loops follow the baro, its scale and bias are not
theirs to remove); ``overall_truth_rmse_m`` is against the true height.

Usage: python benchmarks/bench_adaptive.py [--quick] --out DIR   (writes DIR/adaptive.json)
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from vnav_graph.config import BaroSpec
from vnav_graph.estimators.vertical.adaptive import AdaptiveConfig, run_adaptive
from vnav_graph.estimators.vertical.loops import LoopInputs, gains3, loop_inputs, run_loop
from vnav_graph.simulation import load_scenario, simulate
from vnav_graph.types.streams import BaroStream

VARIANTS = {
    "loop3": None,
    "adaptive-linear": AdaptiveConfig(function="linear"),
    "adaptive-exp": AdaptiveConfig(function="exp"),
    "adaptive-tanh": AdaptiveConfig(function="tanh"),
    "adaptive-sigmoid": AdaptiveConfig(function="sigmoid"),
    "adaptive-tanh-vz": AdaptiveConfig(function="tanh", signal="vz"),
}
STEP_M = 15.0


def _run(name: str, inp: LoopInputs) -> np.ndarray:
    if VARIANTS[name] is None:
        x, _ = run_loop(inp, gains3(20.0, inp.ws2))
    else:
        x, _, _ = run_adaptive(inp, VARIANTS[name])
    return x[:, 0] + inp.h0


def _rmse(e: np.ndarray) -> float:
    return float(np.sqrt(np.mean(e**2))) if e.size else float("nan")


def one_seed(seed: int, duration: float) -> dict:
    from dataclasses import replace

    cfg = load_scenario("sortie", duration_s=duration)
    d = simulate(cfg, seed)
    d_lat = simulate(replace(cfg, baro=replace(cfg.baro, latency_s=0.3,
                                                latency_range_s=None)), seed)
    assert isinstance(cfg.baro, BaroSpec)
    inp = loop_inputs(d)
    t = inp.t
    t_step = 0.5 * duration
    alt_step = d.baro.altitude + np.where(d.baro.t >= t_step, STEP_M, 0.0)
    d_step = d.replace(baro=BaroStream(d.baro.t, alt=alt_step, spec=d.baro.spec))
    inp_step = LoopInputs(t, inp.a_up, np.interp(t, d.baro.t, alt_step) - inp.h0, inp.h0,
                          inp.ws2)
    del d_step
    inp_lat = loop_inputs(d_lat)
    truth = d.truth.alt
    # what a perfect loop would output: the barometer's noiseless, undelayed reading
    # h0 + (1+s)(h − h0) + b(t) (the loops track the baro; its scale/bias are not theirs)
    def ideal(dd):
        return dd.origin_lla[2] + (1 + dd.baro_truth.scale) * (dd.truth.alt - dd.origin_lla[2]) \
            + dd.truth.bias_baro
    ref, ref_lat = ideal(d), ideal(d_lat)
    vz = -d.truth.vel_n[:, 2]
    dyn = (np.abs(vz) > 5.0) & (t > 60)
    cruise = (np.abs(vz) < 0.5) & (t > 60)
    after = (t >= t_step) & (t < t_step + 120.0)
    out = {}
    for name in VARIANTS:
        t0 = time.perf_counter()
        h = _run(name, inp)
        hs = _run(name, inp_step)
        hl = _run(name, inp_lat)
        dh = hs - h  # response to the step alone (same noise realisation)
        bad = np.flatnonzero((t >= t_step) & (np.abs(dh - STEP_M) > 0.1 * STEP_M))
        out[name] = {
            "step_settling_s": float(t[bad[-1]] - t_step) if bad.size else 0.0,
            "step_loop_rmse_m": _rmse((hs - ref - STEP_M)[after]),
            "dynamics_loop_rmse_m": _rmse((h - ref)[dyn]),
            "latency_dynamics_loop_rmse_m": _rmse((hl - ref_lat)[dyn]),
            "cruise_loop_rmse_m": _rmse((h - ref)[cruise]),
            "overall_loop_rmse_m": _rmse((h - ref)[t > 60]),
            "overall_truth_rmse_m": _rmse((h - truth)[t > 60]),
            "runtime_s": time.perf_counter() - t0,
        }
    return out


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="1 seed, 600 s")
    ap.add_argument("--out", required=True, type=Path)
    a = ap.parse_args(argv)
    seeds = [0] if a.quick else [0, 1, 2, 3, 4]
    duration = 600.0 if a.quick else 1200.0
    runs = {s: one_seed(s, duration) for s in seeds}
    keys = next(iter(runs.values()))["loop3"].keys()
    agg = {n: {k: float(np.mean([runs[s][n][k] for s in seeds])) for k in keys}
           for n in VARIANTS}
    res = {"schema": "vnav_graph.adaptive/1", "scenario": "sortie", "duration_s": duration,
           "seeds": seeds, "step_m": STEP_M, "tau_s": 20.0,
           "runs": {str(s): runs[s] for s in seeds},
           "aggregate": agg,
           "speedup_vs_loop3": {n: agg["loop3"]["step_settling_s"] / agg[n]["step_settling_s"]
                                for n in VARIANTS if agg[n]["step_settling_s"] > 0}}
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / "adaptive.json").write_text(json.dumps(res, indent=1))
    for n, v in agg.items():
        print(f"{n:18s} " + " ".join(f"{k}={x:.2f}" for k, x in v.items()))
    return res


if __name__ == "__main__":
    main()
