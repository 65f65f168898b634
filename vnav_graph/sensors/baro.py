"""Barometric altimeter error model — the one model of docs/design.md, used everywhere.

    h_b(t) − h0 = (1 + s)·(h(t − τd) − h0) + b(t) + v,   ḃ = −b/τb + w

h is the true ellipsoidal height, h0 the drive-origin height (the scale acts on height above
it), s a random-constant scale error, τd the latency, b a first-order Gauss-Markov bias and v
white noise. Linearised in τd (seed 001 eq. 2): h_b ≈ h0 + (1+s)(h − h0 − v_up·τd) + b.

The model is written once, as two compiled scalar functions: ``baro_predict`` (the predicted
reading) and ``baro_row`` (its Jacobian with respect to the physical errors (h, v_up, s, τd, b)).
The EKF's row calls them at one event, the 7-state filter at each sample, and the graph's
factor over all samples through ``baro_arrays`` (both at once), which maps the same compiled
functions over broadcast arrays.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import ArrayLike

from ..nav.arrays import put
from ..types.streams import FloatArray


@njit(cache=True)
def baro_predict(h, v_up, scale, latency, bias, h0):  # pragma: no cover - numba
    """Predicted baro altitude [m] from height h [m] and vertical speed v_up [m/s] at the
    sample time: h0 + (1+s)(h − h0 − v_up·τd) + b, the latency applied by first-order
    back-extrapolation h(t−τd) ≈ h − v_up·τd."""
    return h0 + (1.0 + scale) * (h - h0 - v_up * latency) + bias


@njit(cache=True)
def baro_row(h, v_up, scale, latency, h0):  # pragma: no cover - numba
    """∂h_b/∂(h, v_up, s, τd, b) of ``baro_predict``, shape (5,)."""
    return np.array([1.0 + scale, -(1.0 + scale) * latency, h - h0 - v_up * latency,
                     -(1.0 + scale) * v_up, 1.0])


@njit(cache=True)
def _map_baro(h, v_up, scale, latency, bias, h0, pred, jac):  # pragma: no cover - numba
    for i in range(h.size):
        pred[i] = baro_predict(h[i], v_up[i], scale[i], latency[i], bias[i], h0)
        put(jac[i], baro_row(h[i], v_up[i], scale[i], latency[i], h0))


def baro_arrays(h: ArrayLike, v_up: ArrayLike, scale: ArrayLike, latency: ArrayLike,
                bias: ArrayLike, h0: float) -> tuple[FloatArray, FloatArray]:
    """``baro_predict`` and ``baro_row`` over the broadcast inputs: shapes (...) and (..., 5)."""
    args = [np.asarray(x, dtype=float) for x in (h, v_up, scale, latency, bias)]
    shape = np.broadcast_shapes(*(a.shape for a in args))
    # writable contiguous copies: numba reads a broadcast view's flags, which numpy < 2
    # answers with a FutureWarning
    flat = [np.array(np.broadcast_to(a, shape)).reshape(-1) for a in args]
    pred = np.empty(flat[0].size)
    jac = np.empty((flat[0].size, 5))
    _map_baro(*flat, float(h0), pred, jac)
    return pred.reshape(shape), jac.reshape(*shape, 5)

