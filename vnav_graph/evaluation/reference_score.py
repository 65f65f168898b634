"""Holdout windows scored against a reference trajectory (``holdout --truth FILE``).

With a reference (``Drive.truth`` from ``io.reference``) the withheld-GNSS run of every
estimator is also scored against the reference's positions inside the windows: on a drive
whose GNSS input *is* the reference (an RTK solution), the withheld epochs' centimetre
positions are an independent truth for what the estimator did without them.

At each reference epoch inside a window (and inside the estimate's span), with the estimate
interpolated linearly to it:

- altitude error ``ĥ − h_ref`` [m] (no datum offset: the reference is on the drive's datum);
- horizontal error: tangent-plane north/east distance [m] (``pos_h`` estimators);
- vertical-velocity error ``v̂_D − v_D,ref`` [m/s] (``vel_d`` estimators);
- NEES over position and velocity at the covariance epochs inside the windows
  (``metrics.nees``), mean and degrees of freedom.

Returned per estimator as the holdout block's ``reference`` (RMS, maxima, ``per_window``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from ..types import Drive, Estimate
from ..types.streams import FloatArray
from .metrics import finite_max, finite_rms, nees

__all__ = ["reference_block"]


def _inside(t: FloatArray, windows: Sequence[tuple[float, float]]) -> np.ndarray:
    m = np.zeros(t.shape, dtype=bool)
    for a, b in windows:
        m |= (t >= a) & (t <= b)
    return m


def reference_block(est: Estimate, drive: Drive,
                    windows: Sequence[tuple[float, float]]) -> dict[str, Any] | None:
    """The estimate's errors against ``drive.truth`` inside ``windows`` (module docstring);
    None without a truth or when no reference epoch falls inside a window."""
    from ..geo.frames import lla_to_ned

    ref = drive.truth
    if ref is None:
        return None
    tr = est.trajectory
    m = _inside(ref.t, windows) & (ref.t >= tr.t[0]) & (ref.t <= tr.t[-1])
    if not m.any():
        return None
    t = ref.t[m]
    lla_e = np.column_stack([np.interp(t, tr.t, tr.lla[:, j]) for j in range(3)])
    alt = lla_e[:, 2] - ref.lla[m, 2]
    horiz = None
    if "pos_h" in est.provides and np.all(np.isfinite(lla_e[:, :2])):
        d = (lla_to_ned(lla_e, drive.origin_lla)[:, :2]
             - lla_to_ned(ref.lla[m], drive.origin_lla)[:, :2])
        horiz = np.sqrt(np.sum(d**2, axis=1))
    vd = None
    if "vel_d" in est.provides:
        vd = np.interp(t, tr.t, tr.vel_down) - ref.vel_n[m, 2]
    out: dict[str, Any] = {
        "n_scored": int(m.sum()),
        "alt_rmse_m": finite_rms(alt), "alt_max_abs_m": finite_max(alt),
        "horiz_rmse_m": finite_rms(horiz), "horiz_max_m": finite_max(horiz),
        "vel_down_rmse_mps": finite_rms(vd), "nees_mean": None, "nees_dof": None,
    }
    ne = nees(est, drive)
    if ne is not None and est.t_cov is not None:
        tc = est.t_cov[(est.t_cov >= ref.t[0]) & (est.t_cov <= ref.t[-1])]
        w = _inside(tc, windows)
        if w.any():
            out["nees_mean"], out["nees_dof"] = float(np.mean(ne[0][w])), int(ne[1])
    out["per_window"] = []
    for a, b in windows:
        k = (t >= a) & (t <= b)
        out["per_window"].append({
            "t0": float(a), "t1": float(b), "n": int(k.sum()),
            "alt_rmse_m": finite_rms(alt[k]), "horiz_rmse_m": finite_rms(None if horiz is None
                                                              else horiz[k]),
            "horiz_max_m": finite_max(None if horiz is None else horiz[k])})
    return out
