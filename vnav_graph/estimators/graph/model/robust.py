"""Robust losses of the measurement terms (GNSS position, GNSS velocity, baro).

A measurement with whitened residual vector r (GNSS: the 3 rows of one fix; baro: one row)
and Mahalanobis norm e = ‖r‖ costs ρ(e) instead of e²/2, with the threshold k in σ:

    none:    ρ = e²/2                                   w = 1
    huber:   ρ = e²/2 (e ≤ k),  k·e − k²/2 (e > k)       w = 1 (e ≤ k),  k/e (e > k)
    cauchy:  ρ = (k²/2)·ln(1 + (e/k)²)                  w = 1 / (1 + (e/k)²)

(Huber 1964; Zhang, "Parameter estimation techniques", 1997, Table 1). The weight w = ρ'(e)/e
enters Gauss-Newton as iteratively reweighted least squares: the rows are scaled by √w at
each linearisation, which is what GTSAM's ``noiseModel.Robust`` does to the C++ factors
(``robust_noise`` builds the same loss for them; the mEstimator weights are tested equal).
"""

from __future__ import annotations

from typing import Any

import gtsam
import numpy as np

from ....types import FloatArray

LOSSES = ("none", "huber", "cauchy")


def check_loss(name: str, what: str) -> None:
    if name not in LOSSES:
        raise ValueError(f"GraphConfig.{what} must be one of {', '.join(LOSSES)}, not {name!r}")


def weight_and_loss(e: FloatArray, loss: str, k: float) -> tuple[FloatArray, FloatArray]:
    """IRLS weight w(e) and loss ρ(e) of Mahalanobis norms ``e`` (n,)."""
    e = np.abs(np.asarray(e, float))
    if loss == "none":
        return np.ones_like(e), 0.5 * e * e
    if loss == "huber":
        big = e > k
        w = np.where(big, k / np.where(big, e, 1.0), 1.0)
        return w, np.where(big, k * e - 0.5 * k * k, 0.5 * e * e)
    if loss == "cauchy":
        q = (e / k) ** 2
        return 1.0 / (1.0 + q), 0.5 * k * k * np.log1p(q)
    raise ValueError(f"unknown robust loss {loss!r}")


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
