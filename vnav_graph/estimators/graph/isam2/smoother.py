"""``graph-isam2``: incremental smoothing with GTSAM iSAM2 (Kaess et al., IJRR 2012).

One iSAM2 update per keyframe (``online.OnlinePass``; this module runs it, retries it
with robust settings and checks its result against a batch pass). To keep the per-update cost
bounded on long drives the baro calibration (s, τd) is a *slowly varying per-segment* state
K(j) (segments of ``GraphConfig.segment_s``, linked by a random-walk ``BetweenFactorVector``)
instead of one global variable tied to every baro sample: the graph stays chain-structured, so
an update only re-eliminates the cliques of the last keyframes (a global K sits in the root
clique and every new baro term touches it — measured in ``docs/graph.md``).

Baro samples and GNSS fixes between keyframes are linearised once (numpy, ``factors``) at the
current estimate as soon as they have arrived — in the update that creates keyframe k+1: the
fixes inside interval k, and the baro samples stamped up to t_{k+1}, one factor per interval of
their delayed time — and inserted as ``LinearContainerFactor``s with the accelerometer-bias
columns on B(k) (``linear_factors.gnss_factor``, ``linear_factors.baro_factors``); no Python
callback ever runs inside iSAM2. They are relinearised as iSAM2 relinearises its own factors
(``relin.TermBook``): after each update the terms on the keyframes iSAM2 marked are checked
against the rotation/translation thresholds (and their segment's (s, τd) against
``relin.CALIB_THRESHOLD``); the due ones are rebuilt at the current estimate and swapped in at
the next update (``removeFactorIndices``), counted in ``info["isam2_relinearized"]``.

Thresholds: per variable type (``GraphConfig.relinearize_typed``), C/K never (linear
factors only), checked at every update (``relinearize_skip`` 1). With the looser thresholds
of before (0.02 rad, 1 m, every 10 updates) the online estimate drifted 13–19 m from the
filtering optimum inside a 60 s GNSS outage; with these it stays within ~1 m
(``tests/integration/test_graph_isam2_online.py``). The wildfire threshold is 0.01: only
deltas of *old* variables are left stale by it (the newest keyframes sit in the root clique
and are always exact). Measurements in ``docs/graph.md``.

User extensions (``extend``, the compass of ``magnetometer`` among them): a ``CustomFactor``
enters as a ``LinearContainerFactor`` linearised in Python and is relinearised by
``py_factors.PyFactorBook`` (iSAM2's C++ would hand each callback a copy of its whole
``Values``); each factor enters the update that creates the last keyframe it
touches, each new variable (with its prior) the first update that uses it; the final pass has
them all. ``info["extra_variables_online"]``: iSAM2's estimate and marginal σ of the new
variables after the last update; ``info["extra_variables"]``: the final pass's.

Outputs: ``Estimate.online`` holds what was known at each keyframe (the iSAM2 estimate of the
newest keyframe right after its update); ``Estimate.trajectory`` is iSAM2's own smoothed
estimate after the final rounds (``relin.settle``: the segments' (s, τd) tied into one, forced
relinearisation with every term rebuilt until nothing is due), with covariances of the
problem linearised there. With ``GraphConfig.final_batch`` the batch Gauss-Newton of
``solve`` also runs from that estimate as its check (``info["final_batch"]``); only when it
ends significantly lower (``OWN_GAP_FRACTION``) is that a warning naming both costs; its
solution is returned instead only with ``GraphConfig.isam2_batch_fallback``
(``info["isam2_final"]`` = "batch", ``info["trajectory_source"]`` = "final_batch"; otherwise
"isam2").
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence
from typing import Any

import numpy as np
from gtsam.symbol_shorthand import A, B, C, G, K, V, X

from ....geo.frames import mat_to_quat, ned_to_lla, quat_to_mat
from ....types import Drive, Estimate, Trajectory
from ...checks import checked
from ...gnss_auto import with_gm_auto
from ..model import interval_factors as gf
from ..model.cpp_factors import build_batch_graph, pims_for
from ..model.extend import GraphExtension, check_extensions
from ..model.magnetometer import builtin_extensions, mag_info
from ..model.problem import Problem, states_from_values
from ..settings import LOW_RATE_DT, LOW_RATE_KEYFRAME_DT, GraphConfig
from ..solver.general import first_line
from ..solver.linalg import solver_context
from ..solver.outputs import fallback_notes, gnss_gm_info, output_times, outputs, provides
from ..solver.solve import evaluate_at, gauss_newton
from .answers import real_time
from .causal import causal_pass
from .online import OnlineResult
from .setup import UpdateFailed, estimate_info

# averaged low-rate IMU logs (median spacing ≥ LOW_RATE_DT, e.g. the 1 Hz phone logs): a
# keyframe every sample makes an update per second of drive, and after a GNSS gap the typed
# thresholds relinearise a large part of the weakly held past at each; 5 s keyframes and
# looser thresholds (relinearisation every 50 updates) make it a few seconds per hour of
# drive. Applied only when the other settings are the defaults of those fields.
# Every keyframe is kept there (a 93-min log has ~1100 keyframes, ~150 MB of iSAM2): the
# heading of a phone with position-only GNSS is weakly held, and keyframes that left the
# window are not relinearised, so a window leaves iSAM2's own estimate off the optimum.
# Nor does the online GNSS gate run there (``online_gate``): it judges after rounds that, with
# relinearisation every 50 updates, do not converge (docs/real_logs.md, "graph-isam2 on the
# shared logs"; docs/graph.md, "Online GNSS gate").
LOW_RATE_SETTINGS = {"keyframe_dt": LOW_RATE_KEYFRAME_DT, "relinearize_skip": 50,
                     "relinearize_typed": (0.1, 5.0, 2.0, 0.5, 0.02), "isam2_window_s": None,
                     "isam2_gate_s": None}
# settings of the retry after a failed/diverged incremental pass (GraphISAM2.run)
ROBUST_SETTINGS = {"relinearize_skip": 1, "relinearize_typed": None,
                   "relinearize_threshold": 0.01}
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
        if self.config.gnss_gm_auto:  # without, then perhaps with the GNSS error state
            return with_gm_auto(drive, self.config, self.name,
                                lambda cfg: GraphISAM2(cfg, self.extensions).run(drive))
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
        except UpdateFailed as exc:
            cfg = dataclasses.replace(cfg0, **ROBUST_SETTINGS)
            try:
                est = self._run(drive, cfg, True, t_start, str(exc))
            except UpdateFailed:
                raise
            except RuntimeError as exc2:
                raise RuntimeError(f"graph-isam2 (robust retry after: {first_line(exc)}): "
                                   f"{first_line(exc2)}") from exc2
        except RuntimeError as exc:  # not an update: no retry, but named
            raise RuntimeError(f"graph-isam2: {first_line(exc)}") from exc
        # the post-solve hard-iron and baro-scale checks of both families (graph-batch, ekf)
        def rerun(cfg: GraphConfig) -> Estimate:
            return GraphISAM2(cfg, self.extensions).run(drive)

        return checked(est, self.config, rerun)

    def _run(self, drive: Drive, cfg: GraphConfig, robust: bool, t_start: float,
             fallback: str | None) -> Estimate:
        with solver_context():
            return self._run_pass(drive, cfg, robust, t_start, fallback)

    def _run_pass(self, drive: Drive, cfg: GraphConfig, robust: bool, t_start: float,
                  fallback: str | None) -> Estimate:
        extensions = (*self.extensions, *builtin_extensions(drive, cfg))
        on, start_info = causal_pass(drive, cfg, robust, extensions)
        on.relin_counts["isam2_causal_start"] = start_info
        return self._finish(drive, cfg, on, robust, fallback, t_start)

    def _finish(self, drive: Drive, cfg: GraphConfig, on: OnlineResult, robust: bool,
                fallback: str | None, t_start: float) -> Estimate:
        """After the online pass and the final rounds (``on``: iSAM2's estimate, its new
        variables after the last keyframe and the pass's records): the online trajectory,
        iSAM2's own smoothed estimate with its covariances and, with ``final_batch``, the
        batch pass started from it as its check; the Estimate. A restart from graph-batch's
        start begins with the GNSS gate decisions ``on.gate0`` (before iSAM2's own post-solve
        gate)."""
        P, est, ext, init, pims, seg = on.P, on.est, on.ext, on.init, on.pims, on.seg
        t_online = on.t_online
        pri = P.pri
        has_baro = drive.baro is not None
        calib0 = np.zeros(P.n_kf, dtype=int)
        # the real-time output: each keyframe's online state and, between keyframes, its
        # IMU propagation (``answers.real_time``), at the output epochs
        a = on.answers
        t_rt, rt, rt_rot, rt_cov = real_time(P, a.online, quat_to_mat(a.online[:, 6:10]),
                                             a.online_bias, a.online_cov, output_times(P))
        rt[:, 6:10] = mat_to_quat(rt_rot)
        online_traj = self._online_trajectory(P, rt, t_rt)
        # iSAM2's own estimate as a point of the batch problem (one global (s, τd): the
        # segments are tied by the final rounds)
        own_vals, own_graph = self._batch_from(P, est, pims, pri, seg, init)
        pims.clear()  # the graph's IMU factors hold their own copies (3601: ~4 MB an hour)
        if ext is not None:
            ext.add_to_batch(own_graph, own_vals, values_from=est)
        res, restarted = self._check_pass(P, cfg, on, robust, own_graph, own_vals, calib0)
        # iSAM2's own estimate under the batch's cost (after its post-solve GNSS gate: the
        # same fixes), and the choice: iSAM2's own unless the batch pass found a point
        # significantly lower (OWN_GAP_FRACTION)
        own = evaluate_at(P, own_graph, own_vals, calib0, pri)
        chosen, source, warn, final_batch, res, restarted = self._choose(
            P, cfg, on, robust, own, res, restarted, calib0)
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
        info = estimate_info(P, cfg, res if res is not None else chosen, out, on.upd_ms,
                             on.brk, robust, fallback, times, isam_k, int(seg[-1]) + 1,
                             self.name)
        solver_notes = fallback_notes(chosen, cfg, out["cov_damping"])
        info["warnings"] += warn + solver_notes
        # what the answer fell back to, each also a warning (summary.json / bench rows)
        info["fallbacks"] = (
            ([] if fallback is None else [f"iSAM2 update failed and was retried with dogleg "
                                          f"({fallback})"])
            + (["the trajectory is the final batch pass's, not iSAM2's own estimate"]
               if source == "final_batch" else []) + solver_notes)
        info.update(on.relin_counts)
        info["trajectory_source"] = source
        info["isam2_final"] = "batch" if source == "final_batch" else "isam2"
        info["extensions"] = on.ext.counts if on.ext is not None else {}
        info["final_batch"] = final_batch
        info["solver_final"] = info["solver"] = chosen.solver
        info["final_pass_restarted"] = restarted
        info["extra_variables"] = out["extra"]
        info.update(out["accel_scale"])
        info["extra_variables_online"] = on.extra_online
        info.update(mag_info(drive, cfg))
        info.update(gnss_gm_info(P))
        lag, lag_cov, lag_info = self._lag_outputs(P, on, cfg)
        info.update(lag_info)
        return Estimate(self.name, out["trajectory"], provides(drive), out["cov"],
                        out["t_cov"], out["baro"], time.perf_counter() - t_start,
                        online=online_traj, online_cov=rt_cov, lag=lag,
                        lag_cov=lag_cov, info=info, config=self.config)

    @classmethod
    def _check_pass(cls, P: Problem, cfg: GraphConfig, on: OnlineResult, robust: bool,
                    own_graph: Any, own_vals: Any, calib0: Any) -> tuple[Any, bool]:
        """With ``final_batch``, the batch pass (Gauss-Newton) from iSAM2's own estimate, or
        from graph-batch's start after a robust retry or when it does not converge; its result
        (None without ``final_batch``) and whether it was restarted."""
        ext, init, gate0, pri = on.ext, on.init, on.gate0, P.pri
        rot_i, pos_i, vel_i = init
        res = None
        restarted = False
        if cfg.final_batch:
            if robust:
                # the online pass needed the retry: its estimate is a poor starting point
                # (docs/real_logs.md, "graph-isam2 on the shared logs"), so the batch pass
                # starts where graph-batch starts and therefore equals it
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
                res = cls._restart(P, init, ext, gate0, res, take_converged=True)
                restarted = True
        if res is not None:
            # the check pass's system and the rows' Jacobian (~55 MB on a 1-hour drive) are
            # not alive under iSAM2's own rows: ``outputs`` rebuilds them if the check pass
            # is the one chosen (stage script: graph-isam2 peak 667 -> 650 MB)
            res.system = None
            res.rows = res.rows.without_jac()
        return res, restarted

    def _choose(self, P: Problem, cfg: GraphConfig, on: OnlineResult, robust: bool, own: Any,
                res: Any, restarted: bool, calib0: Any,
                ) -> tuple[Any, str, list[str], dict[str, Any] | None, Any, bool]:
        """iSAM2's own estimate ``own`` against the batch pass ``res`` (None without one):
        the chosen solution, its source, the warnings, ``info["final_batch"]``, and the batch
        pass and its restart flag after a restart from graph-batch's start."""
        init, ext, gate0 = on.init, on.ext, on.gate0
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
                    # (docs/real_logs.md, "graph-isam2 on the shared logs")
                    res = self._restart(P, init, ext, gate0, res, take_converged=False)
                    restarted = final_batch["restarted"] = True
                    final_batch.update(cost=float(res.cost), iterations=int(res.iterations),
                                       stop=res.stop, cost_gap=float(own.cost - res.cost))
                if cfg.isam2_batch_fallback:
                    chosen, source = res, "final_batch"
                warn = [f"{self.name}: iSAM2's own smoothed estimate is not at the optimum "
                        f"(cost {own.cost:.1f} against {res.cost:.1f} for the final batch "
                        f"pass); the trajectory is "
                        + ("the final batch pass (isam2_batch_fallback)"
                           if cfg.isam2_batch_fallback else
                           "iSAM2's own (isam2_batch_fallback = true returns the batch pass)")]
        return chosen, source, warn, final_batch, res, restarted

    @classmethod
    def _restart(cls, P: Problem, init: tuple[Any, Any, Any], ext: Any, gate0: tuple[Any, int],
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
    def _from_batch_start(P: Problem, init: tuple[Any, Any, Any], ext: Any,
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
    def _online_trajectory(P: Problem, online: Any, t: Any = None) -> Trajectory:
        """(n, 10) p, v (t frame), quaternion at ``t`` (default: the keyframes)."""
        lla = ned_to_lla(online[:, 0:3], P.origin)
        c_tn = gf.rot_t_n(lla, P.origin)
        vel_n = np.einsum("nji,nj->ni", c_tn, online[:, 3:6])
        q = mat_to_quat(np.swapaxes(c_tn, 1, 2) @ quat_to_mat(online[:, 6:10]))
        return Trajectory(P.t_kf if t is None else t, lla, vel_n, q)

    @classmethod
    def _lag_outputs(cls, P: Problem, on: OnlineResult, cfg: GraphConfig
                     ) -> tuple[Trajectory | None, Any, dict[str, Any]]:
        """``Estimate.lag`` and ``lag_cov`` from the pass's records, and their info."""
        a = on.answers
        info = {"lag_s": float(cfg.isam2_lag_s), "lag_epochs": len(a.lag_kf),
                "isam2_marginals_s": a.seconds,
                "online_cov_epochs": int(np.sum(np.isfinite(a.online_cov[:, 0, 0])))}
        if not a.lag_kf:
            return None, None, info
        arr = np.column_stack([np.asarray(a.lag_state),
                               mat_to_quat(np.asarray(a.lag_rot))])
        tr = cls._online_trajectory(P, arr, P.t_kf[np.asarray(a.lag_kf)])
        # the lag actually realised: update time minus the keyframe's [s]
        info["lag_realised_max_s"] = float(np.max(np.asarray(a.lag_t) - tr.t))
        return tr, np.asarray(a.lag_cov), info

    @staticmethod
    def _batch_from(P: Problem, est: Any, pims: list[Any], pri: dict[str, float],
                    seg: Any, init: tuple[Any, Any, Any]) -> tuple[Any, Any]:
        """The batch problem with iSAM2's factors (``pims``) at iSAM2's estimate ``est``.
        Its priors (keyframe 0's, the gaps') are built from the initial states ``init``, as
        iSAM2's and graph-batch's are: priors built from ``est`` would be centred on iSAM2's
        own estimate, which then pays nothing for them, and the batch pass would optimise a
        problem pulled toward it, judging iSAM2's estimate against the wrong optimum
        (docs/real_logs.md, "graph-isam2 on the shared logs")."""
        nk = P.n_kf
        graph, vals = build_batch_graph(P, *init, pims, pri, np.zeros(nk, dtype=int))
        for k in range(nk):
            # every state from the estimate: build_batch_graph starts the keyframe after an
            # IMU logging gap at its gap prior, tens of metres from iSAM2's estimate, which
            # makes a false cost gap (docs/real_logs.md, "IMU logging gap across a crash")
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
