"""Performance of the GTSAM smoothers on a long hill-drive (docs/design.md ``graph_perf.json``).

    python benchmarks/bench_graph.py [--quick | --hours H] --out DIR

Writes ``DIR/graph_perf.json`` with the keys
``drive_duration_s, keyframes, batch_s, builtin_floor_s, batch_over_floor, isam2_s,
isam2_realtime_factor, isam2_update_p99_ms, ekf_s, ekf_realtime_factor, peak_rss_mb,
general_over_floor`` and (additive) ``peak_rss_mb_by_stage``, ``isam2_relinearized``.

- ``batch_s``: graph-batch graph construction + Gauss-Newton solve (all baro samples and
  GNSS fixes, custom terms linearised in numpy each iteration). Shared set-up (initial
  values, IMU preintegration) and the marginal covariances are not included in either
  timing.
- ``builtin_floor_s``: the same keyframes, the same preintegrated IMU factors (``ImuFactor``
  and a ``BetweenFactorConstantBias`` with the variance of the graph's bias step,
  ``builders.bias_step``: a random walk, no decay), GPS factors
  at keyframe epochs and GTSAM's ``BarometricFactor`` (pressure in kPa, +z up: the altitude
  is fed mirrored because the graph is NED; bias only, one baro sample per keyframe, bias
  random walk as ``BetweenFactorDouble``) — only C++ factors — solved with GTSAM's
  Levenberg-Marquardt in the same run.
- ``general_over_floor``: the same graph-batch solve (same drive, same run) with the general
  sparse path forced (``GraphConfig(solver="general")``: GTSAM elimination of the linearised
  graph, the interval terms as HessianFactor pieces), over ``builtin_floor_s``.
- ``isam2_s``: the whole ``graph-isam2`` run (online pass + final smoothing + outputs);
  ``isam2_update_p99_ms``: 99th percentile of the per-keyframe online update, including the
  Python work of that keyframe (preintegration, interval linearisation, rebuilding the custom
  terms due for relinearisation); ``isam2_relinearized``: how many keyframe intervals had
  their custom baro/GNSS terms rebuilt and swapped in by the online pass
  (``info["isam2_relinearized"]``, ``graph.relin``).
- Both estimators first run once on a 60 s drive (not timed) so that loading numba's cached
  kernels is not counted.
- ``ekf_*``: from ``benchmarks/bench_ekf.py:bench_ekf(duration_s, imu_rate_hz, seed,
  with_rts=False, drive=drive)`` when that file exists, else null: the EKF on the same
  drive (ekf-rts is not reported here and not run); the graph estimates are released first.
- ``peak_rss_mb``: peak resident memory of the whole process (``ru_maxrss``, which the
  per-stage reset also resets: the maximum of it and the stage peaks);
  ``peak_rss_mb_by_stage``: the peak within each stage (``warm-up``, ``simulate``,
  ``graph-batch``, ``graph-batch-general``, ``builtin-floor``, ``graph-isam2``, ``ekf``), the
  kernel's high-water mark reset at the start of each stage (Linux ``/proc/self/clear_refs``;
  elsewhere the running maximum; the C heap is trimmed first, ``linalg.trim_heap``). A
  stage's peak includes what earlier stages left alive (the drive, the interpreter and the
  loaded numba kernels: ≈ 260 MB before the drive); each stage's estimate is released once
  its numbers are read (graph-batch's and the general path's hold ≈ 12 MB each).
- ``isam2_stage_growth_mb``: the graph-isam2 stage's peak minus the resident memory at its
  start, i.e. what graph-isam2 itself adds (the drive and the interpreter excluded); the
  number to compare between drive lengths when asking whether its memory is flat.
"""

from __future__ import annotations

import argparse
import gc
import importlib.util
import json
import resource
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

KEYS = ("drive_duration_s", "keyframes", "batch_s", "builtin_floor_s", "batch_over_floor",
        "isam2_s", "isam2_realtime_factor", "isam2_update_p99_ms", "ekf_s",
        "ekf_realtime_factor", "peak_rss_mb", "general_over_floor")


class StagePeaks:
    """Peak resident memory [MB] of each stage of the benchmark (``peak_rss_mb_by_stage``)."""

    def __init__(self) -> None:
        self.peaks: dict[str, float] = {}
        self.growth: dict[str, float] = {}  # stage peak − resident memory at the stage's start
        self._base = 0.0
        self._reset = Path("/proc/self/clear_refs")

    @staticmethod
    def status_mb(field: str) -> float | None:
        try:
            for line in Path("/proc/self/status").read_text().splitlines():
                if line.startswith(field):
                    return float(line.split()[1]) / 1024.0
        except OSError:
            pass
        return None

    @classmethod
    def _hwm_mb(cls) -> float | None:
        return cls.status_mb("VmHWM:")

    def start(self) -> None:
        from vnav_graph.estimators.graph.solver.linalg import trim_heap

        gc.collect()
        trim_heap()  # what earlier stages freed goes back to the OS, not into this stage's peak
        try:  # "5": reset the peak RSS (VmHWM) to the current RSS (Linux ≥ 4.0)
            self._reset.write_text("5")
        except OSError:
            pass
        self._base = self.status_mb("VmRSS:") or 0.0

    def end(self, stage: str) -> None:
        hwm = self._hwm_mb()
        self.peaks[stage] = (hwm if hwm is not None else
                             resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0)
        self.growth[stage] = self.peaks[stage] - self._base


