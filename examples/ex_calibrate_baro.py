"""Calibrate a barometer against GNSS: seed 001's least squares, and its 7-state filter.

Seed 001 (eq. 4) regresses dH = H_B − H_G on [H_G, −V_G, 1] to get the scale error dSF, the
latency Td and the bias B (``calibrate_baro``). On a simulated sortie
(climbs and descents give the regression its leverage) the estimates are compared with the
simulator's truth; if the ``vekf7`` estimator is in this build, its online estimates of the
same three parameters are shown beside them.

Run: ``python examples/ex_calibrate_baro.py``.
"""

from __future__ import annotations

from typing import Any

from vnav_graph.estimators.base import available, create
from vnav_graph.estimators.vertical.calibration import calibrate_baro, format_calibration
from vnav_graph.evaluation.blocks import baro_block
from vnav_graph.evaluation.montecarlo import shorten_scenario
from vnav_graph.simulation import simulate

REQUIRES: tuple[str, ...] = ()  # vekf7 is optional


def main(duration_s: float = 300.0, seed: int = 1) -> dict[str, Any]:
    """Returns ``{"calibration": BaroCalibration, "truth": {...}, "vekf7": baro block|None}``.

    ``truth`` holds the simulated scale [-], latency [s] and bias b(t) averaged over the
    GNSS epochs used by the regression [m]."""
    drive = simulate(shorten_scenario("sortie", duration_s), seed)
    cal = calibrate_baro(drive)
    tr = drive.truth
    import numpy as np

    bias_mean = float(np.mean(np.interp(drive.gnss.t, tr.t, tr.bias_baro)))
    out: dict[str, Any] = {
        "calibration": cal, "drive": drive,
        "truth": {"scale": drive.baro_truth.scale, "latency_s": drive.baro_truth.latency_s,
                  "bias_m": bias_mean},
        "vekf7": None,
    }
    if "vekf7" in available():
        out["vekf7"] = baro_block(create("vekf7").run(drive).baro, drive)
    return out


if __name__ == "__main__":
    res = main(duration_s=1200.0)
    t = res["truth"]
    print(format_calibration(res["calibration"]))
    print(f"truth: dSF {t['scale'] * 100:.4f} %, Td {t['latency_s']:.4f} s, "
          f"B {t['bias_m']:.3f} m")
    if res["vekf7"] is not None:
        b = res["vekf7"]
        print("vekf7: " + ", ".join(f"{k} {v['est']:.4g} ± {v['sd'] or 0:.2g}"
                                    for k, v in b.items() if v["est"] is not None))
