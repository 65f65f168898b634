"""Simulate a test drive and look at what the sensors saw.

``vnav_graph.simulation.simulate(scenario, seed, **overrides)`` gives a deterministic
``Drive``: IMU, GNSS and barometer streams on one clock plus the truth (trajectory, IMU
biases, the baro Gauss-Markov bias b(t)) and the baro's true scale s and latency τd, so that
the baro model h_b − h0 = (1 + s)(h(t − τd) − h0) + b(t) + v can be checked sample by sample.

Run: ``python examples/ex_simulate_drive.py`` (plots truth, GNSS and baro altitude).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vnav_graph.simulation import simulate
from vnav_graph.types import Drive


@dataclass(frozen=True)
class SimulatedDrive:
    """The drive and the baro model residual h_b − [h0 + (1+s)(h(t−τd) − h0) + b(t)] [m]
    at the baro epochs (white noise v only, if the model is right)."""

    drive: Drive
    baro_residual_m: np.ndarray


def main(duration_s: float = 120.0, scenario: str = "hill-drive", seed: int = 0
         ) -> SimulatedDrive:
    drive = simulate(scenario, seed, duration_s=duration_s)
    tr, bt, baro = drive.truth, drive.baro_truth, drive.baro
    h0 = float(drive.origin_lla[2])
    tb = baro.t
    ok = tb - bt.latency_s >= tr.t[0]
    h_lag = np.interp(tb[ok] - bt.latency_s, tr.t, tr.alt)
    model = h0 + (1 + bt.scale) * (h_lag - h0) + np.interp(tb[ok], tr.t, tr.bias_baro)
    return SimulatedDrive(drive, baro.altitude[ok] - model)


if __name__ == "__main__":
    import matplotlib.pyplot as plt

    res = main(duration_s=600.0)
    d = res.drive
    print(f"{d.name}: {d.duration_s:.0f} s, IMU {d.imu.rate_hz:.0f} Hz, {len(d.gnss)} GNSS fixes, "
          f"{len(d.baro)} baro samples; baro scale {d.baro_truth.scale * 100:.2f} %, latency "
          f"{d.baro_truth.latency_s * 1000:.0f} ms; model residual sd "
          f"{np.std(res.baro_residual_m):.3f} m; GNSS outages {d.meta['gnss_outages']}")
    fig, ax = plt.subplots(figsize=(10, 4))
    ax.plot(d.truth.t, d.truth.alt, "k", label="truth")
    ax.plot(d.gnss.t, d.gnss.lla[:, 2], ".", ms=2, label="GNSS")
    ax.plot(d.baro.t, d.baro.altitude, lw=0.7, label="baro")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("height [m]")
    ax.legend()
    plt.show()
