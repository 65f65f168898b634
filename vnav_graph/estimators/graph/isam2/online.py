"""The online pass of ``graph-isam2`` (``isam2``): one iSAM2 update per keyframe, then the
final rounds.

``OnlinePass`` holds what the updates share: the iSAM2 instance, the running linearisation
point (``states.RunningStates``: keyframe states as last estimated, the segments' (s, τd)
and k_a), the term book of the interval baro / GNSS terms (``relin.TermBook``), the window
of kept keyframes, the GNSS returns and gate (``online_gate.OnlineGate``), the answers
(``answers.Answers``) and the per-update timings. ``update(k)`` creates keyframe k + 1: its
IMU (or gap) factors, its GNSS fixes, the interval terms due for relinearisation and the new
ones, one ``isam.update`` and the read-back of the keyframes iSAM2 touched. ``finish()``
adds the baro samples after the last keyframe, runs the final rounds (``relin.settle``) and
the post-solve GNSS gate, and returns iSAM2's estimate (``OnlineResult``). The design and its
measurements: the module docstring of ``isam2`` and ``docs/graph.md``.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

import gtsam
import numpy as np

from ....types import Drive
from ..model.cpp_factors import PRIOR_ATT_SD, build_batch_graph
from ..model.extend import Collected, GraphExtension, collect, make_view
from ..model.initial_guess import initial_states
from ..model.problem import Problem, setup
from ..settings import GraphConfig
from . import linear_factors as terms
from . import relin
from .answers import Answers
from .final_rounds import OnlineResult, finish
from .online_gate import OnlineGate
from .py_factors import PyFactorBook
from .setup import (
    first_keyframe,
    interval_fixes,
    isam2_params,
    newest_last,
    segments,
    update_error,
)
from .states import RunningStates
from .window import Window

DIVERGED_SPEED = 1e4  # m/s: an online velocity above this means the solution diverged


class OnlinePass:
    """One online pass of graph-isam2 over ``drive`` with ``cfg`` (``robust``: the retry's
    iSAM2 parameters). ``run()`` does the whole pass; ``update(k)`` is one keyframe."""

    def __init__(self, drive: Drive, cfg: GraphConfig, robust: bool,
                 extensions: Sequence[GraphExtension], P: Problem = None,
                 init: tuple[Any, Any, Any] | None = None, causal: bool = False) -> None:
        """``P``, ``init``: the problem and initial states when already set up (a pass
        started again). ``causal``: keyframe 0 from ``P.start0`` (the causal start, its yaw
        prior ``start0.yaw_sd``) instead of the initial states' keyframe 0."""
        P = self.P = setup(drive, cfg) if P is None else P
        self.cfg = cfg
        self.init = initial_states(P) if init is None else init
        nk = P.n_kf
        self.seg = seg = segments(P)
        self.ext: Collected | None = None
        if extensions:
            # the view is the batch's: the same initial values (no IMU factors needed)
            vals_i = build_batch_graph(P, *self.init, None, P.pri, np.zeros(nk, dtype=int))[1]
            self.ext = collect(extensions, make_view(P, vals_i))
        # the extensions' CustomFactors: linearised here, relinearised by the book
        self.pyf = PyFactorBook(self.ext or Collected(), cfg)
        self.isam: Any = gtsam.ISAM2(isam2_params(cfg, robust, self.ext,
                                                  self.pyf.linear_only()))
        st = self.st = RunningStates(P, seg, self.init, causal)
        graph0, vals0, fix_at0 = first_keyframe(
            P, st.rot[0], st.pos[0], st.vel[0], st.cal[0],
            P.start0.yaw_sd if causal else PRIOR_ATT_SD[2])
        self._add_ext(0, graph0, vals0)
        new0 = self.isam.update(graph0, vals0).getNewFactorsIndices()
        self.pyf.record_new(new0, 0)
        self.book = relin.TermBook(P, seg, interval_fixes(P), st.dg_kf)
        self.win = (Window(P, seg, cfg.isam2_window_s, self.ext)
                    if cfg.isam2_window_s is not None else None)
        self.win_info: dict[str, Any] = {"isam2_window_s": None}
        self.book.record_fixes(fix_at0, new0, 0)
        self.upd_ms = np.zeros(nk - 1)
        # per update: preintegration, interval term, isam.update, estimate read-back [ms];
        # variables relinearised, variables re-eliminated, interval terms relinearised
        self.brk = np.zeros((nk - 1, 7))
        self.answers = Answers(P, seg, cfg.isam2_lag_s)
        self.answers.record(0, st.arrays)
        self.gate = OnlineGate(P, cfg.isam2_gate_s)  # GNSS returns, the gate after updates
        self.answers.online_cov[0] = self.answers.cov(self.isam, vals0, 0, 0)
        self.baro_next = 0

    def run(self) -> OnlineResult:
        for k in range(self.P.n_kf - 1):
            self.update(k)
        return self.finish()

    def run_to(self, m: int) -> None:
        """The updates that create keyframes 1 … m."""
        for k in range(m):
            self.update(k)

    def _add_ext(self, k: int, nf: Any, nv: Any) -> None:
        """The user extensions' factors and variables that enter with keyframe k."""
        if self.ext is not None:
            fs, nv_ext = self.ext.at_keyframe(k)
            self.pyf.add(fs, nf, self.st.arrays)
            nv.insert(nv_ext)

    def update(self, k: int) -> None:
        """The iSAM2 update that creates keyframe k + 1."""
        P, book, st = self.P, self.book, self.st
        arr = st.arrays
        tu = time.perf_counter()
        nf = gtsam.NonlinearFactorGraph()
        nv = gtsam.Values()
        st.predict(k, nf, nv)
        t_pre = time.perf_counter()
        fix_at = st.keyframe_fixes(k, nf, nv)
        # the interval terms go first in the update (their factor indices come first): the
        # ones due for relinearisation, rebuilt at the current estimate ...
        nf_t = gtsam.NonlinearFactorGraph()
        tags, removed = book.rebuild(nf_t, k, arr, st.calibration())
        n_swap = len(tags)
        # ... then the new ones, at this linearisation: the GNSS fixes inside interval k
        # enter with its end keyframe (no delay to wait for); the baro samples stamped up to
        # the new keyframe (each to the interval of its delayed time t_s − τd: interval k, or
        # k − 1 for the first τd of interval k)
        sk = terms.keyframe_states(P, k, *arr, st.dg_kf)
        gcf = terms.gnss_factor(P, k, sk, st.bias, book.fixes_of[k])
        st.new_states(k, nf, nv)
        self._add_ext(k + 1, nf, nv)
        new_baro, self.baro_next = terms.baro_factors(P, k, sk, st.bias, st.cal, self.seg,
                                                      book.bt, book.bz, self.baro_next, P.pri)
        tags += book.new_terms(k, gcf, new_baro, sk, st.calibration(), nf_t)
        # the extensions' due CustomFactors, rebuilt after everything else
        nf_p = gtsam.NonlinearFactorGraph()
        ext_removed = self.pyf.rebuild_into(nf_p, nf.size(), arr)
        if ext_removed:
            removed = sorted(set(removed) | set(ext_removed))
        last = None
        if removed:
            # the keys of the new factors go last in the ordering (iSAM2's default), not
            # those of the rebuilt terms: with them a large swap leaves a root clique of
            # hundreds of variables
            last = gtsam.KeyGroupMap()
            for graph, i0 in ((nf_t, n_swap), (nf, 0)):
                for i in range(i0, graph.size()):
                    for key in graph.at(i).keys():
                        last.insert2(key, 1)
        nf_t.push_back(nf)
        nf_t.push_back(nf_p)
        t_lcf = time.perf_counter()
        try:
            ures = self.isam.update(nf_t, nv, removed, last)
            t_upd = time.perf_counter()
            new_idx = ures.getNewFactorsIndices()
            book.record(tags, new_idx)
            st.record(new_idx, len(tags))
            book.record_fixes(fix_at, new_idx, len(tags))
            self.pyf.record_new(new_idx, len(tags))
            marked = st.read_back(self.isam, ures, k, book.floor)
        except RuntimeError as exc:
            raise update_error(P, k, exc, bool(P.gap[k])) from exc
        if not (np.all(np.isfinite(st.rot[k + 1])) and np.all(np.isfinite(st.pos[k + 1]))
                and np.linalg.norm(st.vel[k + 1]) < DIVERGED_SPEED):
            raise update_error(P, k, None, bool(P.gap[k]))
        marked = self.gate.after_update(book, k, fix_at, marked, arr, st.dg_kf,
                                        self.solve_rounds)
        st.read_calibration(self.isam, k, book.first_seg)
        self.answers.after_update(self.isam, k, arr)
        if self.win is not None and (m1 := self.win.due(k + 1)) > self.win.first:
            # keyframes older than the window leave iSAM2 (their conditionals are kept)
            gone = self.win.marginalise(self.isam, m1, st.b_last)
            book.freeze(self.win.first, self.win.first_seg, gone)
            self.pyf.freeze(gone)
            st.forget(set(gone))
        book.pending = book.due(marked, k + 1, st.rot, st.pos, st.calibration())
        self.pyf.check(self.isam, k + 1, arr)
        t_end = time.perf_counter()
        self.upd_ms[k] = 1e3 * (t_end - tu)
        self.brk[k] = (1e3 * (t_pre - tu), 1e3 * (t_lcf - t_pre), 1e3 * (t_upd - t_lcf),
                       1e3 * (t_end - t_upd), ures.getVariablesRelinearized(),
                       ures.getVariablesReeliminated(), n_swap)

    def solve_rounds(self, k: int, marked: np.ndarray, rounds: int,
                     gated: np.ndarray | None = None, kf_rm: list[int] | None = None
                     ) -> tuple[np.ndarray, int]:
        """Up to ``rounds`` more relinearise-and-solve rounds in update k
        (``online_gate.OnlineGate.after_update``: when GNSS returns, and when the gate
        refuses fixes: ``gated``, the intervals whose GNSS term loses them, ``kf_rm``, the
        refused keyframe fixes' factors). Each round rebuilds the interval terms due and lets
        iSAM2 relinearise its own factors; it stops when nothing was relinearised. Returns
        the keyframes marked by all rounds and the rounds run."""
        P, book, st = self.P, self.book, self.st
        gate_round = gated is not None
        for i in range(rounds):
            book.pending = book.due(marked, k + 1, st.rot, st.pos, st.calibration())
            if gate_round and i == 0:
                book.pending = np.union1d(book.pending, gated).astype(int)
            nf = gtsam.NonlinearFactorGraph()
            self.pyf.check(self.isam, k + 1, st.arrays)
            tags, removed = book.rebuild(nf, k, st.arrays, st.calibration())
            ext_removed = self.pyf.rebuild_into(nf, 0, st.arrays)
            n_ext = len(ext_removed)
            removed = sorted(set(removed) | set(ext_removed)
                             | set(kf_rm if gate_round and i == 0 else []))
            try:
                # the newest keyframe last in the re-elimination, not every key of the rebuilt
                # terms (iSAM2's default: after a return nearly all of them, one dense root
                # clique of hundreds of variables, whose elimination is cubic in its size;
                # docs/real_logs.md, "graph-isam2 on the shared logs")
                ures = self.isam.update(nf, gtsam.Values(), removed,
                                        newest_last(P, self.seg, k + 1, st.b_last))
                book.record(tags, ures.getNewFactorsIndices())
                self.pyf.record_new(ures.getNewFactorsIndices(), 0)
                marked = np.union1d(marked, st.read_back(self.isam, ures, k, book.floor))
            except RuntimeError as exc:
                raise update_error(P, k, exc, bool(P.gap[k])) from exc
            marked = marked.astype(int)
            if not tags and not n_ext and ures.getVariablesRelinearized() == 0:
                return marked, i + 1
        return marked, rounds

    def finish(self) -> OnlineResult:
        """The last baro samples, the final rounds and iSAM2's own post-solve GNSS gate
        (``final_rounds.finish``); the iSAM2 instance is released afterwards."""
        return finish(self)
