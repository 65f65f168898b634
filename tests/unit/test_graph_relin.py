"""graph-isam2's relinearisation of its custom interval terms (``graph.relin``): a rebuilt term
is the original at the original's point, and the due-policy picks exactly the intervals
whose keyframes or calibration moved beyond the thresholds."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest
from gtsam.symbol_shorthand import B, C, K, X

from vnav_graph.estimators.graph.isam2 import linear_factors as terms
from vnav_graph.estimators.graph.isam2 import relin as relin
from vnav_graph.estimators.graph.model import interval_factors as gf
from vnav_graph.estimators.graph.model.initial_guess import initial_states
from vnav_graph.estimators.graph.model.problem import setup
from vnav_graph.estimators.graph.settings import GraphConfig
from vnav_graph.simulation.scenario import load_scenario, simulate

M = 7  # the interval under test
ARRAYS = ("rot", "pos", "vel", "bias", "cb", "gg")  # the running arrays, in their order


@pytest.fixture(scope="module")
def problem():
    drive = simulate(load_scenario("hill-drive", duration_s=40.0), seed=3)
    P = setup(drive, GraphConfig())
    rot, pos, vel = initial_states(P)
    nk = P.n_kf
    rng = np.random.default_rng(0)
    bias = np.c_[0.02 * rng.normal(size=(nk, 3)), 1e-4 * rng.normal(size=(nk, 3))]
    arrays = {"rot": rot, "pos": pos, "vel": vel, "bias": bias,
              "cb": 0.5 * rng.normal(size=nk), "gg": np.zeros(nk)}
    g_between = np.flatnonzero((P.g_kf == -1) & P.g_use)
    gk = gf.interval_of(P.t_kf, P.g_t[g_between])
    fixes_of = [g_between[gk == k] for k in range(nk - 1)]
    return P, arrays, fixes_of


def _lin(P, a, cal, m):
    v = gtsam.Values()
    for k in (m - 1, m, m + 1):
        v.insert(X(k), gtsam.Pose3(gtsam.Rot3(a["rot"][k]), a["pos"][k]))
        v.insert(C(k), np.array([a["cb"][k]]))
        v.insert(B(k), gtsam.imuBias.ConstantBias(a["bias"][k, 0:3], a["bias"][k, 3:6]))
    v.insert(K(0), np.asarray(cal[0], float))
    return v


def _terms_of(P, a, cal, fixes_of, m, tau_sel=None):
    """Interval m's GNSS factor and baro factors, as the online pass adds them (the samples
    whose delayed time at τd ``tau_sel``, default cal's, is inside the interval)."""
    seg = np.zeros(P.n_kf, dtype=int)
    st = terms.keyframe_states(P, m, a["rot"], a["pos"], a["vel"], a["bias"], a["cb"], a["gg"])
    gcf = terms.gnss_factor(P, m, st, a["bias"], fixes_of[m])
    bt, bz = P.drive.baro.t, P.drive.baro.altitude
    tau = cal[0][1] if tau_sel is None else tau_sel
    sel = np.flatnonzero((bt - tau >= P.t_kf[m]) & (bt - tau < P.t_kf[m + 1]))
    baro = terms.baro_terms(P, m + 1, st, a["bias"], cal, seg, bt, bz, sel, P.pri)
    return seg, st, gcf, baro


def _total(factors, lin, keys):
    """Information and linear term of the sum of ``factors`` at ``lin`` over ``keys``."""
    g = gtsam.GaussianFactorGraph()
    for f in factors:
        g.push_back(f.linearize(lin))
    for key in keys:  # zero pieces: every key in the result, used or not
        d = {"x": 6, "b": 6, "c": 1, "k": 2}[chr(gtsam.Symbol(key).chr())]
        g.push_back(gtsam.HessianFactor(key, np.zeros((d, d)), np.zeros(d), 0.0))
    lam, eta = g.hessian(gtsam.Ordering(keys))
    return np.array(lam, copy=True), np.array(eta, copy=True)


def _information(f, lin, keys=None):
    """Information and linear term of ``f`` at ``lin``, over ``keys`` (default: its own)."""
    g = gtsam.GaussianFactorGraph()
    g.push_back(f.linearize(lin))
    keys = list(f.keys()) if keys is None else keys
    lam, eta = g.hessian(gtsam.Ordering(keys))
    return np.array(lam, copy=True), np.array(eta, copy=True)


