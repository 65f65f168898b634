"""``frames.ned_to_lla`` against pymap3d's ``ned2geodetic``, whose operations it repeats:
bitwise equal, over origins on the whole globe, distances from metres to thousands of
kilometres, heights below the ellipsoid, and array lengths that take numpy's vector loops
and their tails."""

from __future__ import annotations

import numpy as np
import pymap3d
import pytest

from vnav_graph.geo.frames import ned_to_lla


def _pymap3d(p: np.ndarray, o: np.ndarray) -> np.ndarray:
    lat, lon, h = pymap3d.ned2geodetic(p[:, 0], p[:, 1], p[:, 2], o[0], o[1], o[2], deg=False)
    return np.column_stack([lat, lon, h])


@pytest.mark.parametrize("n", [1, 2, 3, 7, 16, 33, 1000])
@pytest.mark.parametrize("scale", [1.0, 1e3, 1e6])
def test_bitwise_equal_to_pymap3d(n: int, scale: float) -> None:
    rng = np.random.default_rng(n + int(scale))
    for _ in range(20):
        o = np.array([rng.uniform(-1.5, 1.5), rng.uniform(-np.pi, np.pi),
                      rng.uniform(-400.0, 9000.0)])
        p = rng.normal(size=(n, 3)) * scale
        got, want = ned_to_lla(p, o), _pymap3d(p, o)
        assert got.shape == want.shape == (n, 3)
        assert np.array_equal(got, want)


def test_single_point_and_list_input() -> None:
    o = [0.7, -2.1, 120.0]
    got = ned_to_lla([10.0, -5.0, 3.0], o)
    want = _pymap3d(np.array([[10.0, -5.0, 3.0]]), np.asarray(o))
    assert got.shape == (1, 3) and np.array_equal(got, want)


def test_polar_axis_goes_through_pymap3d() -> None:
    """A point on the polar axis takes pymap3d's special branch (latitude ±π/2)."""
    o = np.array([np.pi / 2, 0.0, 0.0])
    p = np.array([[0.0, 0.0, -10.0], [5.0, 0.0, 0.0]])
    got = ned_to_lla(p, o)
    assert np.array_equal(got, _pymap3d(p, o))
    assert got[0, 0] == pytest.approx(np.pi / 2)