def builtin_floor(drive: Any) -> float:
    """Build and solve the C++-only graph; returns the wall time [s]."""
    import gtsam
    from gtsam.symbol_shorthand import B, C, V, X

    from vnav_graph.estimators.graph.model import cpp_factors as builders
    from vnav_graph.estimators.graph.model import initial_guess as init
    from vnav_graph.estimators.graph.model import problem as problem
    from vnav_graph.geo.atmosphere import isa_pressure

    cfg = problem.GraphConfig()
    P = problem.setup(drive, cfg)
    pri = P.pri
    rot, pos, vel = init.initial_states(P)
    pims = builders.pims_for(P, rot, pos)
    bt = drive.baro.t
    alt = drive.baro.altitude
    j = np.clip(np.searchsorted(bt, P.t_kf), 0, bt.size - 1)
    t0 = time.perf_counter()
    graph = gtsam.NonlinearFactorGraph()
    s = P.imu_spec
    graph.add(gtsam.PriorFactorPose3(X(0), gtsam.Pose3(gtsam.Rot3(rot[0]), pos[0]),
                                     problem.noise([0.05, 0.05, 0.5, 10.0, 10.0, 10.0])))
    graph.add(gtsam.PriorFactorVector(V(0), vel[0], problem.noise([2.0] * 3)))
    graph.add(gtsam.PriorFactorConstantBias(
        B(0), gtsam.imuBias.ConstantBias(),
        problem.noise([max(s.accel_bias_sd, 1e-4)] * 3 + [max(s.gyro_bias_sd, 1e-6)] * 3)))
    graph.add(gtsam.PriorFactorDouble(C(0), 0.0, problem.noise([pri["b_sd"]])))
    vals = gtsam.Values()
    baro_noise = problem.noise([pri["noise"]])
    # NED graph, +z-up factor: feed the pressure of the mirrored height −(h − h0)
    p_kpa = isa_pressure(-(alt[j] - P.h0)) / 1000.0
    for k in range(P.n_kf):
        vals.insert(X(k), gtsam.Pose3(gtsam.Rot3(rot[k]), pos[k]))
        vals.insert(V(k), vel[k])
        vals.insert(B(k), gtsam.imuBias.ConstantBias())
        vals.insert(C(k), 0.0)
        for _, f in builders.keyframe_fixes(P, k):
            graph.add(f)
        graph.add(gtsam.BarometricFactor(X(k), C(k), float(p_kpa[k]), baro_noise))
        if k + 1 < P.n_kf:
            dt = float(P.t_kf[k + 1] - P.t_kf[k])
            # the graph's IMU factor and its bias-step variance (no decay, no scale factors)
            graph.add(gtsam.ImuFactor(X(k), V(k), X(k + 1), V(k + 1), B(k), pims[k]))
            graph.add(gtsam.BetweenFactorConstantBias(
                B(k), B(k + 1), gtsam.imuBias.ConstantBias(),
                problem.noise(np.sqrt(builders.bias_step(P.imu_spec, dt)[1]))))
            graph.add(gtsam.BetweenFactorDouble(
                C(k), C(k + 1), 0.0, problem.noise([pri["b_sd"] * np.sqrt(2 * dt / pri["b_tau"])])))
    params = gtsam.LevenbergMarquardtParams()
    params.setRelativeErrorTol(1e-9)
    params.setMaxIterations(50)
    gtsam.LevenbergMarquardtOptimizer(graph, vals, params).optimize()
    return time.perf_counter() - t0


def ekf_timing(duration_s: float, imu_rate_hz: float, drive: Any = None, seed: int = 0
               ) -> tuple[float | None, float | None]:
    path = Path(__file__).resolve().parent / "bench_ekf.py"
    if not path.exists():
        print("bench_ekf.py not found: ekf_s / ekf_realtime_factor are null", file=sys.stderr)
        return None, None
    spec = importlib.util.spec_from_file_location("bench_ekf", path)
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    try:  # on the graph stages' drive (a second simulation was the process's memory peak);
        # ekf-rts is not reported here: not run
        res = mod.bench_ekf(duration_s, imu_rate_hz, seed, with_rts=False, drive=drive)
    except TypeError:  # an older bench_ekf without these options
        res = mod.bench_ekf(duration_s, imu_rate_hz)
    ekf_s = float(res["ekf_s"]) if isinstance(res, dict) else float(res)
    return ekf_s, duration_s / ekf_s if ekf_s > 0 else None


