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
    if n - 1 > LFILTER_MIN_ROWS and np.allclose(dt, dt[0]):
        # long uniform series: scipy.signal's IIR filter (a C loop, ~0.05 s for an hour at
        # 400 Hz against ~0.5 s for the scan); its 1.5 s import is small beside such a drive
        from scipy.signal import lfilter

        out[1:] = lfilter([1.0], [1.0, -phi[0]], w, axis=0)
    else:
        out[1:] = linear_recurrence(phi, w)
    return out


LFILTER_MIN_ROWS = 200_000  # uniform series longer than this go through scipy.signal.lfilter
SCAN_BLOCK = 4096  # rows per block of linear_recurrence's scan


def linear_recurrence(a: FloatArray, w: FloatArray) -> FloatArray:
    """x_k = a_k x_{k−1} + w_k with x_{−1} = 0, for (M,) ``a`` and (M, S) ``w``: (M, S).

    A parallel-prefix scan instead of scipy.signal's IIR filter, whose import alone costs
    1.5 s, a twentieth of a whole first run (a numba loop was tried: as the first kernel of
    the process it paid ~3 s of numba start-up). Within blocks of ``SCAN_BLOCK`` rows,
    log₂(block) vectorised passes: after the pass with shift s, x_k holds
    Σ_{j<2s} (a_k ⋯ a_{k−j+1}) w_{k−j} and the coefficient the product a_k ⋯ a_{k−2s+1}; then
    each block adds its running product of a times the previous block's last row. Equal to the
    plain recursion to rounding (tests/unit/test_sensors.py).
    """
    a = np.asarray(a, dtype=float)
    x = np.array(w, dtype=float)
    m, cols = x.shape
    if m == 0:
        return x
    block = min(SCAN_BLOCK, m)
    nb = -(-m // block)
    pad = nb * block - m
    xb = np.concatenate([x, np.zeros((pad, cols))]).reshape(nb, block, cols)
    cb = np.concatenate([a, np.ones(pad)]).reshape(nb, block)
    s = 1
    while s < block:
        xb[:, s:] = xb[:, s:] + cb[:, s:, None] * xb[:, :-s]
        cb[:, s:] = cb[:, s:] * cb[:, :-s]
        s *= 2
    for b in range(1, nb):  # cb[b, j] is now a_{b,0} ⋯ a_{b,j}
        xb[b] += cb[b][:, None] * xb[b - 1, -1]
    return xb.reshape(-1, cols)[:m]


def random_walk(
    t: FloatArray, density: float, rng: np.random.Generator, size: int = 1
) -> FloatArray:
    """Random walk with root PSD ``density`` (units/√s), starting at 0, shape (N, size)."""
    t = np.asarray(t, dtype=float)
    if density == 0:
        return np.zeros((t.size, size))
    steps = rng.normal(size=(t.size - 1, size)) * (density * np.sqrt(np.diff(t)))[:, None]
    return np.vstack([np.zeros((1, size)), np.cumsum(steps, axis=0)])
