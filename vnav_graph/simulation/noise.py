"""Random sequences of the simulator: a first-order Gauss-Markov process, a random walk, and
the linear recursion that draws them (the discrete variances are ``sensors.noise``'s)."""

from __future__ import annotations

import numpy as np

from ..sensors.noise import gm_process_var, gm_transition
from ..types.streams import FloatArray


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
