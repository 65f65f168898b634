"""The one place where continuous noise specs become discrete variances (the random sequences
the simulator draws from them are ``simulation.noise``)."""

from __future__ import annotations

import numpy as np

from ..types.streams import FloatArray


def white_sd(density: float, dt: float) -> float:
    """Per-sample sigma of band-limited white noise with root PSD ``density`` sampled every
    ``dt`` seconds: σ = density / √dt."""
    return float(density / np.sqrt(dt))


def gm_transition(dt: float | FloatArray, tau: float) -> FloatArray:
    """Exact discrete first-order Gauss-Markov transition φ = exp(-dt/τ) (1 for τ = inf)."""
    dt = np.asarray(dt, dtype=float)
    return np.exp(-dt / tau) if np.isfinite(tau) else np.ones_like(dt)


def gm_process_var(dt: float | FloatArray, tau: float, sd: float) -> FloatArray:
    """Exact discrete driving-noise variance σ²(1 − exp(−2dt/τ)) keeping the steady state σ²."""
    dt = np.asarray(dt, dtype=float)
    if not np.isfinite(tau):
        return np.zeros_like(dt)
    return sd**2 * (1.0 - np.exp(-2.0 * dt / tau))


def gm_mean_prior_sd(sd: float, tau: float, dur: float) -> float:
    """Prior sigma of the time average of a stationary GM process over ``dur`` seconds:
    var = σ²·(2τ/D)(1 − (τ/D)(1 − e^{−D/τ})). The prior of the reported mean baro bias
    ``bias_m`` in both families (its ``observable`` flag compares against it)."""
    if dur <= 0 or not np.isfinite(tau):
        return sd
    x = tau / dur
    return float(sd * np.sqrt(max(2 * x * (1 - x * (1 - np.exp(-1 / x))), 0.0)))


def imu_bias_step(dt: float | FloatArray, tau: float, sd: float, rw: float
                  ) -> tuple[FloatArray, FloatArray]:
    """One step ``dt`` of an IMU bias modelled as one first-order Gauss-Markov state (σ
    ``sd``, correlation time ``tau``) plus a random walk of root PSD ``rw`` (``ImuSpec``):
    b(t + dt) = φ·b(t) + w, φ = exp(−dt/τ), var w = σ²(1 − φ²) + rw²·dt. Returns (φ, var w).
    Both families discretise the IMU biases with it: the ekf's process noise (its Φ and
    ``ekf.kernel.decay_gm`` apply the same φ), the graph's bias link
    (``graph.model.cpp_factors.bias_link``)."""
    dt = np.asarray(dt, dtype=float)
    return gm_transition(dt, tau), gm_process_var(dt, tau, sd) + rw**2 * dt
