"""A zero-velocity factor at standstills detected from the IMU, added to the graph smoothers.

Detection (IMU only): a sample is *quiet* when, over a centred ``WINDOW_S`` window, the
standard deviation of every accelerometer and gyro axis is below ``QUIET_RATIO`` times the
white-noise σ per sample that the IMU's noise spec implies (σ = density·√rate). A keyframe
whose ±``WINDOW_S`` neighbourhood is entirely quiet is a standstill, and gets the C++
built-in factor ``PriorFactorVector(V(k), 0, σ_zupt I)`` (``ZUPT_SD``): the velocity in the
Earth-fixed tangent frame is zero. A prior on V(k) touches one keyframe only, so graph-batch
keeps its banded fast path.

A real car's IMU shakes while the wheels turn; the simulator's IMU does not (at constant
speed its readings are as quiet as at rest, and a variance detector would fire while
cruising). This example therefore adds white road vibration (``VIB_ACCEL_SD``,
``VIB_GYRO_SD`` per sample) to the simulated IMU whenever the true speed exceeds 5 cm/s
(``add_road_vibration``, which reads the truth: a stand-in for physics the simulator lacks).
Both estimates compared below run on the same vibrating drive.

How it changes the estimate: at a standstill the velocity is otherwise known from the GNSS
velocity (σ 0.1 m/s per fix at 10 Hz) and the IMU; the zero-velocity factor pins it to
σ_zupt. ``main`` returns the RMS velocity error (3-D, over the true standstills) with and
without the factor, and how many detected standstill keyframes were in fact moving (true
speed > 5 cm/s). Measured (hill-drive, 120 s, graph-batch), standstill velocity RMS error
without → with: seed 0 19.4 → 5.3 mm/s, seed 1 17.6 → 5.0 mm/s, seed 2 22.7 → 6.7 mm/s, no
false detection; the whole-drive velocity error does not grow (26.1 → 24.8, 27.6 → 26.7,
24.6 → 18.5 mm/s). The altitude is not its target: whole-drive altitude RMSE on the 180 s
bench drive 0.085 → 0.130 m (seed 0), 0.267 → 0.268 m (seed 1), 0.112 → 0.116 m (seed 2)
— the vibration makes the IMU noisier than the noise model the graph trusts, and pinning the
velocity at the stops moves that mismatch elsewhere (not investigated further). Without the
vibration the detector fires while cruising and the altitude RMSE grows to 6–10 m
(``test_zupt_detector_needs_vibration`` checks the false detections). The test asserts, on
seeds 0 and 1, that the standstill velocity error at least halves, that no detected
standstill keyframe was moving, and that the whole-drive velocity error does not grow by more
than 5 %.

Run once through the bench (two plugin estimators on the same vibrating drives: road
vibration only, and road vibration + zero-velocity factor)::

    vnav-graph bench --quick --scenarios hill-drive --seeds 1 \\
        --plugin examples/ex_graph_factor_zupt.py:GraphBatchRoad \\
        --plugin examples/ex_graph_factor_zupt.py:GraphBatchZupt \\
        --estimators graph-batch-road,graph-batch-zupt --out zupt-bench
"""

from __future__ import annotations

from typing import Any

import gtsam
import numpy as np

from vnav_graph.estimators.graph import GraphBatch, GraphConfig
from vnav_graph.estimators.graph.model.extend import GraphView, Terms, V
from vnav_graph.evaluation.montecarlo import shorten_scenario
from vnav_graph.simulation import simulate
from vnav_graph.types import Drive
from vnav_graph.types.streams import FloatArray, ImuStream

REQUIRES = ("graph-batch",)
WINDOW_S = 0.5  # detection window [s]
QUIET_RATIO = 1.6  # quiet: window σ < this × the spec's white-noise σ per sample
ZUPT_SD = 0.01  # σ of the zero-velocity factor per axis [m/s]
VIB_ACCEL_SD = 0.1  # simulated road vibration, per sample [m/s²]
VIB_GYRO_SD = 0.003  # [rad/s]
MOVING_SPEED = 0.05  # [m/s] above which the simulated wheels turn


def add_road_vibration(drive: Drive, seed: int = 0) -> Drive:
    """The drive with white vibration added to the IMU while the true speed exceeds
    ``MOVING_SPEED`` (reads the truth: simulation only)."""
    imu, tr = drive.imu, drive.truth
    assert tr is not None
    moving = np.linalg.norm(tr.at(imu.t).vel_n, axis=1) > MOVING_SPEED
    rng = np.random.default_rng([seed, 13])
    n = (imu.t.size, 3)
    acc = imu.accel_b + moving[:, None] * rng.normal(scale=VIB_ACCEL_SD, size=n)
    gyr = imu.gyro_b + moving[:, None] * rng.normal(scale=VIB_GYRO_SD, size=n)
    return drive.replace(imu=ImuStream(imu.t, gyr, acc, imu.spec))


