"""The online pass of ``graph-isam2`` (``isam2``): one iSAM2 update per keyframe, then the
final rounds.

``OnlinePass`` holds what the updates share: the iSAM2 instance, the running linearisation
arrays (keyframe states as last estimated), the term book of the interval baro / GNSS terms
(``relin.TermBook``), the segments' (s, τd) and k_a, the window of kept keyframes, and the
per-update timings. ``update(k)`` creates keyframe k + 1: its IMU (or gap) factors, its GNSS
fixes, the interval terms due for relinearisation and the new ones, one ``isam.update`` and
the read-back of the keyframes iSAM2 touched. ``finish()`` adds the baro samples after the
last keyframe, runs the final rounds (``relin.settle``) and the post-solve GNSS gate, and
returns iSAM2's estimate (``OnlineResult``). The design and its measurements: the module
docstring of ``isam2`` and ``docs/graph.md``.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

import gtsam
import numpy as np
from gtsam.symbol_shorthand import A, B, C, G, K, V, X

from ....sensors.noise import gm_transition
from ....types import Drive
from ..model import interval_factors as gf
from ..model.cpp_factors import (
    PRIOR_ATT_SD,
    bias_link,
    bias_step,
    build_batch_graph,
    gap_factors,
    gap_start_states,
    gm_factor,
    gnss_gm_factor,
    imu_factor,
    keyframe_fixes,
    zupt_factor,
)
from ..model.extend import Collected, GraphExtension, collect, make_view
from ..model.initial_guess import initial_states
from ..model.problem import Problem, gravity_delta, noise, preintegrate, setup
from ..settings import GraphConfig
from . import linear_factors as terms
from . import relin
from .answers import Answers
from .final_rounds import OnlineResult, finish
from .online_gate import OnlineGate
from .py_factors import PyFactorBook
from .setup import (
    first_keyframe,
    isam2_params,
    newest_last,
    segment_span,
    segments,
    update_error,
)
from .window import Window

DIVERGED_SPEED = 1e4  # m/s: an online velocity above this means the solution diverged
# GNSS returns after at least RETURN_GAP_S [s] without a fix: up to RETURN_ROUNDS more
# relinearise-and-solve rounds in that update (``OnlinePass._iterate``)
RETURN_GAP_S = 10.0
RETURN_ROUNDS = 5


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
        self.has_baro = drive.baro is not None
        self.init = initial_states(P) if init is None else init
        rot_i, pos_i, vel_i = self.init
        nk = P.n_kf
        self.seg = seg = segments(P)
        self.ext: Collected | None = None
        if extensions:
            # the view is the batch's: the same initial values (no IMU factors needed)
            vals_i = build_batch_graph(P, rot_i, pos_i, vel_i, None, P.pri,
                                       np.zeros(nk, dtype=int))[1]
            self.ext = collect(extensions, make_view(P, vals_i))
        # the extensions' CustomFactors: linearised here, relinearised by the book
        self.pyf = PyFactorBook(self.ext or Collected(), cfg)
        self.isam: Any = gtsam.ISAM2(isam2_params(cfg, robust, self.ext,
                                                  self.pyf.linear_only()))
        # running linearisation arrays (keyframe states as last estimated); gg: the GNSS
        # error state G(k) (GraphConfig.gnss_gm_*; (K,) for the height alone), if carried
        self.rot, self.pos, self.vel = np.zeros((nk, 3, 3)), np.zeros((nk, 3)), np.zeros((nk, 3))
        gm_dim = 1 if P.gm is None else P.gm.dim
        self.bias, self.cb = np.zeros((nk, 6)), np.zeros(nk)
        self.gg = np.zeros(nk) if gm_dim == 1 else np.zeros((nk, gm_dim))
        self.arrays = (self.rot, self.pos, self.vel, self.bias, self.cb, self.gg)
        self.cal = {0: np.array([0.0, P.pri["tau0"]])}
        st0 = P.start0
        if causal:
            self.rot[0], self.pos[0], self.vel[0] = st0.rot, st0.pos, st0.vel
        else:
            self.rot[0], self.pos[0], self.vel[0] = rot_i[0], pos_i[0], vel_i[0]
        self.gap_states = gap_start_states(P, rot_i, pos_i, vel_i) if P.gap.any() else None
        graph0, vals0, fix_at0 = first_keyframe(
            P, self.rot[0], self.pos[0], self.vel[0], self.cal[0],
            st0.yaw_sd if causal else PRIOR_ATT_SD[2])
        if self.ext is not None:
            fs, nv_ext = self.ext.at_keyframe(0)
            self.pyf.add(fs, graph0, self.arrays)
            vals0.insert(nv_ext)
        new0 = self.isam.update(graph0, vals0).getNewFactorsIndices()
        self.pyf.record_new(new0, 0)
        self.bt = drive.baro.t if self.has_baro else np.zeros(0)
        self.bz = drive.baro.altitude if self.has_baro else np.zeros(0)
        self.book = relin.TermBook(P, seg, self._fixes_of())
        self.win = (Window(P, seg, cfg.isam2_window_s, self.ext)
                    if cfg.isam2_window_s is not None else None)
        self.win_info: dict[str, Any] = {"isam2_window_s": None}
        self.book.record_fixes(fix_at0, new0, 0)
        self.rw_idx: list[int] = []  # iSAM2 indices of the K / A segment random walks
        self.rw_at: list[int] = []
        # the online gap priors: (interval, index in the update's new factors) until the
        # update, then interval → iSAM2 factor index (swapped by the final rounds)
        self.gap_prior_at: list[tuple[int, int]] = []
        self.gap_prior_idx: dict[int, int] = {}
        self.dg_kf = np.zeros((nk, 3))  # gravity anomaly at each keyframe, once (terms)
        self.pims: list[Any] = []
        self.upd_ms = np.zeros(nk - 1)
        # per update: preintegration, interval term, isam.update, estimate read-back [ms];
        # variables relinearised, variables re-eliminated, interval terms relinearised
        self.brk = np.zeros((nk - 1, 7))
        self.online = np.zeros((nk, 10))  # p(3), v(3), quat(4) in t frame
        self.online_rot = np.zeros((nk, 3, 3))  # its attitude, as quaternions after the pass
        # the biases (accel, gyro) known at each keyframe's update: the real-time output
        # between keyframes propagates the IMU with them (``answers.real_time``)
        self.online_bias = np.zeros((nk, 6))
        self.online[0, 0:6] = np.r_[self.pos[0], self.vel[0]]
        self.online_rot[0] = self.rot[0]
        self.answers = Answers(P, seg, cfg.isam2_lag_s)
        self.last_fix_t = float(P.t_kf[0])  # the latest fix in an update so far
        self.return_rounds = 0  # extra rounds when GNSS returned (``_iterate``)
        self.gate = OnlineGate(P, cfg.isam2_gate_s)  # the post-solve gate after each update
        self.answers.online_cov[0] = self.answers.cov(self.isam, vals0, 0, 0)
        self.baro_next = 0
        self.calib_rw = np.asarray(cfg.calib_rw, float)
        self.s_max = 0.0  # the largest |s| of the online pass (sensors.baro scale check)
        self.b_last = 0  # the last B(k) in iSAM2: B(k), interval k's bias, enters with it
        self.ka = np.zeros(3)  # the accelerometer scale factors as last estimated (P.ka)
        # k_a, like (s, τd), is one variable per segment, A(j), linked by a random walk of
        # root PSD accel_scale_rw·σ_ka (a global A in every bias link put it in every
        # clique: 1800 s hill-drive online pass 35 → 47 s)
        self.ka_rw = cfg.accel_scale_rw * (P.ka.sd if P.ka is not None else 0.0)

    def _fixes_of(self) -> list[np.ndarray]:
        """The fixes of each interval, once (fixes and keyframes are in time order): strictly
        inside it, and — with the GNSS error state — on the keyframe that ends it (the one on
        keyframe 0 goes with interval 0)."""
        P = self.P
        g_between = np.flatnonzero((P.g_kf == -1) & P.g_use)
        cuts = np.arange(1, P.n_kf - 1)
        fixes_of = np.split(g_between, np.searchsorted(
            gf.interval_of(P.t_kf, P.g_t[g_between]), cuts))
        if P.gm is not None:
            on_kf = np.flatnonzero((P.g_kf >= 0) & P.g_use)
            ends = np.split(on_kf, np.searchsorted(np.maximum(P.g_kf[on_kf] - 1, 0), cuts))
            fixes_of = [np.r_[a, b] for a, b in zip(fixes_of, ends, strict=True)]
        return fixes_of

    def run(self) -> OnlineResult:
        for k in range(self.P.n_kf - 1):
            self.update(k)
        return self.finish()

    def run_to(self, m: int) -> None:
        """The updates that create keyframes 1 … m."""
        for k in range(m):
            self.update(k)

    # -- one keyframe --------------------------------------------------------------------

    def a_keys(self, m: int) -> tuple[int, int]:
        return A(int(self.seg[m])), A(int(self.seg[m + 1]))

    def calibration(self) -> dict[int, np.ndarray] | None:
        """The segments' (s, τd) when the drive has a barometer, else None."""
        return self.cal if self.has_baro else None

    def new_bias(self, nv: Any, nf: Any, k: int) -> None:
        """B(k) and its link from B(k−1) (``bias_link``: with the scale factors it needs ā_k,
        known once interval k is preintegrated), predicted from B(k−1)."""
        P, bias = self.P, self.bias
        dt_b = float(P.t_kf[k] - P.t_kf[k - 1])
        phi = bias_step(P.imu_spec, dt_b)[0]  # the link's mean: b(k) = φ·b(k−1)
        bias[k] = phi * bias[k - 1]
        if P.ka is not None:
            bias[k, 0:3] += (P.ka.f_mean[k] - phi[0:3] * P.ka.f_mean[k - 1]) * self.ka
        nv.insert(B(k), gtsam.imuBias.ConstantBias(bias[k, 0:3], bias[k, 3:6]))
        nf.add(bias_link(P, k - 1, dt_b, self.a_keys(k - 1)))

    def _predict(self, k: int, nf: Any, nv: Any) -> Any:
        """Interval k's IMU factor (or, across a logging gap, the gap's factors) and keyframe
        k + 1 at its prediction, which is its linearisation point; the preintegration."""
        P, rot, pos, vel, bias = self.P, self.rot, self.pos, self.vel, self.bias
        dg = gravity_delta(P, pos[k:k + 1])[0]
        self.dg_kf[k] = dg
        if self.b_last < k:
            self.new_bias(nv, nf, k)
            self.b_last = k
        b_k = gtsam.imuBias.ConstantBias(bias[k, 0:3], bias[k, 3:6])
        pim = preintegrate(P, k, rot[k], dg, b_k)
        self.pims.append(pim)
        if P.gap[k]:  # its factors link B(k) to B(k+1): B(k+1) enters now
            # the new keyframe and its re-alignment prior from iSAM2's estimate (the data up
            # to now); the final rounds swap the prior for graph-batch's, built from the
            # initial states, so that both smoothers' final answers solve one problem
            x1, v1, gap_f = gap_factors(P, k, rot, pos, vel, self.a_keys(k))
            nv.insert(X(k + 1), x1)
            nv.insert(V(k + 1), v1)
            nv.insert(B(k + 1), b_k)
            self.b_last = k + 1
            self.gap_prior_at.append((k, nf.size()))  # gap_f[0], the prior
            for f in gap_f:
                nf.add(f)
        else:
            nav = pim.predict(gtsam.NavState(gtsam.Rot3(rot[k]), pos[k], vel[k]), b_k)
            nv.insert(X(k + 1), nav.pose())
            nv.insert(V(k + 1), nav.velocity())
            nf.add(imu_factor(k, pim))
        x_new = nv.atPose3(X(k + 1))
        rot[k + 1], pos[k + 1] = x_new.rotation().matrix(), x_new.translation()
        vel[k + 1], bias[k + 1] = nv.atVector(V(k + 1)), bias[k]
        self.cb[k + 1] = self.cb[k]

    def _keyframe_fixes(self, k: int, nf: Any, nv: Any) -> list[tuple[int, int]]:
        """Keyframe k + 1's GNSS fixes, or its GNSS error state G and link (the fix on
        keyframe k + 1 then ends interval k's rows), and its zero-velocity prior inside a
        standstill. Returns (fix, index in ``nf``) pairs."""
        P = self.P
        fix_at: list[tuple[int, int]] = []
        if P.gm is None:
            for i, f in keyframe_fixes(P, k + 1):
                fix_at.append((i, nf.size()))
                nf.add(f)
        else:
            dt = float(P.t_kf[k + 1] - P.t_kf[k])
            self.gg[k + 1] = self.gg[k] * gm_transition(dt, P.gm.tau_s)
            nv.insert(G(k + 1), np.array(self.gg[k + 1], ndmin=1))
            nf.add(gnss_gm_factor(k, dt, P.gm))
        if P.zupt_kf[k + 1]:  # a standstill decided from the data up to t_{k+1}
            nf.add(zupt_factor(P, k + 1))
        return fix_at

    def _new_states(self, k: int, nf: Any, nv: Any) -> None:
        """Keyframe k + 1's baro bias C and link, a new segment's (s, τd) K and k_a A with
        their random walks, and the user extensions' factors and variables."""
        P, seg = self.P, self.seg
        dt = float(P.t_kf[k + 1] - P.t_kf[k])
        new_seg = seg[k + 1] != seg[k]
        j = int(seg[k + 1])
        if self.has_baro:
            nv.insert(C(k + 1), np.array([self.cb[k]]))
            nf.add(gm_factor(k, dt, P.pri))
            if new_seg:
                self.cal[j] = self.cal[j - 1].copy()
                nv.insert(K(j), self.cal[j])
                span = segment_span(P, seg, j)
                self.rw_at.append(nf.size())  # its index is recorded: the final rounds
                nf.add(gtsam.BetweenFactorVector(K(j - 1), K(j), np.zeros(2),  # remove it
                                                 noise(self.calib_rw * np.sqrt(span))))
        if P.ka is not None and new_seg:
            nv.insert(A(j), self.ka)
            self.rw_at.append(nf.size())
            nf.add(gtsam.BetweenFactorVector(A(j - 1), A(j), np.zeros(3), noise(
                [self.ka_rw * np.sqrt(segment_span(P, seg, j))] * 3)))
        if self.ext is not None:
            fs, nv_ext = self.ext.at_keyframe(k + 1)
            self.pyf.add(fs, nf, self.arrays)
            nv.insert(nv_ext)

    def update(self, k: int) -> None:
        """The iSAM2 update that creates keyframe k + 1."""
        P, book = self.P, self.book
        arr = self.arrays
        tu = time.perf_counter()
        nf = gtsam.NonlinearFactorGraph()
        nv = gtsam.Values()
        self._predict(k, nf, nv)
        t_pre = time.perf_counter()
        fix_at = self._keyframe_fixes(k, nf, nv)
        # the interval terms go first in the update (their factor indices come first): the
        # ones due for relinearisation, rebuilt at the current estimate ...
        nf_t = gtsam.NonlinearFactorGraph()
        tags, removed = book.rebuild(nf_t, k, *arr, self.calibration(), self.bt, self.bz, P.pri,
                                     self.dg_kf)
        n_swap = len(tags)
        # ... then the new ones, at this linearisation: the GNSS fixes inside interval k
        # enter with its end keyframe (no delay to wait for); the baro samples stamped up to
        # the new keyframe (each to the interval of its delayed time t_s − τd: interval k, or
        # k − 1 for the first τd of interval k)
        st = terms.keyframe_states(P, k, *arr, self.dg_kf)
        gcf = terms.gnss_factor(P, k, st, self.bias, book.fixes_of[k])
        self._new_states(k, nf, nv)
        new_baro, self.baro_next = terms.baro_factors(P, k, st, self.bias, self.cal, self.seg,
                                                      self.bt, self.bz, self.baro_next, P.pri)
        tags += book.new_terms(k, gcf, new_baro, st, self.calibration(), nf_t)
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
            for i in range(n_swap, nf_t.size()):
                for key in nf_t.at(i).keys():
                    last.insert2(key, 1)
            for i in range(nf.size()):
                for key in nf.at(i).keys():
                    last.insert2(key, 1)
        nf_t.push_back(nf)
        nf_t.push_back(nf_p)
        t_lcf = time.perf_counter()
        try:
            ures = self.isam.update(nf_t, nv, removed, last)
            t_upd = time.perf_counter()
            new_idx = ures.getNewFactorsIndices()
            book.record(tags, new_idx)
            self.rw_idx += [int(new_idx[len(tags) + i]) for i in self.rw_at]
            self.rw_at = []
            self.gap_prior_idx.update((kk, int(new_idx[len(tags) + i]))
                                      for kk, i in self.gap_prior_at)
            self.gap_prior_at = []
            book.record_fixes(fix_at, new_idx, len(tags))
            self.pyf.record_new(new_idx, len(tags))
            marked = relin.marked_keyframes(ures.getMarkedKeys())
            read = np.r_[np.arange(max(k - 1, 0), k + 2), marked - 1, marked, marked + 1]
            keys_k = np.unique(read[(read >= book.floor) & (read <= k + 1)])
            relin.read_states(self.isam.calculateEstimate(
                relin.state_keys(keys_k, P, self.b_last)), keys_k, arr, P, self.b_last)
        except RuntimeError as exc:
            raise update_error(P, k, exc, bool(P.gap[k])) from exc
        if not (np.all(np.isfinite(self.rot[k + 1])) and np.all(np.isfinite(self.pos[k + 1]))
                and np.linalg.norm(self.vel[k + 1]) < DIVERGED_SPEED):
            raise update_error(P, k, None, bool(P.gap[k]))
        if self._gnss_returns(k, fix_at):
            marked = self._iterate(k, marked, RETURN_ROUNDS)
        if self.gate.judge(book, k, arr, self.dg_kf).size:  # (``online_gate``)
            # converged first, as the batch's gate judges; then without what still fails
            marked = self._iterate(k, marked, RETURN_ROUNDS, count=False)
            bad = self.gate.judge(book, k, arr, self.dg_kf)
            if bad.size:
                gated, kf_rm = self.gate.refuse(book, bad)
                marked = self._iterate(k, marked, 1, gated, kf_rm, count=False)
        self._read_calibration(k)
        self.answers.after_update(self.isam, k, gtsam.Pose3(gtsam.Rot3(self.rot[k + 1]),
                                                            self.pos[k + 1]))
        if self.win is not None and (m1 := self.win.due(k + 1)) > self.win.first:
            # keyframes older than the window leave iSAM2 (their conditionals are kept)
            gone = self.win.marginalise(self.isam, m1, self.b_last)
            book.freeze(self.win.first, self.win.first_seg, gone)
            self.pyf.freeze(gone)
            gone_set = set(gone)
            self.rw_idx = [i for i in self.rw_idx if i not in gone_set]
            self.gap_prior_idx = {kk: i for kk, i in self.gap_prior_idx.items()
                                  if i not in gone_set}
        book.pending = book.due(marked, k + 1, self.rot, self.pos, self.calibration())
        self.pyf.check(self.isam, k + 1, arr)
        self.online[k + 1, 0:6] = np.r_[self.pos[k + 1], self.vel[k + 1]]
        self.online_rot[k + 1] = self.rot[k + 1]
        self.online_bias[k + 1] = self.bias[k + 1]
        t_end = time.perf_counter()
        self.upd_ms[k] = 1e3 * (t_end - tu)
        self.brk[k] = (1e3 * (t_pre - tu), 1e3 * (t_lcf - t_pre), 1e3 * (t_upd - t_lcf),
                       1e3 * (t_end - t_upd), ures.getVariablesRelinearized(),
                       ures.getVariablesReeliminated(), n_swap)

    def _gnss_returns(self, k: int, fix_at: list[tuple[int, int]]) -> bool:
        """Whether update k holds the first GNSS fix after at least ``RETURN_GAP_S`` without
        one (keyframe k + 1's fixes and interval k's)."""
        idx = np.r_[np.asarray([i for i, _ in fix_at], dtype=int), self.book.fixes_of[k]]
        if not idx.size:
            return False
        t = self.P.g_t[idx.astype(int)]
        back = float(t.min()) - self.last_fix_t > RETURN_GAP_S
        self.last_fix_t = max(self.last_fix_t, float(t.max()))
        return back

    def _iterate(self, k: int, marked: np.ndarray, rounds: int,
                 gated: np.ndarray | None = None, kf_rm: list[int] | None = None,
                 count: bool = True) -> np.ndarray:
        """Up to ``rounds`` more relinearise-and-solve rounds in update k: ``RETURN_ROUNDS``
        when GNSS returns, one after the online gate refused fixes (``gated``: the intervals
        whose GNSS term loses them, ``kf_rm``: the refused keyframe fixes' factors; ``count``:
        counted in ``return_rounds``). When GNSS
        returns the fix pulls the dead-reckoned states metres to tens of metres, and one
        Gauss-Newton step from there leaves the online estimate short of the filtering
        optimum (long-outage seed 0: 11.4 m horizontal error at the first fix after the
        180 s outage, the forward ekf 0.7 m). Each round rebuilds the interval terms due and
        lets iSAM2 relinearise its own factors; it stops when nothing was relinearised.
        Returns the keyframes marked by all rounds."""
        P, book = self.P, self.book
        gate_round = gated is not None
        for i in range(rounds):
            book.pending = book.due(marked, k + 1, self.rot, self.pos, self.calibration())
            if gate_round and i == 0:
                book.pending = np.union1d(book.pending, gated).astype(int)
            nf = gtsam.NonlinearFactorGraph()
            self.pyf.check(self.isam, k + 1, self.arrays)
            tags, removed = book.rebuild(nf, k, *self.arrays, self.calibration(), self.bt, self.bz,
                                         P.pri, self.dg_kf)
            ext_removed = self.pyf.rebuild_into(nf, 0, self.arrays)
            n_ext = len(ext_removed)
            removed = sorted(set(removed) | set(ext_removed)
                             | set(kf_rm if gate_round and i == 0 else []))
            try:
                # the newest keyframe last in the re-elimination, not every key of the rebuilt
                # terms (iSAM2's default: after a return nearly all of them, one dense root
                # clique of hundreds of variables, whose elimination is cubic in its size;
                # docs/real_logs.md, "graph-isam2 on the shared logs")
                ures = self.isam.update(nf, gtsam.Values(), removed,
                                        newest_last(P, self.seg, k + 1, self.b_last))
                book.record(tags, ures.getNewFactorsIndices())
                self.pyf.record_new(ures.getNewFactorsIndices(), 0)
                m2 = relin.marked_keyframes(ures.getMarkedKeys())
                read = np.r_[np.arange(max(k - 1, 0), k + 2), m2 - 1, m2, m2 + 1]
                keys_k = np.unique(read[(read >= book.floor) & (read <= k + 1)])
                relin.read_states(self.isam.calculateEstimate(
                    relin.state_keys(keys_k, P, self.b_last)), keys_k, self.arrays, P,
                    self.b_last)
            except RuntimeError as exc:
                raise update_error(P, k, exc, bool(P.gap[k])) from exc
            if count:
                self.return_rounds += 1
            else:
                self.gate.rounds += 1
            marked = np.union1d(marked, m2).astype(int)
            if not tags and not n_ext and ures.getVariablesRelinearized() == 0:
                break
        return marked

    def _read_calibration(self, k: int) -> None:
        """The (s, τd) of keyframe k + 1's segment and the one before, and its k_a."""
        if self.has_baro:
            j = int(self.seg[k + 1])
            for jj in range(max(j - 1, self.book.first_seg), j + 1):
                self.cal[jj] = self.isam.calculateEstimateVector(K(jj))
            self.s_max = max(self.s_max, abs(float(self.cal[j][0])))
        if self.P.ka is not None:
            self.ka = self.isam.calculateEstimateVector(A(int(self.seg[k + 1])))

    def finish(self) -> OnlineResult:
        """The last baro samples, the final rounds and iSAM2's own post-solve GNSS gate
        (``final_rounds.finish``); the iSAM2 instance is released afterwards."""
        return finish(self)
