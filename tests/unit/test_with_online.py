"""``estimators.base.with_online``: a causal estimator's online estimate is its trajectory, at
its covariance epochs with its covariance there, from ``info["online_from_s"]`` on."""

from __future__ import annotations

import numpy as np

from vnav_graph.estimators.base import with_online
from vnav_graph.types import Estimate, Trajectory


def _est(name: str, t_cov: np.ndarray, info: dict) -> Estimate:
    t = np.arange(0.0, 10.01, 0.5)
    lla = np.column_stack([np.zeros(t.size), np.zeros(t.size), 100.0 + t])
    cov = np.stack([np.eye(18) * (1.0 + k) for k in range(t_cov.size)])
    return Estimate(name, Trajectory(t, lla, np.zeros((t.size, 3))),
                    frozenset({"alt", "cov"}), cov=cov, t_cov=t_cov, info=info)


def test_online_is_the_trajectory_at_the_covariance_epochs_once_aligned():
    e = with_online("ekf", _est("ekf", np.arange(0.0, 10.01, 1.0), {"online_from_s": 3.0}))
    np.testing.assert_array_equal(e.online.t, np.arange(3.0, 10.01, 1.0))
    np.testing.assert_array_equal(e.online.alt, 100.0 + np.arange(3.0, 10.01, 1.0))
    # the covariance of epoch k (k = 3..10) is (1 + k)·I: taken, not interpolated
    np.testing.assert_array_equal(e.online_cov[:, 0, 0], 1.0 + np.arange(3.0, 10.01, 1.0))


def test_a_covariance_off_the_trajectory_epochs_leaves_online_cov_empty():
    e = with_online("vkf4", _est("vkf4", np.array([0.25, 1.25]), {}))
    assert e.online is e.trajectory and e.online_cov is None


def test_smoothers_and_estimates_with_their_own_online_are_unchanged():
    e = _est("ekf-rts", np.arange(0.0, 10.01, 1.0), {})
    assert with_online("ekf-rts", e) is e
    g = _est("graph-isam2", np.arange(0.0, 10.01, 1.0), {})
    assert with_online("graph-isam2", g) is g
    own = e.replace(online=e.trajectory)
    assert with_online("ekf", own) is own
