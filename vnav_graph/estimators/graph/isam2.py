"""``graph-isam2``: incremental smoothing with GTSAM iSAM2 (Kaess et al., IJRR 2012).

One iSAM2 update per keyframe. To keep the per-update cost bounded on long drives the baro
calibration (s, τd) is a *slowly varying per-segment* state K(j) (segments of
``GraphConfig.segment_s``, linked by a random-walk ``BetweenFactorVector``) instead of one
global variable tied to every baro sample: the graph stays chain-structured, so an update only
re-eliminates the cliques of the last keyframes (a global K sits in the root clique and every
new baro term touches it — measured in ``docs/graph.md``).

Baro samples and GNSS fixes between keyframes are linearised once (numpy, ``factors``) at
the current estimate as soon as they have arrived — in the update that creates keyframe k+1:
the fixes inside interval k, and the baro samples stamped up to t_{k+1}, one factor per
interval of their delayed time — and inserted as ``LinearContainerFactor``s with the
accelerometer-bias columns on B(k) (``terms.gnss_factor``, ``terms.baro_factors``); no
Python callback ever runs inside iSAM2. They are relinearised as iSAM2 relinearises its own
factors (``relin.TermBook``): after each update the terms on the keyframes iSAM2 marked are
checked against the rotation/translation thresholds (and their segment's (s, τd) against
``relin.CALIB_THRESHOLD``); the due ones are rebuilt at the current estimate and swapped in
at the next update (``removeFactorIndices``), counted in ``info["isam2_relinearized"]``.

Thresholds: per variable type (``GraphConfig.relinearize_typed``), C/K never (linear
factors only), checked at every update (``relinearize_skip`` 1). With the looser thresholds
of before (0.02 rad, 1 m, every 10 updates) the online estimate drifted 13–19 m from the
filtering optimum inside a 60 s GNSS outage; with these it stays within ~1 m
(``tests/integration/test_graph_isam2_online.py``). The wildfire threshold is 0.01: only
deltas of *old* variables are left stale by it (the newest keyframes sit in the root clique
and are always exact). Measurements in ``docs/graph.md``.

User extensions (``extend``): each factor enters the update that creates the last keyframe it
touches, each new variable (with its prior) the first update that uses it; the final pass has
them all. ``info["extra_variables_online"]``: iSAM2's estimate and marginal σ of the new
variables after the last update; ``info["extra_variables"]``: the final pass's.

Outputs: ``Estimate.online`` holds what was known at each keyframe (the iSAM2 estimate of the
newest keyframe right after its update); ``Estimate.trajectory`` is iSAM2's own smoothed
estimate after the final rounds (``relin.settle``: the segments' (s, τd) tied into one, forced
relinearisation with every term rebuilt until nothing is due), with covariances of the
problem linearised there. With ``GraphConfig.final_batch`` the batch Gauss-Newton of
``solve`` also runs from that estimate as its check (``info["final_batch"]``); only when it
ends significantly lower (``OWN_GAP_FRACTION``) is its solution returned instead, with a
warning and ``info["trajectory_source"] = "final_batch"``.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence
from typing import Any

import gtsam
import numpy as np
from gtsam.symbol_shorthand import A, B, C, G, K, V, X

from ...geo.frames import mat_to_quat, ned_to_lla
from ...sensors.baro import without_implausible_scale
from ...sensors.magnetometer import without_contradicting_mag
from ...sensors.noise import gm_transition
from ...types import Drive, Estimate, Trajectory
from . import factors as gf
from . import relin, terms
from .batch import gnss_gm_info, outputs, provides
from .builders import (
    bias_link,
    bias_step,
    build_batch_graph,
    gap_factors,
    gap_start_states,
    gm_factor,
    gnss_gm_factor,
    imu_factor,
    keyframe_fixes,
    pims_for,
)
from .extend import GraphExtension, check_extensions, collect, make_view
from .init import initial_states
from .isam2_setup import (
    estimate_info,
    extra_online_of,
    first_keyframe,
    isam2_params,
    segment_span,
    segments,
    update_error,
)
from .linalg import solver_context, trim_heap
from .magnetometer import builtin_extensions, mag_info
from .problem import (
    gravity_delta,
    noise,
    preintegrate,
    setup,
    states_from_values,
)
from .settings import LOW_RATE_DT, LOW_RATE_KEYFRAME_DT, GraphConfig
from .solve import evaluate_at, gauss_newton
from .window import Window

# averaged low-rate IMU logs (median spacing ≥ LOW_RATE_DT, e.g. the 1 Hz phone logs): a
# keyframe every sample made a 93-min log take 5563 updates (213 s online), and after its 37 s
# GNSS gap the typed thresholds relinearised ~140 variables per update; 5 s keyframes and
# looser thresholds (relinearisation every 50 updates) bring it to ~9 s. Applied only when the
# other settings are the defaults of those fields.
# Every keyframe is kept there (a 93-min log has ~1100 keyframes, ~150 MB of iSAM2): with the
# 600 s window (120 keyframes) iSAM2's own estimate on car 03-01a's holdout drive ended 95
# above the optimum (2·gap 1.1 % of n, the batch check's limit is 1 %: a warning), and car
# 07-18's baro scale moved from −4.6 to −5.4 % (batch −4.3 %): the heading of a phone with
# position-only GNSS is weakly held, and keyframes that left are not relinearised.
LOW_RATE_SETTINGS = {"keyframe_dt": LOW_RATE_KEYFRAME_DT, "relinearize_skip": 50,
                     "relinearize_typed": (0.1, 5.0, 2.0, 0.5, 0.02), "isam2_window_s": None}
# settings of the retry after a failed/diverged incremental pass (GraphISAM2.run)
ROBUST_SETTINGS = {"relinearize_skip": 1, "relinearize_typed": None,
                   "relinearize_threshold": 0.01}
DIVERGED_SPEED = 1e4  # m/s: an online velocity above this means the solution diverged
# iSAM2's own smoothed estimate is returned unless the batch pass started from it ends lower
# by more than this fraction of the problem's dimension n. The cost gap is ½‖Δx‖²_H (the
# squared Mahalanobis distance between the two solutions, halved), while either solution's
# expected ‖x − x_true‖²_H is n: below 1 % of n the two differ by a tenth of the posterior's
# spread (RMS over the variables). Measured on simulated drives: 2·gap ≈ 1–13 against
# n ≈ 5 000–10 000 with keyframe positions 2–4 mm apart; a diverged front end gives 10⁴–10⁶.
OWN_GAP_FRACTION = 0.01


class GraphISAM2:
    """``graph-isam2``: incremental iSAM2 front end + final batch smoothing pass."""

    name = "graph-isam2"

    def __init__(self, config: GraphConfig | None = None,
                 extensions: Sequence[GraphExtension] | None = None) -> None:
        """``extensions``: user factors and variables (``graph.extend``); each factor enters
        the update that creates the last keyframe it touches, each new variable (with its
        prior) the first update that uses it, and the final smoothing pass has them all."""
        self.config = config or GraphConfig()
        self.extensions = check_extensions(extensions)

    def run(self, drive: Drive) -> Estimate:
        """Incremental pass with the configured (fast) settings; if it fails or diverges,
        one retry with the robust settings ``ROBUST_SETTINGS`` (Powell's dogleg trust region
        in iSAM2, relinearisation check at every update with a 0.01 scalar threshold). On
        real logs the undamped single Gauss-Newton step per update overshoots when GNSS
        returns after a long outage with a km-level innovation (phone IMU, 60 s holdout
        windows) or after a logging gap; the dogleg step is bounded by its trust region.
        ``Estimate.info["isam2_fallback"]`` holds the first error when the retry was used."""
        t_start = time.perf_counter()
        cfg0 = self.config
        dt_imu = np.diff(drive.imu.t)
        dt_med = float(np.median(dt_imu)) if dt_imu.size else 0.0
        del dt_imu  # not alive through the run (5.5 MB on a 1-hour 200 Hz drive)
        if dt_med >= LOW_RATE_DT and self.config == \
                GraphConfig(**{f.name: getattr(self.config, f.name)
                                 for f in dataclasses.fields(self.config)
                                 if f.name not in LOW_RATE_SETTINGS}):
            cfg0 = dataclasses.replace(self.config, **LOW_RATE_SETTINGS)
        try:
            est = self._run(drive, cfg0, False, t_start, None)
        except RuntimeError as exc:
            if "graph-isam2:" not in str(exc):
                raise
            cfg = dataclasses.replace(cfg0, **ROBUST_SETTINGS)
            est = self._run(drive, cfg, True, t_start, str(exc))
        # the post-solve hard-iron and baro-scale checks of both families (graph-batch, ekf)
        def rerun(cfg: GraphConfig) -> Estimate:
            return GraphISAM2(cfg, self.extensions).run(drive)

        return without_implausible_scale(without_contradicting_mag(est, self.config, rerun),
                                         self.config, rerun)

    def _run(self, drive: Drive, cfg: GraphConfig, robust: bool, t_start: float,
             fallback: str | None) -> Estimate:
        with solver_context():
            return self._run_pass(drive, cfg, robust, t_start, fallback)

    def _run_pass(self, drive: Drive, cfg: GraphConfig, robust: bool, t_start: float,
                  fallback: str | None) -> Estimate:
        P = setup(drive, cfg)
        pri = P.pri
        has_baro = drive.baro is not None
        rot_i, pos_i, vel_i = initial_states(P)
        nk = P.n_kf
        seg = segments(P)
        calib0 = np.zeros(nk, dtype=int)
        ext = None
        extensions = (*self.extensions, *builtin_extensions(drive, cfg))
        if extensions:
            # the view is the batch's: the same initial values (no IMU factors needed)
            vals_i = build_batch_graph(P, rot_i, pos_i, vel_i, None, pri, calib0)[1]
            ext = collect(extensions, make_view(P, vals_i))
        isam = gtsam.ISAM2(isam2_params(cfg, robust, ext))
        # running linearisation arrays (keyframe states as last estimated)
        rot = np.zeros((nk, 3, 3))
        pos = np.zeros((nk, 3))
        vel = np.zeros((nk, 3))
        bias = np.zeros((nk, 6))
        cb = np.zeros(nk)
        gg = np.zeros(nk)  # the GNSS height error G(k) (GraphConfig.gnss_gm_sd_v), if carried
        cal = {0: np.array([0.0, pri["tau0"]])}
        rot[0], pos[0], vel[0] = rot_i[0], pos_i[0], vel_i[0]
        gap_states = gap_start_states(P, rot_i, pos_i, vel_i) if P.gap.any() else None
        graph0, vals0, fix_at0 = first_keyframe(P, rot[0], pos[0], vel[0], cal[0])
        if ext is not None:
            fs, nv_ext = ext.at_keyframe(0)
            for f in fs:
                graph0.add(f)
            vals0.insert(nv_ext)
        new0 = isam.update(graph0, vals0).getNewFactorsIndices()
        bt = drive.baro.t if has_baro else np.zeros(0)
        bz = drive.baro.altitude if has_baro else np.zeros(0)
        # the fixes of each interval, once (fixes and keyframes are in time order): strictly
        # inside it, and — with the GNSS height state — on the keyframe that ends it (the one
        # on keyframe 0 goes with interval 0)
        g_between = np.flatnonzero((P.g_kf == -1) & P.g_use)
        cuts = np.arange(1, nk - 1)
        fixes_of = np.split(g_between, np.searchsorted(
            gf.interval_of(P.t_kf, P.g_t[g_between]), cuts))
        if P.gm is not None:
            on_kf = np.flatnonzero((P.g_kf >= 0) & P.g_use)
            ends = np.split(on_kf, np.searchsorted(np.maximum(P.g_kf[on_kf] - 1, 0), cuts))
            fixes_of = [np.r_[a, b] for a, b in zip(fixes_of, ends, strict=True)]
        book = relin.TermBook(P, seg, fixes_of)
        win = (Window(P, seg, cfg.isam2_window_s, ext) if cfg.isam2_window_s is not None
               else None)
        win_info: dict[str, Any] = {"isam2_window_s": None}
        book.record_fixes(fix_at0, new0, 0)
        rw_idx: list[int] = []  # iSAM2 indices of the K / A segment random walks
        rw_at: list[int] = []
        dg_kf = np.zeros((nk, 3))  # gravity anomaly at each keyframe, once (terms)
        pims: list[Any] = []
        gap = P.gap
        upd_ms = np.zeros(nk - 1)
        # per update: preintegration, interval term, isam.update, estimate read-back [ms];
        # variables relinearised, variables re-eliminated, interval terms relinearised
        brk = np.zeros((nk - 1, 7))
        online = np.zeros((nk, 10))  # p(3), v(3), quat(4) in t frame
        online_rot = np.zeros((nk, 3, 3))  # its attitude, as quaternions after the pass
        online[0, 0:6] = np.r_[pos[0], vel[0]]
        online_rot[0] = rot[0]
        baro_next = 0
        calib_rw = np.asarray(cfg.calib_rw, float)
        s_max = 0.0  # the largest |s| of the online pass (sensors.baro scale check)

        arrays = (rot, pos, vel, bias, cb, gg)

        b_last = 0  # the last B(k) in iSAM2: B(k), interval k's bias, enters with it
        ka = np.zeros(3)  # the accelerometer scale factors as last estimated (P.ka)
        # k_a, like (s, τd), is one variable per segment, A(j), linked by a random walk of
        # root PSD accel_scale_rw·σ_ka (a global A in every bias link put it in every
        # clique: 1800 s hill-drive online pass 35 → 47 s)
        ka_rw = cfg.accel_scale_rw * (P.ka.sd if P.ka is not None else 0.0)

        def a_keys(m: int) -> tuple[int, int]:
            return A(int(seg[m])), A(int(seg[m + 1]))

        def refresh(keys_k: Any) -> None:
            relin.read_states(isam.calculateEstimate(relin.state_keys(keys_k, P, b_last)),
                              keys_k, arrays, P, b_last)

        def new_bias(nv: Any, nf: Any, k: int) -> None:
            """B(k) and its link from B(k−1) (``bias_link``: with the scale factors it needs
            ā_k, known once interval k is preintegrated), predicted from B(k−1)."""
            dt_b = float(P.t_kf[k] - P.t_kf[k - 1])
            phi = bias_step(P.imu_spec, dt_b)[0]  # the link's mean: b(k) = φ·b(k−1)
            bias[k] = phi * bias[k - 1]
            if P.ka is not None:
                bias[k, 0:3] += (P.ka.f_mean[k] - phi[0:3] * P.ka.f_mean[k - 1]) * ka
            nv.insert(B(k), gtsam.imuBias.ConstantBias(bias[k, 0:3], bias[k, 3:6]))
            nf.add(bias_link(P, k - 1, dt_b, a_keys(k - 1)))

        for k in range(nk - 1):
            tu = time.perf_counter()
            dg = gravity_delta(P, pos[k:k + 1])[0]
            dg_kf[k] = dg
            nf = gtsam.NonlinearFactorGraph()
            nv = gtsam.Values()
            if b_last < k:
                new_bias(nv, nf, k)
                b_last = k
            b_k = gtsam.imuBias.ConstantBias(bias[k, 0:3], bias[k, 3:6])
            pim = preintegrate(P, k, rot[k], dg, b_k)
            pims.append(pim)
            t_pre = time.perf_counter()
            if gap[k]:  # its factors link B(k) to B(k+1): B(k+1) enters now
                # the new keyframe starts at the gap prior's centre from iSAM2's estimate;
                # the prior itself is graph-batch's (from the initial states), so that both
                # smoothers solve one problem
                x1, v1, _ = gap_factors(P, k, rot, pos, vel, a_keys(k))
                gap_f = gap_factors(P, k, *gap_states, a_keys(k))[2]
                nv.insert(X(k + 1), x1)
                nv.insert(V(k + 1), v1)
                nv.insert(B(k + 1), b_k)
                b_last = k + 1
                for f in gap_f:
                    nf.add(f)
            else:
                nav = pim.predict(gtsam.NavState(gtsam.Rot3(rot[k]), pos[k], vel[k]), b_k)
                nv.insert(X(k + 1), nav.pose())
                nv.insert(V(k + 1), nav.velocity())
                nf.add(imu_factor(k, pim))
            # the new keyframe's linearisation point: its prediction
            x_new = nv.atPose3(X(k + 1))
            rot[k + 1], pos[k + 1] = x_new.rotation().matrix(), x_new.translation()
            vel[k + 1], bias[k + 1] = nv.atVector(V(k + 1)), bias[k]
            cb[k + 1] = cb[k]
            dt = float(P.t_kf[k + 1] - P.t_kf[k])
            fix_at: list[tuple[int, int]] = []
            if P.gm is None:
                for i, f in keyframe_fixes(P, k + 1):
                    fix_at.append((i, nf.size()))
                    nf.add(f)
            else:  # G(k+1) and its link; the fix on keyframe k+1 ends interval k's rows
                gg[k + 1] = gg[k] * gm_transition(dt, P.gm.tau_s)
                nv.insert(G(k + 1), np.array([gg[k + 1]]))
                nf.add(gnss_gm_factor(k, dt, P.gm))
            # the interval terms go first in the update (their factor indices come first):
            # the ones due for relinearisation, rebuilt at the current estimate ...
            nf_t = gtsam.NonlinearFactorGraph()
            tags, removed = book.rebuild(nf_t, k, rot, pos, vel, bias, cb, gg,
                                         cal if has_baro else None, bt, bz, pri, dg_kf)
            n_swap = len(tags)
            # ... then the new ones, at this linearisation: the GNSS fixes inside interval k
            # enter with its end keyframe (no delay to wait for)
            st = terms.keyframe_states(P, k, rot, pos, vel, bias, cb, gg, dg_kf)
            gcf = terms.gnss_factor(P, k, st, bias, fixes_of[k])
            if has_baro:
                nv.insert(C(k + 1), np.array([cb[k]]))
                nf.add(gm_factor(k, dt, pri))
                if seg[k + 1] != seg[k]:
                    j = int(seg[k + 1])
                    cal[j] = cal[j - 1].copy()
                    nv.insert(K(j), cal[j])
                    span = segment_span(P, seg, j)
                    rw_at.append(nf.size())  # its index is recorded: the final rounds
                    nf.add(gtsam.BetweenFactorVector(K(j - 1), K(j), np.zeros(2),  # remove it
                                                     noise(calib_rw * np.sqrt(span))))
            if P.ka is not None and seg[k + 1] != seg[k]:
                j = int(seg[k + 1])
                nv.insert(A(j), ka)
                rw_at.append(nf.size())
                nf.add(gtsam.BetweenFactorVector(A(j - 1), A(j), np.zeros(3), noise(
                    [ka_rw * np.sqrt(segment_span(P, seg, j))] * 3)))
            if ext is not None:
                fs, nv_ext = ext.at_keyframe(k + 1)
                for f in fs:
                    nf.add(f)
                nv.insert(nv_ext)
            # baro samples stamped up to the new keyframe (each to the interval of its
            # delayed time t_s − τd: interval k, or k − 1 for the first τd of interval k)
            new_baro, baro_next = terms.baro_factors(P, k, st, bias, cal, seg, bt, bz,
                                                     baro_next, pri)
            tags += book.new_terms(k, gcf, new_baro, st, cal if has_baro else None, nf_t)
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
            t_lcf = time.perf_counter()
            try:
                ures = isam.update(nf_t, nv, removed, last)
                t_upd = time.perf_counter()
                new_idx = ures.getNewFactorsIndices()
                book.record(tags, new_idx)
                rw_idx += [int(new_idx[len(tags) + i]) for i in rw_at]
                rw_at = []
                book.record_fixes(fix_at, new_idx, len(tags))
                marked = relin.marked_keyframes(ures.getMarkedKeys())
                read = np.r_[np.arange(max(k - 1, 0), k + 2), marked - 1, marked, marked + 1]
                refresh(np.unique(read[(read >= book.floor) & (read <= k + 1)]))
            except RuntimeError as exc:
                raise update_error(P, k, exc, bool(gap[k])) from exc
            if not (np.all(np.isfinite(rot[k + 1])) and np.all(np.isfinite(pos[k + 1]))
                    and np.linalg.norm(vel[k + 1]) < DIVERGED_SPEED):
                raise update_error(P, k, None, bool(gap[k]))
            if has_baro:
                j = int(seg[k + 1])
                for jj in range(max(j - 1, book.first_seg), j + 1):
                    cal[jj] = isam.calculateEstimateVector(K(jj))
                s_max = max(s_max, abs(float(cal[j][0])))
            if P.ka is not None:
                ka = isam.calculateEstimateVector(A(int(seg[k + 1])))
            if win is not None and (m1 := win.due(k + 1)) > win.first:
                # keyframes older than the window leave iSAM2 (their conditionals are kept)
                gone = win.marginalise(isam, m1, b_last)
                book.freeze(win.first, win.first_seg, gone)
                gone_set = set(gone)
                rw_idx = [i for i in rw_idx if i not in gone_set]
            book.pending = book.due(marked, k + 1, rot, pos, cal if has_baro else None)
            online[k + 1, 0:6] = np.r_[pos[k + 1], vel[k + 1]]
            online_rot[k + 1] = rot[k + 1]
            t_end = time.perf_counter()
            upd_ms[k] = 1e3 * (t_end - tu)
            brk[k] = (1e3 * (t_pre - tu), 1e3 * (t_lcf - t_pre), 1e3 * (t_upd - t_lcf),
                      1e3 * (t_end - t_upd), ures.getVariablesRelinearized(),
                      ures.getVariablesReeliminated(), n_swap)
        # baro samples stamped after the last keyframe whose delayed time is inside the span,
        # and the last keyframe's B (a continuation of the last interval's: no IMU factor)
        if nk >= 2:
            st = terms.keyframe_states(P, nk - 2, rot, pos, vel, bias, cb, gg, dg_kf)
            new_baro, baro_next = terms.baro_factors(P, nk - 2, st, bias, cal, seg, bt, bz,
                                                     baro_next, pri, last=True)
            nf = gtsam.NonlinearFactorGraph()
            nv = gtsam.Values()
            tags = book.new_terms(nk - 2, None, new_baro, st, cal if has_baro else None, nf)
            if b_last < nk - 1:
                new_bias(nv, nf, nk - 1)
                b_last = nk - 1
            if nf.size():
                book.record(tags, isam.update(nf, nv).getNewFactorsIndices())
        online[:, 6:10] = mat_to_quat(online_rot)  # one call (0.4 ms each, per keyframe)
        t_online = time.perf_counter()
        extra_online = extra_online_of(isam, isam.calculateEstimate(), ext)
        rounds = relin.settle(isam, book, P, seg, rw_idx, arrays, cal, bt, bz,
                              dg_kf) if cfg.final_rounds > 0 else []
        gate0 = (P.g_use.copy(), P.g_rej_post)
        if cfg.final_rounds > 0:
            # the batch's post-solve GNSS gate at iSAM2's estimate, then final rounds
            # without the rejected fixes: its own estimate keeps the fixes the batch keeps
            # (a 15 s IMU gap on hill-drive: 7 fixes the batch gated, a cost gap of 26
            # against the batch pass with them in iSAM2)
            for _ in range(cfg.gate_rounds):
                k_cal = cal[int(seg[-1])] if has_baro else None
                kf_rm = relin.post_solve_gate(book, P,
                                              relin.estimate_states(P, arrays, k_cal))
                if not book.pending.size and not kf_rm:
                    break
                rounds += relin.settle(isam, book, P, seg, rw_idx, arrays, cal, bt, bz,
                                       dg_kf, tie=False, removed=kf_rm)
        est = isam.calculateBestEstimate()  # full back-substitution (no wildfire)
        if win is not None:  # and of the keyframes that left iSAM2
            est = win.complete(est)
            win_info = win.info()
            win = None  # its conditionals (~20 MB on a 1-hour drive) are not needed now
        # the Bayes tree is not needed by the final pass: released before it (≈ 210 MB of
        # C++ memory on a 1-hour drive, otherwise alive under the final pass's peak)
        isam = None  # the closure ``refresh`` shares this name: it is not called again
        trim_heap()  # its freed nodes are scattered over the heap: hand them back
        return self._finish(drive, P, cfg, est, extra_online, t_online, online, ext, robust,
                            fallback, t_start, (rot_i, pos_i, vel_i), pims, seg, upd_ms, brk,
                            {"isam2_relinearized": book.relinearized,
                             "isam2_relinearized_factors": book.swapped_factors,
                             "isam2_calibration_steps_halved": book.damped,
                             "baro_scale_max_abs": s_max if has_baro else None,
                             "isam2_final_rounds": rounds,
                             "isam2_gnss_rejected_postsolve": P.g_rej_post - gate0[1],
                             **win_info,
                             "final_rounds_s": time.perf_counter() - t_online}, gate0)

    def _finish(self, drive: Drive, P: Any, cfg: GraphConfig, est: Any, extra_online: Any,
                t_online: float, online: Any, ext: Any, robust: bool, fallback: str | None,
                t_start: float, init: tuple[Any, Any, Any], pims: list[Any], seg: Any,
                upd_ms: Any, brk: Any, relin_counts: dict[str, Any],
                gate0: tuple[Any, int]) -> Estimate:
        """After the online pass and the final rounds (``est``: iSAM2's estimate,
        ``extra_online``: its new variables after the last keyframe, read at ``t_online``):
        the online trajectory, iSAM2's own smoothed estimate with its covariances and, with
        ``final_batch``, the batch pass started from it as its check; the Estimate.
        ``gate0``: ``P.g_use`` and ``P.g_rej_post`` before iSAM2's own post-solve gate, where
        a restart from graph-batch's start begins."""
        pri = P.pri
        has_baro = drive.baro is not None
        rot_i, pos_i, vel_i = init
        calib0 = np.zeros(P.n_kf, dtype=int)
        online_traj = self._online_trajectory(P, online)
        # iSAM2's own estimate as a point of the batch problem (one global (s, τd): the
        # segments are tied by the final rounds)
        own_vals, own_graph = self._batch_from(P, est, pims, pri, seg, init)
        pims.clear()  # the graph's IMU factors hold their own copies (3601: ~4 MB an hour)
        if ext is not None:
            ext.add_to_batch(own_graph, own_vals, values_from=est)
        res = None
        restarted = False
        if cfg.final_batch:
            if robust:
                # the online pass needed the retry: its estimate is a poor starting point
                # (ski holdout: 22 m withheld-height RMSE after 12 iterations), so the batch
                # pass starts where graph-batch starts and therefore equals it
                graph, res_vals = build_batch_graph(P, rot_i, pos_i, vel_i,
                                                    pims_for(P, rot_i, pos_i), pri, calib0)
                if ext is not None:
                    ext.add_to_batch(graph, res_vals)
            else:
                graph, res_vals = own_graph, own_vals
            res = gauss_newton(P, graph, res_vals, calib0, pri)
            if not robust and not res.converged:
                # the online estimate can sit outside Gauss-Newton's basin after a long
                # outage with a MEMS IMU (long-outage seed 1: 100 iterations, 466 m
                # horizontal RMSE, 202 fixes gated out): solve again from graph-batch's
                # starting point and keep that solution when it converges or ends lower
                res = self._restart(P, init, ext, gate0, res, take_converged=True)
                restarted = True
        # iSAM2's own estimate under the batch's cost (after its post-solve GNSS gate: the
        # same fixes), and the choice: iSAM2's own unless the batch pass found a point
        # significantly lower (OWN_GAP_FRACTION)
        if res is not None:
            # the check pass's system and the rows' Jacobian (~55 MB on a 1-hour drive) are
            # not alive under iSAM2's own rows: ``outputs`` rebuilds them if the check pass
            # is the one chosen (stage script: graph-isam2 peak 667 -> 650 MB)
            res.system = None
            res.rows = res.rows.without_jac()
        own = evaluate_at(P, own_graph, own_vals, calib0, pri)
        chosen, source, warn = own, "isam2", []
        final_batch = None
        if res is not None:
            gap = own.cost - res.cost
            d_p = (states_from_values(P, own.values, calib0).pos
                   - states_from_values(P, res.values, calib0).pos)
            final_batch = {"cost": float(res.cost), "isam2_cost": float(own.cost),
                           "cost_gap": float(gap), "iterations": int(res.iterations),
                           "stop": res.stop, "restarted": restarted,
                           # iSAM2's own keyframe positions minus the batch pass's [m]
                           "max_horizontal_diff_m": float(np.max(np.hypot(d_p[:, 0],
                                                                          d_p[:, 1]))),
                           "max_alt_diff_m": float(np.max(np.abs(d_p[:, 2])))}
            final_batch["dimension"] = int(own.values.dim())
            if 2.0 * gap > OWN_GAP_FRACTION * own.values.dim():
                if not robust and not restarted:
                    # iSAM2's estimate is not the optimum, so it was a poor start too:
                    # the batch pass from graph-batch's start, when it ends lower
                    # (loiter_rtl: 11 m horizontal against 22 m from iSAM2's estimate)
                    res = self._restart(P, init, ext, gate0, res, take_converged=False)
                    restarted = final_batch["restarted"] = True
                    final_batch.update(cost=float(res.cost), iterations=int(res.iterations),
                                       stop=res.stop, cost_gap=float(own.cost - res.cost))
                chosen, source = res, "final_batch"
                warn = [f"{self.name}: iSAM2's own smoothed estimate is not at the optimum "
                        f"(cost {own.cost:.1f} against {res.cost:.1f} for the final batch "
                        f"pass); the trajectory is the final batch pass"]
        t_final = time.perf_counter()
        del own_graph, own_vals
        if chosen is not own:
            del own
        elif res is not None and res.layout is not own.layout:
            # the check pass's sparse pattern is not needed: freed before the covariances
            # (its system and rows' Jacobian went before iSAM2's rows)
            res.layout.pattern = None
        out = outputs(P, chosen, pri, K(0) if has_baro else None)
        isam_k = None
        if has_baro:
            j_last = int(seg[-1])
            isam_k = est.atVector(K(j_last)).tolist()
        times = {"online_s": t_online - t_start, "final_smoothing_s": t_final - t_online}
        info = estimate_info(P, cfg, res if res is not None else chosen, out, upd_ms, brk,
                             robust, fallback, times, isam_k, int(seg[-1]) + 1, self.name)
        info["warnings"] += warn
        info.update(relin_counts)
        info["trajectory_source"] = source
        info["final_batch"] = final_batch
        info["solver_final"] = chosen.solver
        info["final_pass_restarted"] = restarted
        info["extra_variables"] = out["extra"]
        info.update(out["accel_scale"])
        info["extra_variables_online"] = extra_online
        info.update(mag_info(drive, cfg))
        info.update(gnss_gm_info(P))
        return Estimate(self.name, out["trajectory"], provides(drive), out["cov"],
                        out["t_cov"], out["baro"], time.perf_counter() - t_start,
                        online=online_traj, info=info, config=self.config)

    @classmethod
    def _restart(cls, P: Any, init: tuple[Any, Any, Any], ext: Any, gate0: tuple[Any, int],
                 res: Any, take_converged: bool) -> Any:
        """The batch pass again from graph-batch's starting point (``_from_batch_start``);
        its solution when it ends lower than ``res`` (or, with ``take_converged``, when it
        converged), else ``res`` with the GNSS gate decisions that went with it."""
        gate1 = (P.g_use.copy(), P.g_rej_post)
        res2 = cls._from_batch_start(P, init, ext, gate0)
        if res2.cost < res.cost or (take_converged and res2.converged):
            return res2
        P.g_use[:], P.g_rej_post = gate1
        return res

    @staticmethod
    def _from_batch_start(P: Any, init: tuple[Any, Any, Any], ext: Any,
                          gate0: tuple[Any, int]) -> Any:
        """The batch Gauss-Newton from graph-batch's own starting point, with the GNSS fixes
        the gates had accepted before the first batch pass (``gate0``: ``P.g_use`` and
        ``P.g_rej_post`` then): a pass from a diverged point gates good fixes out."""
        P.g_use[:] = gate0[0]
        P.g_rej_post = gate0[1]
        rot_i, pos_i, vel_i = init
        calib0 = np.zeros(P.n_kf, dtype=int)
        g2, v2 = build_batch_graph(P, rot_i, pos_i, vel_i, pims_for(P, rot_i, pos_i), P.pri,
                                   calib0)
        if ext is not None:
            ext.add_to_batch(g2, v2)
        return gauss_newton(P, g2, v2, calib0, P.pri)

    @staticmethod
    def _online_trajectory(P: Any, online: Any) -> Trajectory:
        lla = ned_to_lla(online[:, 0:3], P.origin)
        c_tn = gf.rot_t_n(lla, P.origin)
        vel_n = np.einsum("nji,nj->ni", c_tn, online[:, 3:6])
        from ...geo.frames import quat_to_mat

        q = mat_to_quat(np.swapaxes(c_tn, 1, 2) @ quat_to_mat(online[:, 6:10]))
        return Trajectory(P.t_kf, lla, vel_n, q)

    @staticmethod
    def _batch_from(P: Any, est: Any, pims: list[Any], pri: dict[str, float],
                    seg: Any, init: tuple[Any, Any, Any]) -> tuple[Any, Any]:
        """The batch problem with iSAM2's factors (``pims``) at iSAM2's estimate ``est``.
        Its priors (keyframe 0's, the gaps') are built from the initial states ``init``, as
        iSAM2's and graph-batch's are: built from ``est`` (until session 32) they were
        centred on iSAM2's own estimate, which then paid nothing for them, and the final
        batch pass optimised a problem pulled toward it (ski's first 200 s: iSAM2's own
        estimate judged 20.1 above that problem's optimum, the batch pass moving keyframe
        0's pose off iSAM2's value at a prior cost of 4.9)."""
        nk = P.n_kf
        graph, vals = build_batch_graph(P, *init, pims, pri, np.zeros(nk, dtype=int))
        for k in range(nk):
            # every state from the estimate: build_batch_graph starts the keyframe after an
            # IMU logging gap at its gap prior (on Loiter_RTL that put X(34) 41 m from
            # iSAM2's estimate, a false cost gap of 5771 and a fallback to the batch pass)
            vals.update(X(k), est.atPose3(X(k)))
            vals.update(V(k), est.atVector(V(k)))
            vals.update(B(k), est.atConstantBias(B(k)))
            if P.drive.baro is not None:
                vals.update(C(k), est.atVector(C(k)))
            if P.gm is not None:
                vals.update(G(k), est.atVector(G(k)))
        if P.drive.baro is not None:
            vals.update(K(0), est.atVector(K(int(seg[-1]))))
        if P.ka is not None:  # tied by the final rounds, like K
            vals.update(A(0), est.atVector(A(int(seg[-1]))))
        return vals, graph
