"""Robust losses of the graph (``estimators.graph.robust``) against GTSAM's own m-estimators."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import X

from vnav_graph.estimators.graph import GraphConfig
from vnav_graph.estimators.graph.model.robust import reweight, robust_noise
from vnav_graph.estimators.robust import weight_and_loss

E = np.array([0.0, 0.3, 1.0, 1.99, 2.01, 3.0, 10.0, 250.0])


@pytest.mark.parametrize("loss,make", [("huber", gtsam.noiseModel.mEstimator.Huber),
                                       ("cauchy", gtsam.noiseModel.mEstimator.Cauchy)])
@pytest.mark.parametrize("k", [1.345, 2.0, 3.0])
def test_weight_and_loss_equal_gtsam_mestimators(loss, make, k):
    """The vectorised IRLS rows and GTSAM's noiseModel.Robust (the C++ factors) share one
    loss: compare with the C++ implementation, an independent code path."""
    w, rho = weight_and_loss(E, loss, k)
    est = make.Create(k)
    np.testing.assert_allclose(w, [est.weight(e) for e in E], rtol=1e-12)
    np.testing.assert_allclose(rho, [est.loss(e) for e in E], rtol=1e-12, atol=1e-15)


def test_weight_is_loss_derivative_over_residual():
    """IRLS weight w = ρ'(e)/e (finite differences of ρ)."""
    e = np.linspace(0.1, 20.0, 97)
    h = 1e-6
    for loss in ("none", "huber", "cauchy"):
        w, _ = weight_and_loss(e, loss, 2.0)
        d = (weight_and_loss(e + h, loss, 2.0)[1] - weight_and_loss(e - h, loss, 2.0)[1]) / (2 * h)
        np.testing.assert_allclose(w, d / e, rtol=1e-6)


def test_reweight_uses_the_norm_of_each_fix():
    """A 3-row fix is weighted by the Mahalanobis norm of its whole residual."""
    r = np.array([3.0, 4.0, 0.0, 0.1, 0.2, 0.2])  # fix norms 5 and 0.3
    jac = np.ones((6, 2))
    rw, jw, w, rho = reweight(r, jac, 3, "huber", 2.0)
    np.testing.assert_allclose(w, [2.0 / 5.0, 1.0])
    np.testing.assert_allclose(rw[:3], r[:3] * np.sqrt(0.4))
    np.testing.assert_allclose(jw[3:], jac[3:])
    assert rho == pytest.approx(2.0 * 5.0 - 2.0 + 0.5 * 0.09)


def test_robust_cpp_factor_error_is_the_loss():
    """A GTSAM factor with ``robust_noise`` costs ρ(‖whitened residual‖)."""
    sd = np.array([1.0, 2.0, 0.5])
    meas = np.array([3.0, -4.0, 1.0])
    f = gtsam.GPSFactor(X(0), meas, robust_noise(gtsam.noiseModel.Diagonal.Sigmas(sd),
                                                  "cauchy", 2.0))
    v = gtsam.Values()
    v.insert(X(0), gtsam.Pose3())
    e = np.linalg.norm(meas / sd)
    assert f.error(v) == pytest.approx(weight_and_loss(np.array([e]), "cauchy", 2.0)[1][0],
                                       rel=1e-12)


@pytest.mark.parametrize("kw", [{"loss_baro": "tukey"}, {"loss_gnss_pos": "Huber"},
                                {"loss_threshold_sd": (2.0, 0.0, 2.0)}])
def test_bad_loss_settings_are_rejected(kw):
    with pytest.raises(ValueError, match="GraphConfig.loss"):
        GraphConfig(**kw)