def window_sd(x: FloatArray, n: int) -> FloatArray:
    """Standard deviation of each column over centred windows of n samples (N, 3); the ends
    take the nearest full window."""
    c1 = np.cumsum(np.vstack([np.zeros((1, x.shape[1])), x]), axis=0)
    c2 = np.cumsum(np.vstack([np.zeros((1, x.shape[1])), x**2]), axis=0)
    m = (c1[n:] - c1[:-n]) / n
    sd = np.sqrt(np.clip((c2[n:] - c2[:-n]) / n - m**2, 0.0, None))
    pad0 = n // 2
    return np.vstack([np.repeat(sd[:1], pad0, axis=0), sd,
                      np.repeat(sd[-1:], x.shape[0] - sd.shape[0] - pad0, axis=0)])


def detect_standstill(imu: ImuStream) -> np.ndarray:
    """Boolean (N,): IMU sample ``i`` lies in a quiet window (see the module docstring)."""
    dt = float(np.median(np.diff(imu.t)))
    n = max(int(round(WINDOW_S / dt)), 5)
    spec = imu.spec
    sa = spec.accel_noise_density / np.sqrt(dt)  # white-noise σ per sample
    sg = spec.gyro_noise_density / np.sqrt(dt)
    return (np.all(window_sd(imu.accel_b, n) < QUIET_RATIO * sa, axis=1)
            & np.all(window_sd(imu.gyro_b, n) < QUIET_RATIO * sg, axis=1))


class ZeroVelocity:
    """The extension: a zero-velocity prior on V(k) at every standstill keyframe."""

    name = "zero-velocity"

    def __init__(self) -> None:
        self.keyframes: list[int] = []  # the last run's standstill keyframes
        self.times = np.zeros(0)  # and their times [s]

    def __call__(self, view: GraphView) -> Terms:
        imu = view.drive.imu
        quiet = detect_standstill(imu)
        # a keyframe is a standstill when its whole ±WINDOW_S neighbourhood is quiet
        c = np.r_[0, np.cumsum(~quiet)]
        lo = np.searchsorted(imu.t, view.t_kf - WINDOW_S)
        hi = np.searchsorted(imu.t, view.t_kf + WINDOW_S, side="right")
        self.keyframes = np.flatnonzero(c[hi] - c[lo] == 0).tolist()
        self.times = view.t_kf[self.keyframes]
        noise = gtsam.noiseModel.Isotropic.Sigma(3, ZUPT_SD)
        return Terms([gtsam.PriorFactorVector(V(k), np.zeros(3), noise)
                      for k in self.keyframes])


class GraphBatchRoad(GraphBatch):
    """``graph-batch-road``: graph-batch on the drive with simulated road vibration."""

    name = "graph-batch-road"

    def run(self, drive: Drive) -> Any:
        return super().run(add_road_vibration(drive, int(drive.meta.get("seed", 0))))


class GraphBatchZupt(GraphBatchRoad):
    """``graph-batch-zupt``: the same plus the zero-velocity factor (for ``--plugin``)."""

    name = "graph-batch-zupt"

    def __init__(self, config: GraphConfig | None = None) -> None:
        super().__init__(config, extensions=[ZeroVelocity()])


def main(duration_s: float = 120.0, seed: int = 0) -> dict[str, Any]:
    """Returns ``{"vel_rms_mps": {"standstill"|"all": {"without": x, "with": y}},
    "zupt_keyframes": n, "false_detections": n, "drive": vibrating Drive}``."""
    drive = add_road_vibration(simulate(shorten_scenario("hill-drive", duration_s), seed), seed)
    zv = ZeroVelocity()
    # the built-in zero-velocity updates off in both: the comparison is the extension's own
    cfg = GraphConfig(zupt=False)
    base = GraphBatch(cfg).run(drive)
    ext = GraphBatch(cfg, extensions=[zv]).run(drive)
    t = base.trajectory.t
    truth = drive.truth.at(t)
    still = np.linalg.norm(truth.vel_n, axis=1) < 1e-3

    def rms(est: Any, m: np.ndarray) -> float:
        return float(np.sqrt(np.mean(np.sum((est.trajectory.vel_n[m] - truth.vel_n[m]) ** 2,
                                            axis=1))))

    speed_kf = np.linalg.norm(drive.truth.at(zv.times).vel_n, axis=1)
    every = np.ones(t.size, bool)
    out = {"vel_rms_mps": {"standstill": {"without": rms(base, still), "with": rms(ext, still)},
                           "all": {"without": rms(base, every), "with": rms(ext, every)}},
           "zupt_keyframes": len(zv.keyframes),
           "false_detections": int(np.sum(speed_kf > MOVING_SPEED)),
           "standstill_fraction": float(still.mean()), "drive": drive}
    v = out["vel_rms_mps"]
    print(f"{out['zupt_keyframes']} standstill keyframes detected from the IMU "
          f"({out['false_detections']} while moving); true standstill "
          f"{out['standstill_fraction']:.0%} of the drive")
    print(f"velocity RMS error at standstills: without {1e3 * v['standstill']['without']:.1f} "
          f"mm/s, with zero-velocity factor {1e3 * v['standstill']['with']:.1f} mm/s")
    print(f"velocity RMS error, whole drive: without {1e3 * v['all']['without']:.1f} mm/s, "
          f"with {1e3 * v['all']['with']:.1f} mm/s")
    return out


if __name__ == "__main__":
    main()
