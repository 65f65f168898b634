"""Research extension: add your own estimator and run it through the Monte Carlo bench.

The estimator added here is the simplest altitude source there is — the **barometer alone**,
with its offset set once against GNSS at the start of the drive (what a pilot does when
setting the QNH before take-off):

    b̂ = mean_k (h_b(t_k) − h_GNSS(t_k)) over the GNSS fixes of the first ``calib_s`` seconds,
    ĥ(t) = h_b(t) − b̂,    v̂_D(t) = −dĥ/dt (central difference over ``smooth_s`` seconds).

It ignores the scale error s and the latency τd of the baro model
(h_b − h0 = (1+s)(h(t−τd) − h0) + b(t) + v, ``vnav_graph.sensors.baro``), so its altitude
error grows with s·(h − h0) and with the drift of b(t): a useful floor that every inertial
estimator should beat. A second addition, ``loop3-tau60``, is a variant of a built-in
estimator (the 3rd-order loop with another time constant). Both are registered under new
names with
``vnav_graph.estimators.base.register`` and then benchmarked beside any built-in estimator
that this build provides (``loop3``, ``ekf``, ``graph-batch`` …), with
``vnav_graph.run.bench.bench`` — the function behind ``vnav-graph bench``.

Run: ``python examples/ex_custom_estimator.py`` (prints the bench table).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from vnav_graph.estimators.base import available, register
from vnav_graph.evaluation.montecarlo import format_bench_md
from vnav_graph.run.bench import bench
from vnav_graph.types import BaroEstimate, Drive, Estimate, ParamEstimate, Trajectory


@dataclass(frozen=True)
class BaroOnlyConfig:
    """calib_s: GNSS span used to set the baro offset [s]; smooth_s: differentiation
    window for the vertical velocity [s]."""

    calib_s: float = 30.0
    smooth_s: float = 2.0


class BaroOnly:
    """Barometric altitude with a one-time GNSS offset (no inertial data)."""

    name = "baro-only"

    def __init__(self, config: BaroOnlyConfig | None = None) -> None:
        self.config = config or BaroOnlyConfig()

    def run(self, drive: Drive) -> Estimate:
        t0 = time.perf_counter()
        if drive.baro is None or drive.gnss is None:
            raise ValueError("baro-only needs baro and GNSS data")
        cfg = self.config
        tb, hb = drive.baro.t, drive.baro.altitude
        g = drive.gnss
        first = g.t <= g.t[0] + cfg.calib_s
        first &= (g.t >= tb[0]) & (g.t <= tb[-1])
        if first.sum() < 2:
            raise ValueError("baro-only: fewer than 2 GNSS fixes in the calibration span")
        d = np.interp(g.t[first], tb, hb) - g.lla[first, 2]
        bias = float(np.mean(d))
        bias_sd = float(np.std(d, ddof=1) / np.sqrt(d.size))
        alt = hb - bias
        # central difference over ±smooth_s/2 (clipped at the ends)
        half = max(1, int(round(0.5 * cfg.smooth_s * drive.baro.t.size / (tb[-1] - tb[0]))))
        i = np.arange(tb.size)
        lo, hi = np.clip(i - half, 0, tb.size - 1), np.clip(i + half, 0, tb.size - 1)
        v_up = (alt[hi] - alt[lo]) / (tb[hi] - tb[lo])
        n = tb.size
        lla = np.column_stack([np.full(n, np.nan), np.full(n, np.nan), alt])
        vel = np.column_stack([np.full(n, np.nan), np.full(n, np.nan), -v_up])
        return Estimate(
            estimator=self.name,
            trajectory=Trajectory(tb, lla, vel),
            provides=frozenset({"alt", "vel_d", "baro"}),
            baro=BaroEstimate(bias_m=ParamEstimate(bias, bias_sd)),
            runtime_s=time.perf_counter() - t0,
            config=cfg,
        )


def loop3_tau60(config: Any = None) -> Any:
    """A variant of a built-in: the 3rd-order loop with a 60 s triple pole instead of 20 s
    (slower: trusts the inertial channel longer, filters more baro noise)."""
    from vnav_graph.estimators.vertical.loops import Loop3, Loop3Config

    return Loop3(config or Loop3Config(tau=60.0))


def main(duration_s: float = 120.0, seeds: int = 2, workers: int = 1) -> dict[str, Any]:
    """Register ``baro-only`` (and ``loop3-tau60`` when the loops are in this build) and bench
    them against the built-in ``loop3`` and ``ekf`` (those present) on the hill-drive;
    returns the ``bench.json`` document."""
    register(BaroOnly.name, BaroOnly)
    names = [BaroOnly.name]
    if "loop3" in available():
        register("loop3-tau60", loop3_tau60)
        names.append("loop3-tau60")
    names += [n for n in ("loop3", "ekf") if n in available()]
    return bench(["hill-drive"], names, list(range(seeds)), duration_s=duration_s,
                 workers=workers)


if __name__ == "__main__":
    print(format_bench_md(main(duration_s=300.0, seeds=3, workers=2)))
