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
``lin_points.CALIB_THRESHOLD``); the due ones are rebuilt at the current estimate and swapped in at
the next update (``removeFactorIndices``), counted in ``info["isam2_relinearized"]``.

Thresholds: per variable type (``GraphConfig.relinearize_typed``), C/K never (linear
factors only), checked at every update (``relinearize_skip`` 1). With the looser thresholds
of before (0.02 rad, 1 m, every 10 updates) the online estimate drifted 13–19 m from the
filtering optimum inside a 60 s GNSS outage; with these it stays within ~1 m
(``tests/integration/test_graph_isam2_online.py``). The wildfire threshold is 0.01: only
deltas of *old* variables are left stale by it (the newest keyframes sit in the root clique
and are always exact). Measurements in ``docs/graph.md``.

User extensions (``extend``, the compass of ``builtin_sensors`` among them): a ``CustomFactor``
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
``solve`` also runs from that estimate as its check (``final_check``,
``info["final_batch"]``); only when it ends significantly lower
(``final_check.OWN_GAP_FRACTION``) is that a warning naming both costs; its solution is
returned instead only with ``GraphConfig.isam2_batch_fallback`` (``info["isam2_final"]`` =
"batch", ``info["trajectory_source"]`` = "final_batch"; otherwise "isam2").
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Sequence

import numpy as np
from gtsam.symbol_shorthand import K

from ....geo.frames import mat_to_quat, quat_to_mat
from ....types import Drive, Estimate
from ...checks import checked
from ...gnss_auto import with_gm_auto
from ..model.builtin_sensors import builtin_extensions, mag_info
from ..model.extend import GraphExtension, check_extensions
from ..settings import LOW_RATE_DT, LOW_RATE_KEYFRAME_DT, GraphConfig
from ..solver.general import first_line
from ..solver.linalg import solver_context
from ..solver.outputs import fallback_notes, gnss_gm_info, output_times, outputs, provides
from ..solver.solve import evaluate_at
from .answers import online_trajectory, real_time
from .causal import causal_pass
from .final_check import batch_from, check_pass, choose
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
        online_traj = online_trajectory(P, rt, t_rt)
        # iSAM2's own estimate as a point of the batch problem (one global (s, τd): the
        # segments are tied by the final rounds)
        own_vals, own_graph = batch_from(P, est, pims, pri, seg, init)
        pims.clear()  # the graph's IMU factors hold their own copies (3601: ~4 MB an hour)
        if ext is not None:
            ext.add_to_batch(own_graph, own_vals, values_from=est)
        res, restarted = check_pass(P, cfg, on, robust, own_graph, own_vals, calib0)
        # iSAM2's own estimate under the batch's cost (after its post-solve GNSS gate: the
        # same fixes), and the choice: iSAM2's own unless the batch pass found a point
        # significantly lower (final_check.OWN_GAP_FRACTION)
        own = evaluate_at(P, own_graph, own_vals, calib0, pri)
        chosen, source, warn, final_batch, res, restarted = choose(
            P, cfg, on, robust, own, res, restarted, calib0, self.name)
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
        lag, lag_cov, lag_info = a.lag_answer()
        info.update(lag_info)
        return Estimate(self.name, out["trajectory"], provides(drive), out["cov"],
                        out["t_cov"], out["baro"], time.perf_counter() - t_start,
                        online=online_traj, online_cov=rt_cov, lag=lag,
                        lag_cov=lag_cov, info=info, config=self.config)
