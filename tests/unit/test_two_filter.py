"""On a linear-Gaussian problem the forward/backward two-filter combination equals the RTS
smoother (``ekf.twofilter``; Fraser & Potter 1969), and the EKF's backward drive is the
forward one played backward (``ekf.backward``)."""

from __future__ import annotations

import numpy as np

from vnav_graph.estimators.ekf import twofilter as tf


def _problem(seed: int, n_steps: int = 60):
    """Constant-acceleration model in one axis plus a random-walk bias, position measured."""
    rng = np.random.default_rng(seed)
    dt = 0.5
    f = np.array([[1.0, dt, 0.5 * dt * dt, 0.0], [0.0, 1.0, dt, 0.0], [0.0, 0.0, 1.0, 0.0],
                  [0.0, 0.0, 0.0, 1.0]])
    q = np.diag([1e-4, 1e-3, 1e-2, 1e-3])
    h = np.array([[1.0, 0.0, 0.0, 1.0], [0.0, 1.0, 0.0, 0.0]])
    r = np.diag([0.5, 0.05])
    m0, p0 = np.zeros(4), np.diag([10.0, 4.0, 1.0, 2.0])
    x = rng.multivariate_normal(m0, p0)
    z = np.empty((n_steps, 2))
    for k in range(n_steps):
        if k > 0:
            x = f @ x + rng.multivariate_normal(np.zeros(4), q)
        z[k] = h @ x + rng.multivariate_normal(np.zeros(2), r)
    return f, q, h, r, z, m0, p0


def test_two_filter_equals_rts():
    for seed in range(3):
        f, q, h, r, z, m0, p0 = _problem(seed)
        xf, pf = tf.kalman(f, q, h, r, z, m0, p0)
        xr, pr = tf.rts(f, q, xf, pf)
        yb, ybb = tf.backward_information(f, q, h, r, z)
        xc, pc = tf.combine(xf, pf, yb, ybb)
        np.testing.assert_allclose(xc, xr, rtol=1e-8, atol=1e-9)
        np.testing.assert_allclose(pc, pr, rtol=1e-8, atol=1e-11)
        # the smoother differs from the filter except at the last epoch: the test compares
        # two non-trivial answers
        assert np.max(np.abs(xr[:-1] - xf[:-1])) > 1e-2
        np.testing.assert_array_equal(xr[-1], xf[-1])


def test_backward_information_of_the_last_steps():
    """Closed form for one step: with F = I, Q = 0 and measurement z_N alone after k = N−1,
    the backward information about x_{N−1} is Hᵀ R⁻¹ H and Hᵀ R⁻¹ z_N."""
    f, _, h, r, z, _, _ = _problem(4, 2)
    eye = np.eye(4)
    yb, ybb = tf.backward_information(eye, np.zeros((4, 4)), h, r, z)
    ri = np.linalg.inv(r)
    np.testing.assert_allclose(ybb[0], h.T @ ri @ h, rtol=1e-12)
    np.testing.assert_allclose(yb[0], h.T @ ri @ z[1], rtol=1e-12)
    assert not np.any(ybb[1]) and not np.any(yb[1])
