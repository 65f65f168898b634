"""The EKF's robust update (``ekf.model.vector_update``): Huber re-weighting of the innovation
and Schmidt consider states, against their closed forms."""

from __future__ import annotations

import numpy as np
import pytest

from vnav_graph.estimators.ekf import model as km
from vnav_graph.estimators.ekf.settings import EkfConfig


def _problem(seed: int = 3) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(km.NX, km.NX))
    return a @ a.T + np.eye(km.NX), rng.normal(size=km.NX)


@pytest.mark.parametrize("y", [0.5, 3.0, -40.0])
def test_huber_scalar_update_is_the_kalman_update_with_r_over_w(y):
    """Scalar innovation ν with S = hPhᵀ + r and e = |ν|/√S: Huber's weight is w = min(1, k/e)
    and the update is the Kalman update with variance r/w: K = Ph/(hPh + r/w), δx = Kν,
    P⁺ = P − K hP. Below the threshold it is the plain update, bit for bit."""
    p, h = _problem()
    r, k = 0.7, 2.0
    s = h @ p @ h + r
    e = abs(y) / np.sqrt(s)
    w = min(1.0, k / e)
    gain = p @ h / (h @ p @ h + r / w)
    p1, dx1 = p.copy(), np.zeros(km.NX)
    ok, nis, _, w_out = km.vector_update(p1, dx1, h[None].copy(), np.array([y]),
                                         np.array([r]), 1e9, False, k, 0, 0)
    assert ok and nis == pytest.approx(e * e, rel=1e-12)
    assert w_out == pytest.approx(w, rel=1e-12)
    np.testing.assert_allclose(dx1, gain * y, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(p1, p - np.outer(gain, h @ p), rtol=1e-9, atol=1e-10)
    p2, dx2 = p.copy(), np.zeros(km.NX)
    km.vector_update(p2, dx2, h[None].copy(), np.array([y]), np.array([r]), 1e9, False, 0.0,
                     0, 0)
    if w == 1.0:  # under the threshold the loss changes nothing
        assert np.array_equal(p1, p2) and np.array_equal(dx1, dx2)
    else:  # above it the update is smaller by the closed-form ratio
        g0 = p @ h / s
        np.testing.assert_allclose(dx2, g0 * y, rtol=1e-10, atol=1e-12)
        assert np.linalg.norm(dx1) < np.linalg.norm(dx2)


def test_huber_weight_formula():
    assert km.huber_weight(1.5, 2.0) == 1.0
    assert km.huber_weight(8.0, 2.0) == pytest.approx(0.25)
    assert km.huber_weight(8.0, 0.0) == 1.0  # threshold 0: no loss


def test_consider_states_keep_estimate_and_covariance():
    """States [c0, c1) as consider states: their correction and covariance block are unchanged;
    the others get the optimal gain of the rest, K_x = P_xh/S, with P⁺_xx = P_xx − K_x S K_xᵀ."""
    p, h = _problem(5)
    r, y, c0, c1 = 0.3, 1.7, km.IATT, km.IATT + 3
    p1, dx = p.copy(), np.zeros(km.NX)
    km.consider_update(p1, dx, h.copy(), y, r, c0, c1)
    s = h @ p @ h + r
    gain = p @ h / s
    gain[c0:c1] = 0.0
    assert np.all(dx[c0:c1] == 0.0)
    np.testing.assert_allclose(dx, gain * y, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(p1[c0:c1, c0:c1], p[c0:c1, c0:c1], rtol=1e-12)
    rest = np.r_[0:c0, c1:km.NX]
    expect = p - np.outer(gain, p @ h) - np.outer(p @ h, gain) + s * np.outer(gain, gain)
    np.testing.assert_allclose(p1[np.ix_(rest, rest)], (p - np.outer(gain, h @ p))[
        np.ix_(rest, rest)], rtol=1e-9, atol=1e-10)
    np.testing.assert_allclose(p1, expect, rtol=1e-9, atol=1e-10)


def test_config_huber_thresholds_and_bad_loss():
    assert EkfConfig().huber_k() == (0.0, 0.0, 0.0)
    cfg = EkfConfig(loss_gnss_pos="huber", loss_baro="huber", loss_threshold_sd=(2.0, 3.0, 1.5))
    assert cfg.huber_k() == (2.0, 0.0, 1.5)
    with pytest.raises(ValueError, match="loss_gnss_vel"):
        EkfConfig(loss_gnss_vel="cauchy")
