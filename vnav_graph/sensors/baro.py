"""Barometric altimeter error model — the one model of docs/design.md, used everywhere.

    h_b(t) − h0 = (1 + s)·(h(t − τd) − h0) + b(t) + v,   ḃ = −b/τb + w

h is the true ellipsoidal height, h0 the drive-origin height (the scale acts on height above
it), s a random-constant scale error, τd the latency, b a first-order Gauss-Markov bias and v
white noise. Linearised in τd (seed 001 eq. 2): h_b ≈ h0 + (1+s)(h − h0 − v_up·τd) + b.

``measure_baro`` is the model an estimator predicts with; ``baro_jacobian`` is its Jacobian
with respect to (h, v_up, s, τd, b) — the EKF, the 7-state filter and the graph factor all use
these two functions.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ..config import BaroSpec
from ..geo.atmosphere import isa_pressure
from ..types import BaroTruth
from ..types.streams import BaroStream, FloatArray
from .noise import gauss_markov

HPA_PER_M = 1.0 / 8.3  # near sea level, for converting a bias sigma to pressure


def measure_baro(
    h: ArrayLike, v_up: ArrayLike, scale: ArrayLike, latency: ArrayLike, bias: ArrayLike,
    h0: float,
) -> FloatArray:
    """Predicted baro altitude [m] from height h [m] and vertical speed v_up [m/s] at the
    sample time, with the latency applied by first-order back-extrapolation h(t−τ) ≈ h − v·τ."""
    h = np.asarray(h, dtype=float)
    return h0 + (1.0 + np.asarray(scale)) * (h - h0 - np.asarray(v_up) * latency) + bias


def baro_jacobian(
    h: ArrayLike, v_up: ArrayLike, scale: ArrayLike, latency: ArrayLike, h0: float
) -> FloatArray:
    """∂h_b/∂(h, v_up, s, τd, b), shape (..., 5)."""
    h = np.asarray(h, dtype=float)
    v_up = np.asarray(v_up, dtype=float)
    s = np.asarray(scale, dtype=float)
    tau = np.asarray(latency, dtype=float)
    one = np.ones(np.broadcast(h, v_up, s, tau).shape)
    return np.stack(
        [(1 + s) * one, -(1 + s) * tau * one, (h - h0 - v_up * tau) * one, -(1 + s) * v_up * one,
         one],
        axis=-1,
    )


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


# The physical range of the scale error. s is the ISA pressure altitude's error against
# height, set by the air's temperature off the standard atmosphere, s ≈ ΔT/T: ±25 % would
# need air 70 K off it (−55 °C or +85 °C near sea level), beyond any flight or drive. An
# estimate beyond it means the baro states absorbed something else: an inertial vertical
# that contradicts the baro (an accelerometer bias step, e.g. vibration rectification on
# 181.BIN: |f| 7–8 m/s² for 20 s of climb) drives (1 + s) towards 0, the baro's gain on the
# height vanishes and the height drifts with the accelerometer (a 3 m/s² step in the last
# 60 s of a 300 s hill-drive without GNSS: s → −1.01 and 3.7 km of altitude error for
# graph-batch, s = +0.61 for ekf-rts; docs/graph.md, "Baro scale limit").
SCALE_LIMIT = 0.25
# Prior σ of the scale in the solve that replaces such an estimate: held at the prior mean.
STIFF_SCALE_SD = 1e-3


def implausible_scale_note(result: Any) -> str:
    """Why ``result`` (an ``Estimate``) has a physically impossible baro scale, or "": the
    final |s|, or the largest |s| its pass went through (``info["baro_scale_max_abs"]``:
    the forward filter's, iSAM2's online), beyond ``SCALE_LIMIT``."""
    sc = result.baro.scale if result.baro is not None else None
    if sc is None:
        return ""
    worst = max(abs(float(sc.est)), float(result.info.get("baro_scale_max_abs") or 0.0))
    if not worst > SCALE_LIMIT:
        return ""
    return (f"baro scale {sc.est:+.1%} (|s| up to {worst:.0%} in the pass) is beyond the "
            f"physical ±{SCALE_LIMIT:.0%}: the inertial vertical contradicts the barometer "
            "(an accelerometer bias step, e.g. vibration) and the scale absorbed it")


def without_implausible_scale(result: Any, config: Any, rerun: Callable[[Any], Any]) -> Any:
    """The post-solve baro-scale check of every estimator with a scale state (ekf, ekf-rts,
    graph-batch, graph-isam2): ``result`` when its scale is physical
    (:func:`implausible_scale_note`), else ``rerun(config with baro_scale_sd =
    STIFF_SCALE_SD)`` (the scale held at its prior mean) with the reason as a warning and in
    ``info["baro_scale_note"]``; the real-time answers stay ``result``'s (the check needs
    the whole drive: ``Estimate.with_real_time_of``). A config that already sets
    ``baro_scale_sd`` is the user's (or this check's) own choice and is not second-guessed,
    and a result that carries ``baro_scale_note`` already is that re-solve, reached through
    another check's rerun (the magnetometer's runs the whole estimator again, checks
    included)."""
    if getattr(config, "baro_scale_sd", None) is not None or "baro_scale_note" in result.info:
        return result  # the user's prior, or already this check's re-solve (a nested rerun)
    why = implausible_scale_note(result)
    if not why:
        return result
    from dataclasses import replace

    again = rerun(replace(config, baro_scale_sd=STIFF_SCALE_SD)).with_real_time_of(
        result, "the baro scale was held at 0 after the whole drive's scale check")
    note = f"{why}; solved again with the scale held at 0 (prior σ {STIFF_SCALE_SD:.1%})"
    info = {**again.info, "baro_scale_note": note,
            "warnings": [*(again.info.get("warnings") or []), note]}
    return again.replace(info=info, config=config,
                         runtime_s=result.runtime_s + again.runtime_s)


# A calibration estimate this many prior σ from its prior mean contradicts its prior: a draw
# that far out of a Gaussian prior has probability 6e-7, and the estimate's own σ, computed
# as if the prior held, is then too small. Simulated: a baro whose latency is 1.0 s against
# the default prior 0.1 ± 0.1 s is estimated at 0.70–0.73 ± 0.06 s by all four estimators
# (4.5 of their σ from the truth). Real: car 03-01a (1 Hz phone) puts the latency at −0.99 s
# with ekf-rts and at −0.48 s with graph-batch, each ±0.05 s, and graph-batch run on
# ekf-rts's 1 s time grid (keyframes every second) gives −1.00 s: the value follows the
# model's time resolution, not the data (docs/real_logs.md, "Baro latency on 1 Hz logs").
PRIOR_CONFLICT_Z = 5.0


def prior_conflict_notes(baro: Any) -> list[str]:
    """One note per calibration parameter of ``baro`` (a ``BaroEstimate``: scale, latency)
    whose estimate lies more than ``PRIOR_CONFLICT_Z`` prior σ from its prior mean."""
    out = []
    for attr, name, unit, k in (("scale", "scale", "%", 100.0),
                                ("latency_s", "latency", "s", 1.0)):
        pe = getattr(baro, attr, None)
        if pe is None or pe.prior_mean is None or not pe.prior_sd or pe.sd is None:
            continue
        z = (pe.est - pe.prior_mean) / pe.prior_sd
        if abs(z) > PRIOR_CONFLICT_Z:
            out.append(f"baro {name} {k * pe.est:+.2f} ± {k * pe.sd:.2f} {unit} is {abs(z):.1f} "
                       f"prior σ from its prior {k * pe.prior_mean:.2f} ± {k * pe.prior_sd:.2f} "
                       f"{unit}: the data contradict the prior (a sensor far from the default, "
                       f"a timing error or an unmodelled baro/GNSS height error) and its ± "
                       f"does not include that")
    return out


def with_prior_conflict_notes(result: Any) -> Any:
    """``result`` (an ``Estimate``) with :func:`prior_conflict_notes` in
    ``info["baro_prior_conflict"]`` and among its warnings (none, or already noted by a
    nested re-run of the estimator: unchanged)."""
    notes = prior_conflict_notes(result.baro)
    if not notes or "baro_prior_conflict" in result.info:
        return result
    warns = [*(result.info.get("warnings") or []), *notes]
    return result.replace(info={**result.info, "baro_prior_conflict": notes, "warnings": warns})
