"""Barometric altimeter error model — the one model of docs/design.md, used everywhere.

    h_b(t) − h0 = (1 + s)·(h(t − τd) − h0) + b(t) + v,   ḃ = −b/τb + w

h is the true ellipsoidal height, h0 the drive-origin height (the scale acts on height above
it), s a random-constant scale error, τd the latency, b a first-order Gauss-Markov bias and v
white noise. Linearised in τd (seed 001 eq. 2): h_b ≈ h0 + (1+s)(h − h0 − v_up·τd) + b.

The model is written once, as two compiled scalar functions: ``baro_predict`` (the predicted
reading) and ``baro_row`` (its Jacobian with respect to the physical errors (h, v_up, s, τd, b)).
The EKF's row calls them at one event, the 7-state filter at each sample, and the graph's
factor over all samples through ``baro_arrays`` (both at once; ``measure_baro`` /
``baro_jacobian`` for one of them), which maps the same compiled functions over broadcast
arrays.
"""

from __future__ import annotations

import numpy as np
from numba import njit
from numpy.typing import ArrayLike

from ..config import BaroSpec
from ..geo.atmosphere import isa_pressure
from ..nav.arrays import put
from ..types import BaroTruth
from ..types.streams import BaroStream, FloatArray
from .noise import gauss_markov


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


def measure_baro(
    h: ArrayLike, v_up: ArrayLike, scale: ArrayLike, latency: ArrayLike, bias: ArrayLike,
    h0: float,
) -> FloatArray:
    """``baro_predict`` over broadcast arrays [m]."""
    return baro_arrays(h, v_up, scale, latency, bias, h0)[0]


def baro_jacobian(
    h: ArrayLike, v_up: ArrayLike, scale: ArrayLike, latency: ArrayLike, h0: float
) -> FloatArray:
    """``baro_row`` over broadcast arrays: ∂h_b/∂(h, v_up, s, τd, b), shape (..., 5)."""
    return baro_arrays(h, v_up, scale, latency, 0.0, h0)[1]


def draw_baro_truth(spec: BaroSpec, rng: np.random.Generator) -> BaroTruth:
    """Draw the random constants (scale, latency) of one simulated altimeter."""
    s = spec.scale if spec.scale is not None else float(rng.normal(0.0, spec.scale_sd))
    if spec.latency_range_s is not None:
        tau = float(rng.uniform(*spec.latency_range_s))
    else:
        tau = spec.latency_s
    return BaroTruth(scale=s, latency_s=tau)


def _indicated_scale(h0: float, dT: float) -> float:
    """Slope − 1 of the standard-law altitude against the true height in an ISA + dT
    troposphere whose sea-level pressure makes the reading exact at h0 [m] (zero bias).

    With p = c·P0·(1 − L·h/(T0 + dT))^(g/RL) the standard law reads
    h_i = T0/L·(1 − c'·(1 − L·h/(T0 + dT))), c' = c^(RL/g): affine in h with slope
    c'·T0/(T0 + dT). c' ≠ 1 moves the slope by ≈ L·(h_i(h0) − h0)/T0 (5e-4 per 25 m), which is
    why this is ≈ T0/(T0 + dT) − 1 but not exactly.
    """
    from ..geo.atmosphere import G0, P0, R_AIR, T0, L

    c = (isa_pressure(h0) / isa_pressure(h0, dT, p0=1.0) / P0) ** (R_AIR * L / G0)
    return float(c * T0 / (T0 + dT) - 1.0)


def simulate_baro(
    t: FloatArray, t_truth: FloatArray, h_truth: FloatArray, h0: float, spec: BaroSpec,
    rng: np.random.Generator,
) -> tuple[BaroStream, BaroTruth, FloatArray]:
    """Generate baro samples at ``t`` from the true height ``h_truth`` sampled at ``t_truth``.

    Returns the stream, the drawn constants and the bias b(t) at ``t`` [m].
    In ``physical`` mode the pressure is produced by a non-standard atmosphere (ISA + dT with
    dT = −s·T0/(1+s), giving scale s exactly at the reference, and a sea-level pressure
    drifting as a Gauss-Markov process that gives b); the returned bias is then the
    indicated-altitude error at h0 (exact there; away from h0 the ISA law adds a small
    nonlinearity that the linear model does not have), and the stream carries pressure [Pa].
    With ``spec.isa_offset_k`` = ΔT the day is ISA + ΔT on top of the sensor's s:
    dT = (T0 + ΔT)/(1+s) − T0 = −s·T0/(1+s) + ΔT/(1+s), so T0/(T0 + dT) = (1+s)·T0/(T0 + ΔT).
    The returned ``BaroTruth.scale`` is then the effective scale an estimator should find: the
    exact slope − 1 of the reading against the true height (``_indicated_scale``), which the
    reading's setting at h0 moves from T0/(T0 + dT) − 1 by ≈ −L·h0·dT/(T0 + dT)² (−1.5e-3 at
    h0 = 890 m for s = −3 %, ΔT = 15 K). In the ISA troposphere the reading is affine in h, so
    that slope holds at every height. At ΔT = 0 the returned scale stays the drawn s, as
    before.
    """
    truth = draw_baro_truth(spec, rng)
    t_del = t - truth.latency_s
    if t_del[0] < t_truth[0]:
        t_del = np.maximum(t_del, t_truth[0])  # the first τd seconds repeat the first height
    h_del = np.interp(t_del, t_truth, h_truth)
    x0 = None if spec.bias_init is None else np.array([spec.bias_init])
    bias = gauss_markov(t, spec.bias_tau, spec.bias_sd, rng, 1, x0=x0)[:, 0]
    noise = rng.normal(0.0, spec.noise_sd, t.size) if spec.noise_sd > 0 else np.zeros(t.size)
    if not spec.physical:
        alt = h0 + (1.0 + truth.scale) * (h_del - h0) + bias + noise
        return BaroStream(t, alt=alt, spec=spec), truth, bias
    from ..geo.atmosphere import R_AIR, T0, isa_temperature

    # ISA + dT with dT = −s·T0/(1+s) makes the standard-law altimeter read (1+s)·h; the day's
    # offset ΔT enters as ΔT/(1+s) (docstring), and adds exactly 0.0 when it is 0.
    dT = -truth.scale * T0 / (1.0 + truth.scale) + spec.isa_offset_k / (1.0 + truth.scale)
    # Sea-level pressure p0(t) chosen so the indicated altitude at h0 is exactly h0 + b(t).
    p0 = isa_pressure(h0 + bias) / isa_pressure(h0, dT, p0=1.0)
    if spec.isa_offset_k != 0.0:
        truth = BaroTruth(scale=_indicated_scale(h0, dT), latency_s=truth.latency_s)
    p = p0 * isa_pressure(h_del, dT, p0=1.0)
    # white noise of noise_sd metres through the hydrostatic gradient dp/dh = −p·g/(R·T)
    p = p - noise * p * 9.80665 / (R_AIR * isa_temperature(h_del, dT))
    return BaroStream(t, pressure=p, spec=spec), truth, bias