def test_rebuilt_terms_equal_the_originals_at_their_point(problem):
    P, a, fixes_of = problem
    cal = {0: np.array([0.01, 0.2])}
    seg, st, gcf, baro = _terms_of(P, a, cal, fixes_of, M)
    assert gcf is not None and baro and all(m == M for m, _, _ in baro)
    book = relin.TermBook(P, seg, fixes_of)
    nf = gtsam.NonlinearFactorGraph()
    tags = book.new_terms(M, gcf, baro, st, cal, nf)
    book.record(tags, range(nf.size()))
    book.pending = np.array([M])
    nf2 = gtsam.NonlinearFactorGraph()
    tags2, removed = book.rebuild(nf2, M + 1, tuple(a[n] for n in ARRAYS), cal)
    assert sorted(removed) == list(range(nf.size()))
    # rebuilt, the interval's GNSS rows go into its baro factor: one factor
    assert [t[:2] for t in tags2] == [("gb", M)]
    assert book.relinearized == 1
    assert book.gnss_idx[M] == -1 and book.baro_idx[M] == []
    book.record(tags2, [7])
    assert book.gnss_idx[M] == 7 and book.baro_idx[M] == [7]
    lin = _lin(P, a, cal, M)
    keys = [X(M), X(M + 1), C(M), C(M + 1), K(0), B(M)]
    lam0, eta0 = _total([nf.at(i) for i in range(nf.size())], lin, keys)
    lam1, eta1 = _total([nf2.at(0)], lin, keys)
    # the 1e-9 regularisation of each information_factor (two before, one now) aside
    np.testing.assert_allclose(lam1, lam0, rtol=1e-9, atol=1e-8)
    np.testing.assert_allclose(eta1, eta0, rtol=1e-9, atol=1e-9 * np.abs(eta0).max())
    assert np.abs(lam0).max() > 1e3  # not trivially equal
    # the samples went back to the interval they came from
    np.testing.assert_array_equal(np.sort(np.concatenate([t[2] for t in tags2])),
                                  np.sort(np.concatenate([t[2] for t in tags if t[0] == "b"])))


def test_rebuilt_terms_follow_a_new_calibration(problem):
    """Rebuilt at a new (s, τd), the baro terms' information is that of the same samples'
    terms built there directly (and differs from the old one's: the rows are nonlinear in
    K); samples whose delayed time left the interval move with it."""
    P, a, fixes_of = problem
    cal0, cal1 = {0: np.array([0.0, 0.1])}, {0: np.array([0.04, 0.25])}
    seg, st, gcf, baro0 = _terms_of(P, a, cal0, fixes_of, M)
    book = relin.TermBook(P, seg, fixes_of)
    nf = gtsam.NonlinearFactorGraph()
    tags = book.new_terms(M, gcf, baro0, st, cal0, nf)
    book.record(tags, range(nf.size()))
    marked = np.zeros(0, dtype=int)
    # K moved beyond CALIB_THRESHOLD: interval M (and only the intervals with baro terms) due
    due = book.due(marked, M + 1, a["rot"], a["pos"], cal1)
    np.testing.assert_array_equal(due, [M])
    assert book.due(marked, M + 1, a["rot"], a["pos"], cal0).size == 0
    book.pending = due
    nf2 = gtsam.NonlinearFactorGraph()
    tags2, _ = book.rebuild(nf2, M + 1, tuple(a[n] for n in ARRAYS), cal1)
    _, _, _, baro1 = _terms_of(P, a, cal1, fixes_of, M, tau_sel=cal0[0][1])
    lin = _lin(P, a, cal1, M)
    i_b = [i for i, t in enumerate(tags2) if t[0] == "b"]
    assert [t[0] for t in tags2 if t[1] == M] == ["gb"]
    keys = [X(M - 1), X(M), X(M + 1), C(M - 1), C(M), C(M + 1), K(0), B(M - 1), B(M)]
    lam_r = _total([nf2.at(i) for i in range(nf2.size())], lin, keys)[0]
    lam_d = _total([f for _, _, f in baro1] + [gcf], lin, keys)[0]  # GNSS: no K in it
    lam_o = _total([nf.at(i) for i in range(nf.size())], lin, keys)[0]
    np.testing.assert_allclose(lam_r, lam_d, rtol=1e-9, atol=1e-8)
    assert np.abs(lam_o - lam_d).max() > 1e-3 * np.abs(lam_d).max()
    del i_b
    assert {t[1] for t in tags2} == {M - 1, M}  # τd 0.1 → 0.25 s: samples moved to M − 1


