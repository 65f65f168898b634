"""Robust losses of the measurement terms (GNSS position, GNSS velocity, baro), shared by
both families: the graphs' IRLS (``estimators.graph.model.robust``) and ekf-rts's weights from
smoothed residuals (``estimators.ekf.regate``).

A measurement with whitened residual vector r (GNSS: the 3 rows of one fix; baro: one row)
and Mahalanobis norm e = ‖r‖ costs ρ(e) instead of e²/2, with the threshold k in σ:

    none:    ρ = e²/2                                   w = 1
    huber:   ρ = e²/2 (e ≤ k),  k·e − k²/2 (e > k)       w = 1 (e ≤ k),  k/e (e > k)
    cauchy:  ρ = (k²/2)·ln(1 + (e/k)²)                  w = 1 / (1 + (e/k)²)

(Huber 1964; Zhang, "Parameter estimation techniques", 1997, Table 1). The weight w = ρ'(e)/e
is the iteratively-reweighted-least-squares weight: rows scaled by √w at each linearisation
(GTSAM's ``noiseModel.Robust`` on the graphs' C++ factors, tested equal), or a variance R/w.

A fix that fits the solution worse than any loss should weigh is refused after solving by
both families' post-solve gates at one threshold (``post_gate_threshold``).
"""

from __future__ import annotations

from functools import cache

import numpy as np

from ..types.streams import FloatArray

LOSSES = ("none", "huber", "cauchy")


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


@cache
def post_gate_threshold(gate_prob: float, dof: int) -> float:
    """χ² threshold of the post-solve GNSS gates (the graphs', ekf-rts's post-smoothing one):
    the 1 − (1 − p)² quantile, ``dof`` degrees of freedom (a false rejection costs a whole
    re-solve, a glitch has χ² in the thousands either way)."""
    from scipy.stats import chi2

    return float(chi2.ppf(1.0 - (1.0 - gate_prob) ** 2, dof))
