"""graph-isam2's book of Python factors (``isam2.py_factors``): a CustomFactor linearised by
the book is the factor's own linearisation, and the relinearisation rule follows iSAM2's
thresholds (closed-form rotations and offsets against the configured thresholds)."""

from __future__ import annotations

import gtsam
import numpy as np
from gtsam.symbol_shorthand import H, X

from vnav_graph.estimators.graph.isam2.py_factors import PyFactorBook
from vnav_graph.estimators.graph.model.builtin_sensors import (
    MAG_RELIN_THRESHOLD_UT,
    mag_heading_factor,
)
from vnav_graph.estimators.graph.model.extend import Collected, Variable
from vnav_graph.estimators.graph.settings import GraphConfig
from vnav_graph.geo.frames import quat_to_mat

CFG = GraphConfig()
ROT_THR, TRANS_THR = CFG.relinearize_typed[0], CFG.relinearize_typed[1]


def _rot_z(a: float) -> np.ndarray:
    return quat_to_mat(np.array([np.cos(a / 2), 0.0, 0.0, np.sin(a / 2)]))


def _book(n_kf: int = 5, k: int = 3) -> tuple[PyFactorBook, tuple, gtsam.CustomFactor]:
    f = mag_heading_factor(k, np.array([21.0, -4.0, 43.0]), 0.02, 0.05, 3.0)
    var = Variable(H(0), np.zeros(3), 3.0, relinearize_threshold=MAG_RELIN_THRESHOLD_UT)
    ext = Collected(factors=[f], ready=[k], variables={H(0): (var, np.zeros(3))},
                    prior={H(0): gtsam.PriorFactorVector(H(0), np.zeros(3),
                                                         gtsam.noiseModel.Isotropic.Sigma(3, 3.0))},
                    first={H(0): k})
    rot = np.tile(_rot_z(0.3), (n_kf, 1, 1))
    pos = np.zeros((n_kf, 3))
    arrays = (rot, pos, np.zeros((n_kf, 3)), np.zeros((n_kf, 6)), np.zeros(n_kf),
              np.zeros(n_kf))
    book = PyFactorBook(ext, CFG)
    book.now[H(0)] = np.array([0.5, -0.2, 0.1])
    return book, arrays, f


def test_built_factor_is_the_custom_factors_linearisation():
    book, arrays, f = _book()
    lcf = book.build(f, arrays)
    lin = gtsam.Values()
    lin.insert(X(3), gtsam.Pose3(gtsam.Rot3(arrays[0][3]), arrays[1][3]))
    lin.insert(H(0), book.now[H(0)])
    a_ref = f.linearize(lin).jacobian()
    a_lcf = lcf.linearize(lin).jacobian()
    # the same whitened rows (one scalar residual; sign convention of GTSAM's b = −e)
    np.testing.assert_allclose(a_lcf[0], a_ref[0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(a_lcf[1], a_ref[1], rtol=0, atol=1e-12)
    # away from the point the container is the first-order model of the factor's error:
    # e(x ⊕ δ) − (e(x) + J δ) = O(|δ|²)
    d = np.r_[1e-4, -2e-4, 3e-4, 0.0, 0.0, 0.0]
    moved = gtsam.Values()
    moved.insert(X(3), lin.atPose3(X(3)).retract(d))
    moved.insert(H(0), book.now[H(0)] + 1e-3)
    assert abs(lcf.error(moved) - f.error(moved)) < 1e-5 * max(f.error(moved), 1.0)


def test_due_follows_the_thresholds():
    book, arrays, f = _book()
    rot, pos = arrays[0], arrays[1]
    book.record([0], [7], [0])
    book.build(f, arrays)
    assert book.due(arrays).size == 0
    r0 = rot[3].copy()
    rot[3] = r0 @ _rot_z(0.5 * ROT_THR)  # below the rotation threshold
    assert book.due(arrays).size == 0
    rot[3] = r0 @ _rot_z(2.0 * ROT_THR)
    assert book.due(arrays).tolist() == [0]
    rot[3] = r0
    pos[3] = [0.0, 0.0, 2.0 * TRANS_THR]  # a pose moves as a whole (iSAM2's rule)
    assert book.due(arrays).tolist() == [0]
    pos[3] = [0.0, 0.0, 0.5 * TRANS_THR]
    assert book.due(arrays).size == 0
    h0 = book.now[H(0)].copy()
    book.now[H(0)] = h0 + [0.0, 0.6 * MAG_RELIN_THRESHOLD_UT, 0.0]
    assert book.due(arrays).size == 0
    book.now[H(0)] = h0 + [0.0, 1.5 * MAG_RELIN_THRESHOLD_UT, 0.0]
    assert book.due(arrays).tolist() == [0]


def test_rebuild_swaps_and_freeze_stops():
    book, arrays, f = _book()
    book.record([0], [7], [0])
    book.build(f, arrays)
    book.now[H(0)] = book.now[H(0)] + 2.0 * MAG_RELIN_THRESHOLD_UT
    book.pending = book.due(arrays)
    nf = gtsam.NonlinearFactorGraph()
    slots, at, removed = book.rebuild(nf, arrays)
    assert (slots, at, removed, nf.size()) == ([0], [0], [7], 1)
    assert book.due(arrays).size == 0  # not live until recorded again
    book.record(slots, [11], at)
    assert book.due(arrays).size == 0  # rebuilt at the current H(0)
    book.freeze([11])
    book.now[H(0)] = book.now[H(0)] + 5.0
    assert book.due(arrays).size == 0  # left iSAM2: never rebuilt


def test_only_book_factors_make_a_variable_linear_only():
    book, _, _ = _book()
    assert book.linear_only() == {"h"}
    f2 = gtsam.BetweenFactorVector(H(0), H(0), np.zeros(3),
                                   gtsam.noiseModel.Isotropic.Sigma(3, 1.0))
    book.ext.factors.append(f2)
    assert book.linear_only() == set()
