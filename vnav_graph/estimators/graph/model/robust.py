"""The graphs' use of the shared robust losses (``estimators.robust``: the losses, their weights
and the references): rows reweighted for Gauss-Newton as IRLS (``reweight``), and the same loss
as GTSAM's robust noise model for the C++ factors (``robust_noise``; the mEstimator weights
are tested equal).
"""

from __future__ import annotations

from typing import Any

import gtsam
import numpy as np

from ....types.streams import FloatArray
from ...robust import weight_and_loss


def reweight(r: FloatArray, jac: FloatArray, dim: int, loss: str, k: float
             ) -> tuple[FloatArray, FloatArray, FloatArray, float]:
    """Rows of measurements of ``dim`` consecutive rows each, reweighted: (√w·r, √w·J, w per
    measurement, Σρ)."""
    e = np.sqrt(np.sum(r.reshape(-1, dim) ** 2, axis=1))
    if loss == "none":  # the plain rows, untouched
        return r, jac, np.ones(e.size), 0.5 * float(r @ r)
    w, rho = weight_and_loss(e, loss, k)
    sw = np.repeat(np.sqrt(w), dim)
    return r * sw, jac * sw[:, None], w, float(np.sum(rho))


def robust_noise(model: Any, loss: str, k: float) -> Any:
    """``model`` wrapped in GTSAM's robust noise model of the same loss (unchanged for
    "none")."""
    if loss == "none":
        return model
    est = (gtsam.noiseModel.mEstimator.Huber if loss == "huber"
           else gtsam.noiseModel.mEstimator.Cauchy).Create(k)
    return gtsam.noiseModel.Robust.Create(est, model)
