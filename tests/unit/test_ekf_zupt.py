"""The ekf's zero-velocity update (``ekf.updates.zupt_rows`` through ``ekf.updates.update_zupt``)
against the closed-form Kalman update on a known covariance."""

from __future__ import annotations

import numpy as np
from scipy.stats import chi2

from vnav_graph.estimators.ekf import model as km
from vnav_graph.estimators.ekf.updates import update_zupt, zupt_rows

GATE = float(chi2.ppf(0.9995, 3))


def _prior() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """P with velocity variances pv, each velocity axis correlated (c) with its position axis
    only; the nominal velocity vm."""
    p = np.eye(km.NX) * 1e-2
    pv = np.array([0.04, 0.09, 0.01])
    c = np.array([0.05, -0.02, 0.0])
    for a in range(3):
        p[km.IVEL + a, km.IVEL + a] = pv[a]
        p[km.IPOS + a, km.IPOS + a] = 1.0
        p[km.IPOS + a, km.IVEL + a] = p[km.IVEL + a, km.IPOS + a] = c[a]
    return p, pv, c


def test_zupt_update_closed_form() -> None:
    p, pv, c = _prior()
    pos_var = np.diag(p)[km.IPOS:km.IPOS + 3].copy()
    vm = np.array([0.3, -0.2, 0.1])  # the filter's velocity while the vehicle stands
    sd = 0.05
    y, hm, r, mm = zupt_rows(vm, sd)
    assert mm == 3
    np.testing.assert_array_equal(y[:3], vm)
    np.testing.assert_array_equal(r[:3], sd**2)
    dx = np.zeros(km.NX)
    inn = np.full((1, 3), np.nan)
    rej = np.zeros(1, dtype=bool)
    update_zupt(p, dx, hm[:3].copy(), y, r, GATE, inn, rej, 0)
    assert not rej[0]
    rv = sd**2
    # independent axes: per axis the scalar Kalman update with H = e_v, S = pv + R
    np.testing.assert_allclose(np.diag(p)[km.IVEL:km.IVEL + 3], pv * rv / (pv + rv),
                               rtol=1e-12)
    np.testing.assert_allclose(np.diag(p)[km.IPOS:km.IPOS + 3], pos_var - c**2 / (pv + rv),
                               rtol=1e-12)
    np.testing.assert_allclose(dx[km.IVEL:km.IVEL + 3], pv / (pv + rv) * vm, rtol=1e-12)
    np.testing.assert_allclose(dx[km.IPOS:km.IPOS + 3], c / (pv + rv) * vm, rtol=1e-12)
    np.testing.assert_allclose(inn[0], -vm / np.sqrt(pv + rv), rtol=1e-12)


def test_zupt_contradicted_by_the_velocity_is_refused() -> None:
    # 2 m/s against σ ≤ 0.3 m/s: NIS ≈ 100 ≫ the χ²₃ gate; P and dx untouched
    p, _, _ = _prior()
    p0 = p.copy()
    y, hm, r, _ = zupt_rows(np.array([2.0, 0.0, 0.0]), 0.05)
    dx = np.zeros(km.NX)
    inn = np.full((1, 3), np.nan)
    rej = np.zeros(1, dtype=bool)
    update_zupt(p, dx, hm[:3].copy(), y, r, GATE, inn, rej, 0)
    assert rej[0]
    np.testing.assert_array_equal(p, p0)
    assert not dx.any()