def test_due_picks_the_moved_intervals_only(problem):
    P, a, fixes_of = problem
    cal = {0: np.array([0.0, 0.1])}
    seg = np.zeros(P.n_kf, dtype=int)
    book = relin.TermBook(P, seg, fixes_of)
    for m in range(3, 12):
        _, st, gcf, baro = _terms_of(P, a, cal, fixes_of, m)
        nf = gtsam.NonlinearFactorGraph()
        book.record(book.new_terms(m, gcf, baro, st, cal, nf), range(nf.size()))
    rot_thr, trans_thr = GraphConfig().relinearize_typed[0:2]
    rot, pos = a["rot"].copy(), a["pos"].copy()
    pos[5] += np.array([0.0, 0.9 * trans_thr, 0.0])  # below: nothing
    rot[9] = rot[9] @ gtsam.Rot3.Expmap(np.array([0.0, 1.5 * rot_thr, 0.0])).matrix()
    marked = np.array([5, 9])
    np.testing.assert_array_equal(book.due(marked, 12, rot, pos, cal), [8, 9])
    # a move beyond the translation threshold of a keyframe iSAM2 did not mark: not checked
    pos[3] += np.array([2.0 * trans_thr, 0.0, 0.0])
    np.testing.assert_array_equal(book.due(marked, 12, rot, pos, cal), [8, 9])
    # marked, it is (interval 2 has no terms); intervals ending after k_new are not
    np.testing.assert_array_equal(book.due(np.array([3, 9]), 12, rot, pos, cal), [3, 8, 9])
    np.testing.assert_array_equal(book.due(np.array([3, 9]), 9, rot, pos, cal), [3, 8])


def test_a_reversed_calibration_step_is_halved_a_monotone_one_taken_whole(problem):
    """``LinPoints.damped_calibration``: rebuilding the baro terms at the estimate is an
    undamped Gauss-Newton step in (s, τd). Steps in one direction are taken whole; a step
    that reverses the previous rebuild's is moved half-way (the 2-cycle of τd on 218.BIN's
    touchdown, relin module)."""
    P, _, fixes_of = problem
    seg = np.zeros(P.n_kf, dtype=int)
    book = relin.TermBook(P, seg, fixes_of)
    book.points.lin_cal[[M, M + 1]] = [0.0, 0.1]  # the terms were first built at (0, 0.1)
    ms = [M, M + 1]
    c1 = book.points.damped_calibration({0: np.array([0.002, 0.3])}, ms)
    np.testing.assert_allclose(c1[0], [0.002, 0.3])  # first rebuild: the estimate
    c2 = book.points.damped_calibration({0: np.array([0.004, 0.4])}, ms)
    np.testing.assert_allclose(c2[0], [0.004, 0.4])  # same direction: whole
    assert book.points.damped == 0
    c3 = book.points.damped_calibration({0: np.array([0.006, -0.2])}, ms)
    # τd reverses (+0.1 then −0.6): half-way, −0.3 → 0.1; s goes on: whole
    np.testing.assert_allclose(c3[0], [0.006, 0.1])
    assert book.points.damped == 1
    # the estimate passed in is not changed
    cal = {0: np.array([0.006, 0.5])}
    book.points.damped_calibration(cal, ms)
    np.testing.assert_allclose(cal[0], [0.006, 0.5])


def test_gnss_chi2_in_blocks_equals_the_whole_set(problem, monkeypatch):
    # the post-solve gate's χ² is computed in blocks of fixes (memory); with blocks of 7
    # fixes, with and without the cached increments, it equals the χ² of the rows of every
    # fix at once (gnss_rows_of)
    from vnav_graph.estimators.graph.model import problem as gp

    P, a, _ = problem
    st = relin.estimate_states(P, (a["rot"], a["pos"], a["vel"], a["bias"], a["cb"], a["gg"]),
                               np.array([0.01, 0.1]))
    idx = gp.gnss_batch_idx(P)
    assert idx.size > 20
    rows = gp.gnss_rows_of(P, st, idx)  # also caches the increments at these fixes
    r = rows.r.reshape(-1, idx.size, 3)
    whole = np.sum(r**2, axis=(0, 2))
    monkeypatch.setattr(gp, "CHI2_BLOCK", 7)
    c2, dof = gp.gnss_chi2(P, st, idx)
    np.testing.assert_allclose(c2, whole, rtol=1e-12)
    assert dof == 3 * r.shape[0]
    P.g_incr = None  # without the cache: the increments per block
    c2_nc, _ = gp.gnss_chi2(P, st, idx)
    np.testing.assert_allclose(c2_nc, whole, rtol=1e-12)
