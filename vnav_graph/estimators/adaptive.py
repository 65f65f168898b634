"""Seed 000 (Sokolović, Dikić, Stančić 2014): 3rd-order baro-inertial loop with adaptive
gain/damping coefficients (``loop3-adaptive``).

The seed text stops before its equations; the law below is designed from its abstract and
the loop literature and written out in ``docs/adaptive_loop.md``. The fixed loop (``loops``)
places a triple pole at −1/τ: k1 = 3/τ, k2 = 3/τ² + ω_s², k3 = 1/τ³. The adaptive loop keeps
that structure (so the frozen-gain loop is stable for every value) and shortens the time
constant when the loop is far from equilibrium:

    τ_eff(t) = τ / s(t),   s = 1 + (s_max − 1)·φ(x),   φ: [0, ∞) → [0, 1), φ(0) = 0,
    k1 = 3s/τ,  k2 = 3s²/τ² + ω_s²,  k3 = s³/τ³,

with x = ē/e0 (``signal="error"``: ē the low-passed loop error magnitude, time constant
T_a, ē̇ = (|e| − ē)/T_a) or x = |v̂|/v0 (``signal="vz"``: the estimated vertical speed —
vertical dynamics, where baro lag and INS errors grow). Adaptation functions φ:

- ``"linear"``: min(x, 1) (linear-saturated)
- ``"exp"``: 1 − exp(−x)
- ``"tanh"``: tanh(x)
- ``"sigmoid"``: (σ(a(x − 1)) − σ(−a)) / (1 − σ(−a)), σ the logistic, a = 4 (soft threshold
  at x = 1)
- ``"none"``: 0 (the loop is then exactly ``loop3``; tested)

The seed also feeds the loop's corrections into an EKF as control signals (GNSS altitude
as the measurement); that variant is not implemented (docs/adaptive_loop.md). Measured
benefit (benchmarks/bench_adaptive.py): 1.7-3× faster settling after a baro step; no gain
in fast climbs/descents or with baro latency.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from ..types import Drive, Estimate
from .loops import LoopInputs, _estimate, discrete_model, loop_inputs
from .vertical_input import AhrsConfig

_FUNCS = {"none": 0, "linear": 1, "exp": 2, "tanh": 3, "sigmoid": 4}
_SIGNALS = {"error": 0, "vz": 1}


@dataclass(frozen=True)
class AdaptiveConfig:
    """tau [s] nominal triple-pole time constant; s_max [-] largest speed-up; function (see
    module docstring); signal "error" | "vz"; e0 [m], v0 [m/s] normalisations; t_avg [s]
    time constant T_a of the error-magnitude low-pass."""

    tau: float = 20.0
    s_max: float = 4.0
    function: str = "tanh"
    signal: str = "error"
    e0: float = 3.0
    v0: float = 5.0
    t_avg: float = 2.0
    ahrs: AhrsConfig = field(default_factory=AhrsConfig)

    def __post_init__(self) -> None:
        if self.function not in _FUNCS:
            raise ValueError(f"AdaptiveConfig.function: one of {sorted(_FUNCS)}")
        if self.signal not in _SIGNALS:
            raise ValueError(f"AdaptiveConfig.signal: one of {sorted(_SIGNALS)}")
        if not (self.tau > 0 and self.s_max >= 1 and self.e0 > 0 and self.v0 > 0
                and self.t_avg > 0):
            raise ValueError("AdaptiveConfig: tau, e0, v0, t_avg > 0 and s_max >= 1 required")


@njit(cache=True)
def _phi(x, func):
    if func == 0:
        return 0.0
    if func == 1:
        return x if x < 1.0 else 1.0
    if func == 2:
        return 1.0 - np.exp(-x)
    if func == 3:
        return np.tanh(x)
    a = 4.0
    s0 = 1.0 / (1.0 + np.exp(a))
    return (1.0 / (1.0 + np.exp(-a * (x - 1.0))) - s0) / (1.0 - s0)


@njit(cache=True)
def adaptive_kernel(a_up, z_baro, phi, gam, dt, tau, ws2, s_max, func, signal, e0, v0,
                    t_avg, x0):
    """Loop-3 recursion of ``loops.loop_kernel`` with per-step gains
    dt·[3s/τ, 3s²/τ² + ω_s², −s³/τ³]. Returns states (N, 3), loop error (N,), s (N,)."""
    n = a_up.size
    x = np.empty((n, 3))
    err = np.empty(n)
    s_out = np.empty(n)
    x[0] = x0
    ebar = 0.0
    alpha = dt / t_avg if dt < t_avg else 1.0
    gain_dt = np.empty(3)
    scale = 1.0  # kept for the same expression order as loop_kernel
    for k in range(n):
        e = x[k, 0] - z_baro[k]
        err[k] = e
        ebar += alpha * (abs(e) - ebar)
        if signal == 0:
            xi = ebar / e0
        else:
            xi = abs(x[k, 1]) / v0
        s = 1.0 + (s_max - 1.0) * _phi(xi, func)
        s_out[k] = s
        if k == n - 1:
            break
        gain_dt[0] = 3.0 * s / tau * dt
        gain_dt[1] = (3.0 * s**2 / tau**2 + ws2) * dt
        gain_dt[2] = -(s**3 / tau**3) * dt
        for i in range(3):
            acc = gam[i] * a_up[k] - scale * gain_dt[i] * e
            for j in range(3):
                acc += phi[i, j] * x[k, j]
            x[k + 1, i] = acc
    return x, err, s_out


def run_adaptive(inp: LoopInputs, cfg: AdaptiveConfig, x0=None):
    """Run the adaptive loop on prepared inputs; returns (states (N, 3), error (N,), s (N,))."""
    dt = float(np.median(np.diff(inp.t)))
    phi, gam = discrete_model(dt, inp.ws2, 3)
    if x0 is None:
        x0 = np.array([inp.z_baro[0], 0.0, 0.0])
    return adaptive_kernel(inp.a_up, inp.z_baro, phi, gam, dt, cfg.tau, inp.ws2, cfg.s_max,
                           _FUNCS[cfg.function], _SIGNALS[cfg.signal], cfg.e0, cfg.v0,
                           cfg.t_avg, np.asarray(x0, float))


class AdaptiveLoop3:
    """3rd-order baro-inertial loop with adaptive coefficients (``loop3-adaptive``)."""

    name = "loop3-adaptive"

    def __init__(self, config: AdaptiveConfig | None = None) -> None:
        self.config = config or AdaptiveConfig()

    def run(self, drive: Drive) -> Estimate:
        t0 = time.perf_counter()
        inp = loop_inputs(drive, self.config.ahrs)
        x, err, s = run_adaptive(inp, self.config)
        return _estimate(self.name, inp.t, x[:, 0] + inp.h0, x[:, 1],
                         time.perf_counter() - t0, self.config,
                         {"uses": "imu+baro", "speedup_mean": float(np.mean(s)),
                          "speedup_max": float(np.max(s)),
                          "accel_bias_up_final": float(x[-1, 2])})
