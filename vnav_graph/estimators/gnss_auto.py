"""``gnss_gm_auto``: carry the Gauss-Markov GNSS error state only on a drive whose GNSS errors
are correlated in time, decided from the drive itself (both families call ``with_gm_auto``).

The receiver's σ says how large its errors are, not how they are correlated. A first pass
runs without the state; the autocorrelation at 5 s of the fixes' residuals against that
pass (``sensors.gnss_residuals``) is near 0 when the errors are white (the smoothed
trajectory does not follow white noise) and large when they are correlated over tens of
seconds. Above ``GM_AUTO_THRESHOLD`` on either axis, and above ``GM_AUTO_SIGMAS`` times the
σ 1/√M of a white series' autocorrelation over the M fix pairs at that lag (a short or 1 Hz
drive: 6 min at 1 Hz gives 0.21), the pass is run again with the state
(its σ and τ from the configuration: the same causes, atmosphere, orbit and multipath,
correlate every axis, and a smoother that follows a fast correlated error hides it in one
axis's residuals: urban-dense's horizontal 0.00 … 0.14 under ekf-rts against 0.41 … 0.47
vertical). Carrying the state on a white-error drive costs accuracy (the fixes are
down-weighted for an error that is not there), hence the test.

``info["gnss_gm_auto"]``: {"autocorr_h", "autocorr_v", "lag_s", "pairs", "threshold", "on",
"decided_at_s"}; a warning when the state was turned on; ``runtime_s`` covers both passes.
The decision needs the whole drive, so it changes the final answer only: with the state on,
the real-time answers (``online``, ``lag``) stay the first pass's
(``Estimate.with_real_time_of``, ``info["real_time_pass"]``).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np

from ..sensors.gnss_model import GM_AUTO_SIGMAS, GM_AUTO_THRESHOLD
from ..sensors.gnss_residuals import RESIDUAL_LAG_S, gnss_residual_autocorr
from ..types import Drive, Estimate


def gm_decision(est: Estimate, drive: Drive) -> dict[str, Any]:
    """The autocorrelations of ``est``'s GNSS residuals and whether they call for the state."""
    ac = gnss_residual_autocorr(est, drive) or {}
    h, v, pairs = ac.get("horiz"), ac.get("vert"), int(ac.get("pairs") or 0)
    thr = max(GM_AUTO_THRESHOLD, GM_AUTO_SIGMAS / np.sqrt(pairs)) if pairs else np.inf
    on = any(x is not None and x > thr for x in (h, v))
    return {"autocorr_h": h, "autocorr_v": v, "lag_s": RESIDUAL_LAG_S, "pairs": pairs,
            "threshold": float(thr), "on": bool(on)}


def with_gm_auto(drive: Drive, cfg: Any, name: str,
                 run: Callable[[Any], Estimate]) -> Estimate:
    """``run(config)`` without the state, then with it when ``gm_decision`` says so
    (module docstring). ``cfg``: an ``EkfConfig`` / ``GraphConfig`` with ``gnss_gm_auto``."""
    t0 = time.perf_counter()
    est = run(replace(cfg, gnss_gm_sd_h=0.0, gnss_gm_sd_v=0.0, gnss_gm_auto=False))
    t = est.trajectory.t
    # the residuals of the whole drive: the decision is taken at its end [s from its start]
    dec = {**gm_decision(est, drive), "decided_at_s": float(t[-1] - t[0]) if t.size else 0.0}
    warnings = list(est.info.get("warnings") or [])
    if dec["on"]:
        # decided from the whole drive: the real-time answers stay the first pass's
        est = run(replace(cfg, gnss_gm_auto=False)).with_real_time_of(
            est, "gnss_gm_auto: the GNSS error state was turned on from the whole drive's "
            "residuals")
        gm = cfg.gnss_gm
        warnings = list(est.info.get("warnings") or [])
        warnings.append(
            f"{name}: the GNSS residuals are correlated in time (autocorrelation at "
            f"{RESIDUAL_LAG_S:g} s: horizontal {_f(dec['autocorr_h'])}, vertical "
            f"{_f(dec['autocorr_v'])}, above {dec['threshold']:.3g}); solved again with the "
            f"Gauss-Markov GNSS error state (σ {gm.sd_h:g} m horizontal, {gm.sd_v:g} m "
            f"vertical, τ {gm.tau_s:g} s)")
    info = {**est.info, "gnss_gm_auto": dec, "warnings": warnings}
    return est.replace(info=info, runtime_s=time.perf_counter() - t0)


def _f(x: float | None) -> str:
    return "—" if x is None else f"{x:.2f}"
