"""The post-run check chain of every estimator with the full state (ekf, ekf-rts, graph-batch,
graph-isam2), in the order ``checked`` applies it:

1. the hard-iron check (``without_contradicting_mag``): a magnetometer whose estimated hard
   iron contradicts its prior is left out and the drive solved again;
2. the baro-scale check (``without_implausible_scale``): a scale beyond the physical ±25 % is
   held at its prior mean and the drive solved again;
3. the prior-conflict notes (``with_prior_conflict_notes``): a calibration estimate far from
   its prior is named among the warnings (vekf7 applies this one too).

A re-solve changes the final answer only: the real-time answers stay the first pass's
(``Estimate.with_real_time_of``), since each check needs the whole drive.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from ..types import Estimate


def checked(result: Estimate, config: Any, rerun: Callable[[Any], Estimate],
            mag_rerun: Callable[[Any], Estimate] | None = None) -> Estimate:
    """``result`` through the chain: ``rerun(config)`` solves the drive again with the
    estimator's whole run (checks included); ``mag_rerun`` (default ``rerun``) is the one the
    hard-iron check uses."""
    result = without_contradicting_mag(result, config, mag_rerun or rerun)
    return with_prior_conflict_notes(without_implausible_scale(result, config, rerun))


HARD_IRON_GATE_PROB = 0.999  # χ²₃ probability of the post-solve hard-iron check


def hard_iron_note(info: dict[str, Any], prior_sd_ut: float) -> str:
    """Post-solve check of an estimate that used the magnetometer: '' when its hard iron
    (``info["extra_variables"]["h0"]["est"]``) is plausible under its prior N(0, σ² I)
    (χ²₃ at ``HARD_IRON_GATE_PROB``: 4.0σ in 3 dof), else the note of an estimator that
    drops the magnetometer and solves again. A hard iron far outside its prior means the
    compass contradicts the heading of GNSS and IMU (interference beyond the model): a hard
    iron that cancels most of the horizontal field lets any heading fit (docs/real_logs.md,
    "Magnetometer noise, field strength and spread"). Same rule for both families."""
    h = (info.get("extra_variables") or {}).get("h0")
    if h is None:
        return ""
    from scipy.stats import chi2

    b = np.asarray(h["est"], float)
    d2 = float(np.sum((b / prior_sd_ut) ** 2))
    lim = float(chi2.ppf(HARD_IRON_GATE_PROB, 3))
    if not d2 > lim:
        return ""
    return (f"magnetometer not used: with it the hard iron came out at ({b[0]:.1f}, "
            f"{b[1]:.1f}, {b[2]:.1f}) µT, {np.sqrt(d2):.1f}σ of its {prior_sd_ut:g} µT prior "
            f"(χ²₃ {d2:.0f} > {lim:.1f}): the compass contradicts the heading of GNSS and "
            "IMU (interference beyond the hard-iron model); solved again without it")


def without_contradicting_mag(result: Estimate, config: Any,
                              rerun: Callable[[Any], Estimate]) -> Estimate:
    """The post-solve hard-iron check of every estimator that uses the magnetometer (ekf,
    ekf-rts, graph-batch, graph-isam2): ``result`` when it passes (:func:`hard_iron_note`;
    ``config`` has ``use_mag`` and ``mag_bias_sd``), else ``rerun(config without the
    magnetometer)`` with the reason in ``info["mag_note"]``, the config asked for and the
    time of both runs; the real-time answers stay ``result``'s (the check needs the whole
    drive: ``Estimate.with_real_time_of``)."""
    why = hard_iron_note(result.info, config.mag_bias_sd) if config.use_mag else ""
    if not why:
        return result
    from dataclasses import replace

    again = rerun(replace(config, use_mag=False)).with_real_time_of(
        result, "the magnetometer was left out after the whole drive's hard-iron check")
    return again.replace(info={**again.info, "mag_note": why}, config=config,
                         runtime_s=result.runtime_s + again.runtime_s)


# The physical range of the scale error. s is the ISA pressure altitude's error against
# height, set by the air's temperature off the standard atmosphere, s ≈ ΔT/T: ±25 % would
# need air 70 K off it (−55 °C or +85 °C near sea level), beyond any flight or drive. An
# estimate beyond it means the baro states absorbed something else: an inertial vertical
# that contradicts the baro (an accelerometer bias step, e.g. vibration rectification:
# docs/real_logs.md, "Accelerometers that lose specific force") drives (1 + s) towards 0,
# the baro's gain on the height vanishes and the height drifts with the accelerometer (a
# 3 m/s² step in the last 60 s of a 300 s hill-drive without GNSS: s → −1.01 and 3.7 km of
# altitude error for graph-batch, s = +0.61 for ekf-rts; docs/graph.md, "Baro scale limit").
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
# (4.5 of their σ from the truth). On a 1 Hz log a latency below the model's time resolution
# follows the keyframe or propagation grid, not the data, and lands many prior σ out
# (docs/real_logs.md, "Baro latency on 1 Hz logs").
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