def main(argv: list[str] | None = None) -> dict[str, Any]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="10-minute drive instead of 1 hour")
    ap.add_argument("--hours", type=float, default=None,
                    help="drive length in hours (default 1; --quick: 10 minutes)")
    ap.add_argument("--out", required=True, type=Path)
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args(argv)
    from vnav_graph.estimators.graph import GraphBatch, GraphConfig, GraphISAM2
    from vnav_graph.simulation.scenario import simulate

    if a.hours is not None and not a.hours > 0:
        ap.error("--hours must be positive")
    duration = 3600.0 * a.hours if a.hours is not None else (600.0 if a.quick else 3600.0)
    stages = StagePeaks()
    # warm-up on a 60 s drive: numba's cached kernels are loaded on first call (~0.5 s),
    # a one-off cost that the C++-only floor does not have
    stages.start()
    warm = simulate("hill-drive", a.seed, duration_s=60.0, imu_rate_hz=200.0)
    GraphBatch().run(warm)
    GraphBatch(GraphConfig(solver="general")).run(warm)
    GraphISAM2().run(warm)
    del warm
    stages.end("warm-up")
    stages.start()
    # the estimators never read the truth: the bench keeps the drive without it (103 of the
    # 142 MB of a 1-hour 200 Hz drive; the arrays of the other streams are shared, not copied)
    drive = simulate("hill-drive", a.seed, duration_s=duration,
                     imu_rate_hz=200.0).replace(truth=None, baro_truth=None)
    stages.end("simulate")
    # each stage's estimate is released once its numbers are read: a stage's peak is the
    # drive and the interpreter plus its own estimator, not the earlier stages' outputs
    # (~12 MB per 1-hour estimate, most of it the 20 Hz trajectory)
    stages.start()
    eb = GraphBatch().run(drive)
    stages.end("graph-batch")
    batch_s = float(eb.info["timing_s"]["solve"])
    keyframes = int(eb.info["keyframes"])
    note = (f"graph-batch full run {eb.runtime_s:.1f} s (timing {eb.info['timing_s']}), "
            f"GN iterations {eb.info['iterations']}; ")
    del eb
    stages.start()
    eg = GraphBatch(GraphConfig(solver="general")).run(drive)
    stages.end("graph-batch-general")
    general_s = float(eg.info["timing_s"]["solve"])
    note += (f"general path: solve {general_s:.2f} s, full run {eg.runtime_s:.1f} s, "
             f"{eg.info['iterations']} iterations; ")
    del eg
    stages.start()
    floor_s = builtin_floor(drive)
    stages.end("builtin-floor")
    stages.start()
    ei = GraphISAM2().run(drive)
    stages.end("graph-isam2")
    drive_s = float(drive.duration_s)
    note += (f"isam2 online {ei.info['online_s']:.1f} s, "
             f"final smoothing {ei.info['final_smoothing_s']:.1f} s, "
             f"p50 {ei.info['update_p50_ms']:.1f} ms, "
             f"window {ei.info['isam2_window_s']} s "
             f"({ei.info.get('isam2_marginalised_keyframes', 0)} keyframes left iSAM2)")
    isam2_s = float(ei.runtime_s)
    isam2_p99 = float(ei.info["update_p99_ms"])
    isam2_relin = int(ei.info["isam2_relinearized"])
    isam2_extra = {"isam2_lag_s": float(ei.info["lag_s"]),
                   "isam2_online_s": float(ei.info["online_s"]),
                   "isam2_marginals_s": float(ei.info["isam2_marginals_s"]),
                   "isam2_final": ei.info["isam2_final"]}
    del ei
    stages.start()
    ekf_s, ekf_rf = ekf_timing(duration, 200.0, drive, a.seed)
    del drive
    stages.end("ekf")
    out = {
        "drive_duration_s": drive_s,
        "keyframes": keyframes,
        "batch_s": batch_s,
        "builtin_floor_s": float(floor_s),
        "batch_over_floor": batch_s / floor_s,
        "isam2_s": isam2_s,
        "isam2_realtime_factor": drive_s / isam2_s,
        "isam2_update_p99_ms": isam2_p99,
        "ekf_s": ekf_s,
        "ekf_realtime_factor": ekf_rf,
        # resetting the high-water mark also resets ru_maxrss: the maximum of the stages'
        "peak_rss_mb": max(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
                           *stages.peaks.values()),
        "general_over_floor": general_s / floor_s,
    }
    assert tuple(out) == KEYS
    out["peak_rss_mb_by_stage"] = stages.peaks  # additive (docs/design.md)
    out["isam2_relinearized"] = isam2_relin  # additive
    # additive: the lag L of Estimate.lag, the graph-isam2 stage's own peak, the online
    # pass, the part of it spent on the online/lag marginal covariances, whose answer
    out.update(isam2_extra, isam2_peak_rss_mb=stages.peaks["graph-isam2"])
    # additive: what the graph-isam2 stage added to the process (the drive, interpreter and
    # GTSAM excluded): its online pass's own memory, which the window keeps flat in drive length
    out["isam2_stage_growth_mb"] = stages.growth["graph-isam2"]
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / "graph_perf.json").write_text(json.dumps(out, indent=2) + "\n")
    print(json.dumps(out, indent=2))
    print(note, file=sys.stderr)
    return out


if __name__ == "__main__":
    main()
