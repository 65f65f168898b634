"""The end of ``graph-isam2``'s online pass: the baro samples after the last keyframe, the
final rounds that make iSAM2's own estimate the smoothed optimum of the batch's model
(``relin.settle``), iSAM2's post-solve GNSS gate, and what the pass hands to the final batch
check (``OnlineResult``)."""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import gtsam
import numpy as np

from ....geo.frames import mat_to_quat
from ..model.cpp_factors import gap_factors
from ..model.extend import Collected
from ..model.problem import Problem
from ..solver.linalg import trim_heap
from . import linear_factors as terms
from . import relin
from .answers import Answers
from .setup import extra_online_of


@dataclass
class OnlineResult:
    """What the online pass hands to the final batch check (``GraphISAM2._finish``).

    est: iSAM2's estimate after the final rounds (gtsam.Values, with the keyframes that left
    its window); extra_online: the user variables after the last keyframe; t_online: when the
    last update ended (perf_counter); init: the initial states; pims: the IMU
    preintegrations of the intervals; seg: segment of each keyframe; upd_ms / brk: per-update
    timings and counts; relin_counts: the info entries of the relinearisation; gate0:
    ``P.g_use`` and ``P.g_rej_post`` before iSAM2's own post-solve gate; answers: the online
    states and covariances and the lag records."""

    P: Problem
    est: Any
    extra_online: Any
    t_online: float
    ext: Collected | None
    init: tuple[Any, Any, Any]
    pims: list[Any]
    seg: np.ndarray
    upd_ms: np.ndarray
    brk: np.ndarray
    relin_counts: dict[str, Any]
    gate0: tuple[Any, int]
    answers: Answers


def close_last(op: Any) -> None:
    """The baro samples stamped after the last keyframe whose delayed time is inside the
    span, and the last keyframe's B (a continuation of the last interval's: no IMU
    factor)."""
    P, nk, st = op.P, op.P.n_kf, op.st
    if nk < 2:
        return
    sk = terms.keyframe_states(P, nk - 2, *st.arrays, st.dg_kf)
    new_baro, op.baro_next = terms.baro_factors(P, nk - 2, sk, st.bias, st.cal, op.seg,
                                                op.book.bt, op.book.bz, op.baro_next, P.pri,
                                                last=True)
    nf = gtsam.NonlinearFactorGraph()
    nv = gtsam.Values()
    tags = op.book.new_terms(nk - 2, None, new_baro, sk, st.calibration(), nf)
    if st.b_last < nk - 1:
        st.new_bias(nv, nf, nk - 1)
    if nf.size():
        op.book.record(tags, op.isam.update(nf, nv).getNewFactorsIndices())


def finish(op: Any) -> OnlineResult:
    """The last baro samples, the final rounds and iSAM2's own post-solve GNSS gate of the
    online pass ``op`` (``online.OnlinePass``); its iSAM2 instance is released afterwards."""
    P, cfg, book, st, a = op.P, op.cfg, op.book, op.st, op.answers
    close_last(op)
    a.online[:, 6:10] = mat_to_quat(a.online_rot)  # one call (0.4 ms per keyframe)
    t_online = time.perf_counter()
    extra_online = extra_online_of(op.isam, op.isam.calculateEstimate(), op.ext)
    args = (P, op.seg, st.rw_idx, st.arrays, st.cal)
    op.pyf.skip = 1  # the final rounds check at every round, as iSAM2's forced ones
    # the online gap priors (from the online state) give way to graph-batch's (from the
    # initial states); those that left the window stay (counted)
    swap = ([], [])
    if cfg.final_rounds > 0 and st.gap_prior_idx:
        swap = (list(st.gap_prior_idx.values()),
                [gap_factors(P, k, *st.gap_states, st.a_keys(k))[2][0]
                 for k in st.gap_prior_idx])
    rounds = (relin.settle(op.isam, book, *args, pyf=op.pyf, swap=swap)
              if cfg.final_rounds > 0 else [])
    gate0 = (P.g_use.copy(), P.g_rej_post)
    if cfg.final_rounds > 0:
        # the batch's post-solve GNSS gate at iSAM2's estimate, then final rounds without
        # the rejected fixes: its own estimate keeps the fixes the batch keeps (a 15 s IMU
        # gap on hill-drive: 7 fixes the batch gated, a cost gap of 26 against the batch
        # pass with them in iSAM2)
        for _ in range(cfg.gate_rounds):
            k_cal = st.cal[int(op.seg[-1])] if st.has_baro else None
            kf_rm = relin.post_solve_gate(book, P,
                                          relin.estimate_states(P, st.arrays, k_cal))
            if not book.pending.size and not kf_rm:
                break
            rounds += relin.settle(op.isam, book, *args, tie=False, removed=kf_rm,
                                   pyf=op.pyf)
    est = op.isam.calculateBestEstimate()  # full back-substitution (no wildfire)
    if op.win is not None:  # and of the keyframes that left iSAM2
        est = op.win.complete(est)
        op.win_info = op.win.info()
        op.win = None  # its conditionals (~20 MB on a 1-hour drive) are not needed now
    # the Bayes tree is not needed by the final pass: released before it (≈ 210 MB of
    # C++ memory on a 1-hour drive, otherwise alive under the final pass's peak)
    op.isam = None
    trim_heap()  # its freed nodes are scattered over the heap: hand them back
    counts = {"isam2_relinearized": book.relinearized,
              "isam2_relinearized_factors": book.swapped_factors,
              "isam2_calibration_steps_halved": book.points.damped,
              "isam2_baro_samples_left_window": book.dropped_at_floor,
              "isam2_gnss_return_rounds": op.gate.return_rounds,
              # the extensions' CustomFactors linearised again (``py_factors``)
              "isam2_relinearized_custom": op.pyf.rebuilt,
              "baro_scale_max_abs": st.s_max if st.has_baro else None,
              "isam2_final_rounds": rounds,
              "isam2_gnss_rejected_postsolve": P.g_rej_post - gate0[1],
              # refused by the online pass's gate after its updates (``online_gate``)
              "isam2_gnss_rejected_online": op.gate.refused,
              "isam2_gate_rounds": op.gate.rounds,
              # IMU-gap re-alignment priors of the final answer that stayed the online
              # pass's (their keyframes left the window before the final rounds)
              "isam2_gap_priors_online": int(np.sum(P.gap)) - len(swap[0]),
              **op.win_info,
              "final_rounds_s": time.perf_counter() - t_online}
    return OnlineResult(P, est, extra_online, t_online, op.ext, op.init, st.pims, op.seg,
                        op.upd_ms, op.brk, counts, gate0, a)
