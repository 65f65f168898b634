"""The one place where continuous noise specs become discrete variances and sequences."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

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
    if n > 1:
        w[0] += phi[0] * x0
    out = np.empty((n, size))
    out[0] = x0
    out[1:] = linear_recurrence(phi, w)
    return out


SCAN_MAX_ROWS = 200_000  # longer series go through scipy.signal.lfilter (see below)


def linear_recurrence(a: FloatArray, w: FloatArray) -> FloatArray:
    """x_k = a_k x_{k−1} + w_k with x_{−1} = 0, for (M,) ``a`` and (M, S) ``w``: (M, S).

    Up to ``SCAN_MAX_ROWS`` rows: a parallel-prefix scan (log₂ M vectorised numpy passes).
    scipy.signal's IIR filter needs a 1.5 s import, a twentieth of a whole first run, and a
    numba loop spends ~3 s initialising numba's compiler when it is the first kernel of the
    process (both measured on the default drive). After the pass with shift s, x_k holds
    Σ_{j<2s} (a_k ⋯ a_{k−j+1}) w_{k−j} and the coefficient the product a_k ⋯ a_{k−2s+1}.
    Longer series (an hour at 100 Hz) go through ``scipy.signal.lfilter`` (a C loop; the scan
    would cost ~1 s per call there): constant ``a`` only, else a Python loop. All three equal
    the plain recursion to rounding (tests/unit/test_sensors.py).
    """
    a = np.asarray(a, dtype=float)
    x = np.array(w, dtype=float)
    m = x.shape[0]
    if m == 0:
        return x
    if m > SCAN_MAX_ROWS:
        if np.all(a == a[0]):
            from scipy.signal import lfilter

            return np.asarray(lfilter([1.0], [1.0, -a[0]], x, axis=0))
        for k in range(1, m):
            x[k] += a[k] * x[k - 1]
        return x
    coef = a[:, None] * np.ones((1, x.shape[1]))
    s = 1
    while s < m:
        x[s:] = x[s:] + coef[s:] * x[:-s]
        coef[s:] = coef[s:] * coef[:-s]
        s *= 2
    return x


def random_walk(
    t: FloatArray, density: float, rng: np.random.Generator, size: int = 1
) -> FloatArray:
    """Random walk with root PSD ``density`` (units/√s), starting at 0, shape (N, size)."""
    t = np.asarray(t, dtype=float)
    if density == 0:
        return np.zeros((t.size, size))
    steps = rng.normal(size=(t.size - 1, size)) * (density * np.sqrt(np.diff(t)))[:, None]
    return np.vstack([np.zeros((1, size)), np.cumsum(steps, axis=0)])
