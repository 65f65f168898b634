"""The one place where continuous noise specs become discrete variances and sequences."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.signal import lfilter

FloatArray = NDArray[np.float64]


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


def gauss_markov(
    t: FloatArray, tau: float, sd: float, rng: np.random.Generator, size: int = 1,
    x0: FloatArray | None = None,
) -> FloatArray:
    """Sample a stationary first-order Gauss-Markov process at times ``t``, shape (N, size).

    x_{k+1} = φ_k x_k + w_k, φ_k = exp(−Δt_k/τ), var w_k = σ²(1 − φ_k²), x_0 ~ N(0, σ²)
    (or ``x0``). τ = inf gives a random constant.
    """
    t = np.asarray(t, dtype=float)
    n = t.size
    x0 = rng.normal(0.0, sd, size) if x0 is None else np.broadcast_to(x0, (size,)).astype(float)
    if sd == 0 and x0 is None:
        return np.zeros((n, size))
    dt = np.diff(t)
    if not np.isfinite(tau):
        return np.broadcast_to(x0, (n, size)).copy()
    phi = gm_transition(dt, tau)
    w = rng.normal(size=(n - 1, size)) * np.sqrt(gm_process_var(dt, tau, sd))[:, None]
    if dt.size == 0 or np.allclose(dt, dt[0]):
        # uniform step: one IIR filter call
        out = np.empty((n, size))
        out[0] = x0
        if n > 1:
            zi = (phi[0] * x0)[None, :]
            out[1:] = lfilter([1.0], [1.0, -phi[0]], w, axis=0, zi=zi)[0]
        return out
    out = np.empty((n, size))
    out[0] = x0
    for k in range(n - 1):
        out[k + 1] = phi[k] * out[k] + w[k]
    return out


def random_walk(
    t: FloatArray, density: float, rng: np.random.Generator, size: int = 1
) -> FloatArray:
    """Random walk with root PSD ``density`` (units/√s), starting at 0, shape (N, size)."""
    t = np.asarray(t, dtype=float)
    if density == 0:
        return np.zeros((t.size, size))
    steps = rng.normal(size=(t.size - 1, size)) * (density * np.sqrt(np.diff(t)))[:, None]
    return np.vstack([np.zeros((1, size)), np.cumsum(steps, axis=0)])
