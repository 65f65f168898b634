"""Relinearisation of ``graph-isam2``'s custom interval terms.

The baro samples and GNSS fixes between keyframes enter iSAM2 as ``LinearContainerFactor``s
built in numpy (``terms``): a fixed quadratic around the point where they were built (the
new keyframe at its IMU prediction). iSAM2 relinearises its own C++ factors but cannot
relinearise these, so :class:`TermBook` does it the way iSAM2 does for its factors: it keeps
every term's factor index and linearisation point (``lin_points.LinPoints``), and after each
update checks the terms whose variables iSAM2 has just marked (relinearised, or touched by
new factors). A term is due when its keyframes moved beyond the rotation/translation
thresholds iSAM2 uses (``GraphConfig.relinearize_typed``, or the scalar threshold), or its
segment's baro calibration K = (s, τd) beyond ``lin_points.CALIB_THRESHOLD`` since it was
built. Due terms are rebuilt
at the current estimate and swapped in at the next update (``removeFactorIndices``), all
factors of an interval at once; robust losses get fresh IRLS weights there.

Why only rotation, translation and K: the rows are linear in the accelerometer bias, the baro
bias and the GNSS height error; the velocity only enters through the Coriolis term of the
interpolant (2Ω×δv ≈ 7e-5 m/s² per m/s). Rotation turns the lever arm and the IMU increments;
translation moves the robust weights; (1 + s)·h and h(t_s − τd) are bilinear / nonlinear in K
(a linearisation error of δs·δh and ½·a_up·δτ²).

A baro sample stays with the interval it was first assigned to unless a rebuild at a new τd
puts its delayed time into another interval; it then moves to that interval's terms.

``settle``: the final rounds after the last keyframe, which make iSAM2's own estimate the
smoothed optimum of the batch's model (``isam2`` module docstring, ``docs/graph.md``).
"""

from __future__ import annotations

from typing import Any

import gtsam
import numpy as np
from gtsam.symbol_shorthand import A, B, C, G, K, V, X

from ..model import interval_factors as gf
from ..model.problem import Problem, nav_accel, noise, post_solve_rejections
from . import linear_factors as terms
from .lin_points import LinPoints

# σ of (s, τd) between neighbouring segments in the final rounds: one calibration, the
# batch's model (the random walks of the online pass are removed)
TIE_SD = (1e-6, 1e-5)
_KEY_BITS = 56
_IDX_MASK = (1 << _KEY_BITS) - 1
_X, _B = ord("x"), ord("b")


