"""``graph.check_jacobians``: an extension factor's Jacobians against central differences,
and a wrong Jacobian shape caught in Python before GTSAM sees it."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import V, X

from vnav_graph.estimators.graph import check_jacobians


def _good(this, values, h):
    """Position of X(0) plus the vector V(0): Jacobians [R | 0] via Pose3.translation."""
    p = values.atPose3(this.keys()[0])
    hp = np.zeros((3, 6)) if h is not None else None
    e = p.translation(hp) + values.atVector(this.keys()[1])
    if h is not None:
        h[0], h[1] = hp, np.eye(3)
    return e


def _values():
    vals = gtsam.Values()
    vals.insert(X(0), gtsam.Pose3(gtsam.Rot3.Ypr(0.3, -0.2, 0.1), np.array([1.0, 2.0, 3.0])))
    vals.insert(V(0), np.array([0.1, 0.2, 0.3]))
    return vals


def test_right_jacobians_pass_and_a_wrong_one_is_named():
    model = gtsam.noiseModel.Isotropic.Sigma(3, 0.5)
    ok = check_jacobians(gtsam.CustomFactor(model, [X(0), V(0)], _good), _values(),
                         error_func=_good)
    assert ok.ok and max(ok.max_error.values()) < 1e-8
    # whitened: the analytic block is the Jacobian divided by σ
    np.testing.assert_allclose(ok.analytic["v0"], np.eye(3) / 0.5, atol=1e-12)

    def scaled(this, values, h):
        e = _good(this, values, h)
        if h is not None:
            h[1] = 2.0 * np.eye(3)
        return e
    bad = check_jacobians(gtsam.CustomFactor(model, [X(0), V(0)], scaled), _values())
    assert not bad.ok and bad.max_error["v0"] == pytest.approx(1.0, rel=1e-6)
    assert str(bad).startswith("Jacobian of v0 differs from central differences by 1")


def test_a_wrong_shape_is_one_line_not_a_crash():
    def wrong(this, values, h):
        if h is not None:
            h[0] = np.eye(2)
        return values.atVector(this.keys()[0])
    vals = gtsam.Values()
    vals.insert(V(0), np.zeros(3))
    f = gtsam.CustomFactor(gtsam.noiseModel.Isotropic.Sigma(3, 1.0), [V(0)], wrong)
    with pytest.raises(ValueError, match=r"Jacobian of v0 has shape \(2, 2\), expected "
                                         r"\(3, 3\)"):
        check_jacobians(f, vals, error_func=wrong)
