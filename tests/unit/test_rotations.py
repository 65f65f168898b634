"""The shared rotation kernels (vnav_graph.nav.rotations) against closed forms and against the
vectorised numpy/scipy versions of vnav_graph.geo.frames."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from vnav_graph.geo.frames import quat_to_mat, rph_to_quat, skew
from vnav_graph.nav import rotations as rot
from vnav_graph.nav.levelling import coarse_level


@pytest.fixture
def rng():
    return np.random.default_rng(7)


def test_skew_and_cross(rng):
    for _ in range(20):
        a, b = rng.normal(size=3), rng.normal(size=3)
        np.testing.assert_allclose(rot.cross3(a, b), np.cross(a, b), atol=1e-15)
        np.testing.assert_allclose(rot.skew3(a) @ b, np.cross(a, b), atol=1e-15)
        np.testing.assert_array_equal(rot.skew3(a), skew(a))


def test_exponentials_match_scipy(rng):
    for scale in (1e-12, 1e-7, 0.3, 3.0):
        phi = rng.normal(size=3) * scale
        ref = Rotation.from_rotvec(phi)
        np.testing.assert_allclose(rot.so3_exp(phi), ref.as_matrix(), atol=1e-14)
        q = rot.quat_exp(phi)
        np.testing.assert_allclose(rot.quat_to_dcm(q), ref.as_matrix(), atol=1e-14)
        np.testing.assert_allclose(np.linalg.norm(q), 1.0, atol=1e-15)


def test_quaternion_product_composes_rotations(rng):
    p, q = rot.quat_exp(rng.normal(size=3)), rot.quat_exp(rng.normal(size=3))
    np.testing.assert_allclose(rot.quat_to_dcm(rot.quat_mul(p, q)),
                               rot.quat_to_dcm(p) @ rot.quat_to_dcm(q), atol=1e-14)


def test_rpy_quat_matches_the_vectorised_twin(rng):
    rph = np.column_stack([rng.uniform(-3, 3, 30), rng.uniform(-1.5, 1.5, 30),
                           rng.uniform(-3, 3, 30)])
    ref = rph_to_quat(rph)
    for k in range(len(rph)):
        q = rot.rpy_quat(*rph[k])
        q = q if q[0] >= 0 else -q  # same rotation; frames.rph_to_quat returns w >= 0
        np.testing.assert_allclose(q, ref[k], atol=1e-14)
        np.testing.assert_allclose(rot.quat_to_dcm(q), quat_to_mat(ref[k:k + 1])[0],
                                   atol=1e-14)
        assert rot.yaw_of(q) == pytest.approx(rph[k, 2], abs=1e-12)


def test_coarse_level_inverts_gravity(rng):
    g = 9.80665
    for _ in range(20):
        roll, pitch = rng.uniform(-1.2, 1.2), rng.uniform(-1.2, 1.2)
        c_nb = rot.quat_to_dcm(rot.rpy_quat(roll, pitch, rng.uniform(-3, 3)))
        f_b = c_nb.T @ np.array([0.0, 0.0, -g])  # at rest: f = −g, NED (g down)
        assert coarse_level(f_b) == pytest.approx((roll, pitch), abs=1e-12)


def test_dcm_to_quat_inverts_quat_to_dcm_on_every_branch():
    # random rotations plus angles near π about each axis (the branches where 1 + tr is
    # small and the largest diagonal element leads Shepperd's method)
    rng = np.random.default_rng(5)
    qs = list(Rotation.random(200, random_state=rng).as_quat(scalar_first=True))
    for axis in np.eye(3):
        for ang in (np.pi - 1e-3, np.pi, 0.5):
            qs.append(np.r_[np.cos(ang / 2), np.sin(ang / 2) * axis])
    qs.append(np.array([1.0, 0.0, 0.0, 0.0]))
    for q in qs:
        q = q * np.sign(q[0]) if q[0] != 0 else q
        back = rot.dcm_to_quat(rot.quat_to_dcm(q))
        assert back[0] >= 0.0
        # the same rotation (q and −q are one rotation when w = 0)
        assert abs(abs(back @ q) - 1.0) < 1e-12
        np.testing.assert_allclose(rot.quat_to_dcm(back), rot.quat_to_dcm(q), atol=1e-14)
        into = np.empty((3, 3))
        rot.quat_to_dcm_into(q, into)
        np.testing.assert_array_equal(into, rot.quat_to_dcm(q))
