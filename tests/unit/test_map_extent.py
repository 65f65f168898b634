"""The trajectory map's extent: set by the reference, widened by a bounded amount for the
estimates, and a diverging estimate named with how far it leaves the map."""

from __future__ import annotations

import numpy as np
import pytest

from vnav_graph.report.map_plot import ALLOW, MARGIN, MIN_SIZE_M, in_any, map_extent


def _square(side: float) -> np.ndarray:
    """North/east corners of a side × side square from the origin."""
    return np.array([[0.0, 0.0], [side, 0.0], [side, side], [0.0, side]])


def test_extent_is_the_reference_box_plus_margin():
    ext = map_extent(_square(1000.0), {"ekf": _square(1000.0) + 5.0})
    pad = MARGIN * 1000.0
    # the estimate stays inside the allowed growth: the box grows to include it
    assert (ext.e0, ext.n0) == pytest.approx((-pad, -pad))
    assert (ext.e1, ext.n1) == pytest.approx((1005.0 + pad, 1005.0 + pad))
    assert ext.outside == {}


def test_a_diverging_track_leaves_the_map_and_is_named():
    far = np.array([[0.0, 0.0], [0.0, 10_000.0]])  # 10 km east
    ext = map_extent(_square(1000.0), {"ekf": far, "graph-batch": _square(1000.0)})
    size = 1000.0
    assert ext.e1 == pytest.approx(size + ALLOW * size + MARGIN * size)
    assert ext.outside["ekf"] == pytest.approx(10_000.0 - ext.e1)
    assert "graph-batch" not in ext.outside


def test_a_standing_vehicle_gets_the_minimum_size_and_nan_rows_are_ignored():
    ref = np.array([[10.0, 20.0], [np.nan, np.nan], [10.0, 20.0]])
    ext = map_extent(ref, {"ekf": np.full((3, 2), np.nan)})
    assert ext.e1 - ext.e0 == pytest.approx(MIN_SIZE_M * (1 + 2 * MARGIN))
    assert ext.n1 - ext.n0 == pytest.approx(MIN_SIZE_M * (1 + 2 * MARGIN))
    assert (ext.e0 + ext.e1) / 2 == pytest.approx(20.0)
    assert ext.outside == {}


def test_in_any_closed_windows():
    t = np.array([0.0, 1.0, 2.0, 5.0, 6.0])
    np.testing.assert_array_equal(in_any(t, [(1.0, 2.0), (6.0, 7.0)]),
                                  [False, True, True, False, True])
    assert not in_any(t, []).any()