def split_keys(arr: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The character (as its code) and index of each GTSAM symbol key of ``arr`` (uint64)."""
    return ((arr >> np.uint64(_KEY_BITS)).astype(int),
            (arr & np.uint64(_IDX_MASK)).astype(np.int64))


def marked_keyframes(keys: Any) -> np.ndarray:
    """Keyframe indices of the X/B keys among an ``ISAM2Result``'s marked keys."""
    arr = np.fromiter(keys, dtype=np.uint64)
    if arr.size == 0:
        return np.zeros(0, dtype=int)
    ch, idx = split_keys(arr)
    return np.unique(idx[(ch == _X) | (ch == _B)])


class TermBook:
    """Factor indices of one pass's interval terms and their linearisation points
    (``points``); picks the due ones and rebuilds them (module docstring)."""

    def __init__(self, P: Problem, seg: np.ndarray, fixes_of: list[np.ndarray],
                 dg: Any = None) -> None:
        """``dg``: the gravity anomaly at each keyframe (``linear_factors.keyframe_states``),
        filled as the pass goes."""
        self.P = P
        self.seg = seg
        self.fixes_of = fixes_of
        baro = P.drive.baro
        self.bt = baro.t if baro is not None else np.zeros(0)  # the baro samples
        self.bz = baro.altitude if baro is not None else np.zeros(0)
        self.dg = dg
        n = max(P.n_kf - 1, 0)
        self.gnss_idx = np.full(n, -1, dtype=np.int64)
        self.baro_idx: list[list[int]] = [[] for _ in range(n)]
        self.baro_of: list[list[np.ndarray]] = [[] for _ in range(n)]
        self.points = LinPoints(P, seg)
        self.pending = np.zeros(0, dtype=int)
        # iSAM2 indices of each keyframe fix's factors (fix index → indices; ``record_fixes``)
        self.kf_fix_idx: dict[int, list[int]] = {}
        self.relinearized = 0  # interval terms rebuilt and swapped in
        self.swapped_factors = 0  # iSAM2 factors removed by those swaps
        # baro samples left out of a rebuild: their delayed time moved before the window
        self.dropped_at_floor = 0
        # with a window (``graph.window``): the oldest keyframe and segment still in iSAM2;
        # intervals before ``floor`` were marginalised and are never rebuilt
        self.floor = 0
        self.first_seg = 0

    def freeze(self, floor: int, first_seg: int, deleted: list[int]) -> None:
        """Keyframes before ``floor`` (segments before ``first_seg``) left iSAM2 with its
        factors ``deleted``: their intervals' terms are no longer iSAM2's to swap."""
        self.gnss_idx[:floor] = -1
        for m in range(self.floor, min(floor, len(self.baro_idx))):
            self.baro_idx[m], self.baro_of[m] = [], []
        gone = set(deleted)
        self.kf_fix_idx = {i: v for i, v in self.kf_fix_idx.items()
                           if not gone.issuperset(v)}
        self.floor, self.first_seg = floor, first_seg

    # -- bookkeeping -----------------------------------------------------------------------

    def record(self, tags: list[tuple[Any, ...]], new_idx: Any) -> None:
        """Factor indices of the terms just added: ``tags[i]`` describes the i-th new factor
        of the update (``("g", m)`` or ``("b", m, samples)``)."""
        for tag, idx in zip(tags, new_idx, strict=False):
            if tag[0] in ("g", "gb"):  # "gb": GNSS and baro of the interval in one factor
                self.gnss_idx[tag[1]] = int(idx)
            if tag[0] in ("b", "gb"):
                self.baro_idx[tag[1]].append(int(idx))
                self.baro_of[tag[1]].append(tag[2])

    def record_fixes(self, fix_at: list[tuple[int, int]], new_idx: Any, offset: int) -> None:
        """Factor indices of keyframe fixes just added: ``fix_at`` holds (fix index, position
        in the update's graph after its first ``offset`` factors)."""
        for i, at in fix_at:
            self.kf_fix_idx.setdefault(i, []).append(int(new_idx[offset + at]))

    def new_terms(self, m_g: int, gcf: Any, baro: list[tuple[int, np.ndarray, Any]],
                  st: gf.KeyframeStates, cal: dict[int, Any] | None,
                  nf: Any) -> list[tuple[Any, ...]]:
        """Add the update's new terms to ``nf``; their tags, in order."""
        tags: list[tuple[Any, ...]] = []
        if gcf is not None:
            nf.add(gcf)
            tags.append(("g", m_g))
            self.points.note(m_g, st, None)
        for m, sel, f in baro:
            nf.add(f)
            tags.append(("b", m, sel))
            self.points.note(m, st, cal)
        return tags

    def drop_fixes(self, rej: np.ndarray, ms: Any = None) -> tuple[np.ndarray, list[int]]:
        """Take the refused fixes ``rej`` out of their intervals' terms (``fixes_of``; ``ms``:
        the intervals that may hold them, default every one); returns the intervals whose
        GNSS term must be rebuilt and the iSAM2 indices of the refused keyframe fixes'
        factors, to remove."""
        pend = []
        for m in range(len(self.fixes_of)) if ms is None else ms:
            f = self.fixes_of[m]
            if f.size and (drop := np.isin(f, rej)).any():
                self.fixes_of[m] = f[~drop]
                pend.append(m)
        P = self.P
        kf_rm = [j for i in rej[P.g_kf[rej] >= 0] for j in self.kf_fix_idx.pop(int(i), [])]
        return np.asarray(pend, dtype=int), kf_rm

    # -- policy ----------------------------------------------------------------------------

    def due(self, marked: np.ndarray, k_new: int, rot: Any, pos: Any,
            cal: dict[int, Any] | None, all_segments: bool = False) -> np.ndarray:
        """The intervals to rebuild from ``floor`` on (``LinPoints.due``)."""
        return self.points.due(marked, k_new, rot, pos, cal, self.floor, all_segments)

    # -- rebuilding ------------------------------------------------------------------------

    def rebuild(self, nf: Any, k: int, arrays: tuple[Any, ...], cal: dict[int, Any] | None
                ) -> tuple[list[tuple[Any, ...]], list[int]]:
        """Rebuild the pending intervals' terms at the running arrays (rot, pos, vel, bias,
        cb, gg: the current estimate; keyframe k+1: its prediction) into ``nf``; returns
        their tags and the indices of the factors they replace. Samples whose delayed time
        moved past keyframe k+1 are clipped into interval k, as when they first entered."""
        ks = [int(m) for m in self.pending if self.floor <= m < k + 1]
        self.pending = np.zeros(0, dtype=int)
        if not ks:
            return [], []
        P = self.P
        st = terms.keyframe_states(P, ks, *arrays, self.dg)
        bias = arrays[3]
        tags: list[tuple[Any, ...]] = []
        removed: list[int] = []
        samples = []
        g_ks = [m for m in ks if self.gnss_idx[m] >= 0]
        # with a baro (and no GNSS error state: other keys) an interval's GNSS rows go
        # into its baro factor: one factor per rebuilt interval
        merge = cal is not None and P.gm is None
        extra: dict[int, Any] = {}
        if merge:
            g_rows = terms.gnss_interval_rows(P, g_ks, st, [self.fixes_of[m] for m in g_ks])
            extra = {m: r for m, r in zip(g_ks, g_rows, strict=True) if r is not None}
        else:
            for m, f in zip(g_ks, terms.gnss_factors(P, g_ks, st, bias,
                                                      [self.fixes_of[m] for m in g_ks]),
                            strict=True):
                nf.add(f)
                tags.append(("g", m))
        for m in g_ks:
            removed.append(int(self.gnss_idx[m]))
            self.gnss_idx[m] = -1
        if cal is not None:  # before the intervals' points are cleared below
            cal = self.points.damped_calibration(cal, ks)
        for m in ks:
            if self.baro_idx[m]:
                removed.extend(self.baro_idx[m])
                samples.extend(self.baro_of[m])
                self.baro_idx[m], self.baro_of[m] = [], []
            self.points.clear(m)
        baro_ms: set[int] = set()
        if (samples or extra) and cal is not None:
            sel = np.sort(np.concatenate(samples)) if samples else np.zeros(0, dtype=int)
            n_in = 0
            for m, s_m, f in terms.baro_terms(P, k, st, bias, cal, self.seg, self.bt, self.bz,
                                              sel, P.pri, extra=extra, floor=self.floor):
                n_in += s_m.size
                nf.add(f)
                tags.append(("gb" if m in extra else "b", m, s_m))
                baro_ms.add(m)
            self.dropped_at_floor += sel.size - n_in
        for m in sorted(set(ks) | baro_ms):
            # a sample that moved into an interval not rebuilt here leaves its point alone
            self.points.note(m, st, cal if m in baro_ms else None)
        removed = sorted(set(removed))  # a merged factor is both an interval's GNSS and baro
        self.relinearized += len(ks)
        self.swapped_factors += len(removed)
        return tags, removed


def read_states(est: Any, keys_k: Any, arrays: tuple[Any, ...], P: Problem,
                b_last: int | None = None) -> None:
    """The states of keyframes ``keys_k`` in ``est`` (X, V, B, and C / G when the problem has
    them) into the running arrays (rot, pos, vel, bias, cb, gg). ``b_last``: the last B(k)
    iSAM2 holds (B(k) enters with interval k); a later keyframe's bias is B(b_last)'s."""
    if _read_bulk(est, keys_k, arrays, P, b_last):
        return
    rot, pos, vel, bias, cb, gg = arrays
    has_baro, has_gm = P.drive.baro is not None, P.gm is not None
    for k in keys_k:
        pose = est.atPose3(X(k))
        rot[k] = pose.rotation().matrix()
        pos[k] = pose.translation()
        vel[k] = est.atVector(V(k))
        if b_last is None or k <= b_last:
            bias[k] = est.atConstantBias(B(k)).vector()
        else:
            bias[k] = bias[b_last]
        if has_baro:
            cb[k] = est.atVector(C(k))[0]
        if has_gm:
            g = est.atVector(G(k))
            gg[k] = g[0] if gg.ndim == 1 else g


def _read_bulk(est: Any, keys_k: Any, arrays: tuple[Any, ...], P: Problem,
               b_last: int | None) -> bool:
    """``read_states`` when ``est`` holds exactly ``state_keys(keys_k)`` (an update's
    read-back): poses and vectors copied out in one call per type (GTSAM's
    ``utilities.extract*``, in key order: the keyframes' order), instead of ~7 calls per
    keyframe. False (nothing read) for any other ``est``."""
    keys_k = np.asarray(keys_k, dtype=int)
    n = keys_k.size
    has_baro, has_gm = P.drive.baro is not None, P.gm is not None
    n_b = int(np.sum(keys_k <= b_last)) if b_last is not None else n
    if n == 0 or est.size() != n * (2 + has_baro + has_gm) + n_b:
        return False
    rot, pos, vel, bias, cb, gg = arrays
    poses = gtsam.utilities.extractPose3(est)
    rot[keys_k] = poses[:, 0:9].reshape(n, 3, 3)
    pos[keys_k] = poses[:, 9:12]
    vel[keys_k] = gtsam.utilities.extractVectors(est, "v")
    for k in keys_k[:n_b]:
        bias[k] = est.atConstantBias(B(int(k))).vector()
    for k in keys_k[n_b:]:
        bias[k] = bias[b_last]
    if has_baro:
        cb[keys_k] = gtsam.utilities.extractVectors(est, "c")[:, 0]
    if has_gm:
        g = gtsam.utilities.extractVectors(est, "g")
        gg[keys_k] = g[:, 0] if gg.ndim == 1 else g
    return True


def state_keys(keys_k: Any, P: Problem, b_last: int | None = None) -> Any:
    """The keys ``read_states`` reads for keyframes ``keys_k`` (``b_last``: see there)."""
    has_baro, has_gm = P.drive.baro is not None, P.gm is not None
    return gtsam.KeyVector([kk for k in keys_k for kk in
                            ([X(k), V(k)] + ([B(k)] if b_last is None or k <= b_last else [])
                             + ([C(k)] if has_baro else []) + ([G(k)] if has_gm else []))])


def settle(isam: Any, book: TermBook, P: Problem, seg: Any, rw_idx: list[int],
            arrays: tuple[Any, ...], cal: dict[int, Any], tie: bool = True,
            removed: list[int] | None = None, pyf: Any = None,
            swap: tuple[list[int], list[Any]] = ([], [])) -> list[list[int]]:
    """Final rounds after the last keyframe, so that iSAM2's own estimate is the smoothed
    optimum of the batch's model: the segments' (s, τd) and accelerometer scale factors are
    tied into one (their random walks removed, ``TIE_SD`` between neighbours), then
    forced-relinearisation updates in which every custom term beyond the thresholds is
    rebuilt, until nothing is (at most
    ``cfg.final_rounds``); ``pyf``: the extensions' ``py_factors.PyFactorBook``, whose due
    factors are rebuilt in the same rounds; ``swap``: factor indices removed and factors
    added in the first round (the online gap priors and graph-batch's). Returns per round
    [terms rebuilt, variables iSAM2 relinearised]."""
    cfg = P.cfg
    n_seg = int(seg[-1]) + 1
    nf = gtsam.NonlinearFactorGraph()
    removed = list(removed or [])
    nk = P.n_kf
    everything = np.arange(book.floor, nk)  # the keyframes iSAM2 holds
    j0 = book.first_seg
    has_baro = P.drive.baro is not None
    rot, pos = arrays[0:2]
    tags: list[tuple[Any, ...]] = []
    if book.pending.size:  # due intervals (the post-solve gate's) rebuilt in the first round
        # (first in the update: ``record`` pairs the tags with the first new indices)
        tags, more = book.rebuild(nf, nk - 2, arrays, cal if has_baro else None)
        removed = sorted(set(removed) | set(more))
    if tie and n_seg > 1 and (has_baro or P.ka is not None):
        for j in range(j0 + 1, n_seg):
            if has_baro:
                nf.add(gtsam.BetweenFactorVector(K(j - 1), K(j), np.zeros(2), noise(TIE_SD)))
            if P.ka is not None:  # the segments' accelerometer scale factors A(j) too
                nf.add(gtsam.BetweenFactorVector(A(j - 1), A(j), np.zeros(3),
                                                 noise([TIE_SD[0]] * 3)))
        removed = sorted(set(removed) | set(rw_idx))
    for f in swap[1]:
        nf.add(f)
    removed = sorted(set(removed) | set(swap[0]))
    out: list[list[int]] = []
    removed = sorted(set(removed) | set(pyf.rebuild_into(nf, 0, arrays) if pyf is not None
                                         else []))
    for r in range(cfg.final_rounds):
        # an empty constraint map: plain COLAMD for the re-elimination (iSAM2's default
        # puts every key of the new factors, nearly all here, last: one huge root clique)
        ures = isam.update(nf, gtsam.Values(), removed, gtsam.KeyGroupMap(), None, None, True)
        book.record(tags, ures.getNewFactorsIndices())
        n_py = len(pyf.new[0]) if pyf is not None else 0
        if pyf is not None:
            pyf.record_new(ures.getNewFactorsIndices(), 0)
        n_relin = int(ures.getVariablesRelinearized())
        est = isam.calculateBestEstimate()
        read_states(est, everything, arrays, P)
        if pyf is not None:
            pyf.read_ext(est)
            pyf.pending = pyf.due(arrays)
        if has_baro:
            for j in range(j0, n_seg):
                cal[j] = est.atVector(K(j))
        book.pending = book.due(everything, nk - 1, rot, pos, cal if has_baro else None,
                                all_segments=True)
        out.append([len(tags) + n_py, n_relin])
        py_due = pyf is not None and pyf.pending.size
        if (not book.pending.size and not py_due and n_relin == 0) \
                or r == cfg.final_rounds - 1:
            break
        nf = gtsam.NonlinearFactorGraph()
        tags, removed = book.rebuild(nf, nk - 2, arrays, cal if has_baro else None)
        removed = sorted(set(removed) | set(pyf.rebuild_into(nf, 0, arrays) if pyf is not None
                                             else []))
    return out


def post_solve_gate(book: TermBook, P: Problem, states: Any) -> list[int]:
    """The batch's post-solve GNSS gate (``solve.gauss_newton``) at iSAM2's estimate, so
    that its own smoothed estimate uses the fixes the batch would keep: fixes whose χ² at
    ``states`` (``KeyframeStates`` of the estimate) exceeds the gate are marked unused
    (``P.g_use``, ``P.g_rej_post``), their intervals are set due (``book.pending``) so the
    next final rounds rebuild them without the fix; returns the iSAM2 factor indices of the
    rejected keyframe fixes (``TermBook.kf_fix_idx``), to be removed. Empty when nothing (or
    everything) fails."""
    rej = post_solve_rejections(P, states)
    if book.floor > 0 and rej.size:
        # fixes of keyframes that left iSAM2 (``graph.window``) are in its marginal: kept
        frozen = np.where(P.g_kf[rej] >= 0, P.g_kf[rej],
                          gf.interval_of(P.t_kf, P.g_t[rej])) < book.floor
        P.g_use[rej[frozen]] = True
        P.g_rej_post -= int(frozen.sum())
        rej = rej[~frozen]
    if not rej.size:
        return []
    pend, kf_rm = book.drop_fixes(rej)
    book.pending = np.unique(np.r_[book.pending, pend]).astype(int)
    return kf_rm


def estimate_states(P: Problem, arrays: tuple[Any, ...], k_cal: Any) -> gf.KeyframeStates:
    """``KeyframeStates`` of the running arrays (iSAM2's estimate as ``settle`` last read it)
    with one (s, τd) ``k_cal``: what ``problem.states_from_values`` gives for the batch's
    values at that estimate, without building them."""
    rot, pos, vel, bias, cb, gg = arrays
    nk = P.n_kf
    has_baro = P.drive.baro is not None
    acc = nav_accel(P, pos, vel)
    s, tau = ((np.full(nk, float(k_cal[0])), np.full(nk, float(k_cal[1]))) if has_baro
              else (np.zeros(nk), np.zeros(nk)))
    return gf.KeyframeStates(rot, pos, vel, bias[:, 0:3], cb if has_baro else np.zeros(nk),
                             s, tau, acc, gg if P.gm is not None else None)
