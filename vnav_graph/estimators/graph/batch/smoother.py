"""``graph-batch``: full-batch GTSAM smoothing (the outputs are ``solver.outputs``).

Only the modules of this subpackage import gtsam. Design (details and measurements in
``docs/graph.md``):

- Frame: one Earth-fixed tangent-plane NED frame ``t`` at ``Drive.origin_lla``;
  ``MakeSharedD(γ(origin))`` gravity, ``omegaCoriolis`` = Ω_ie resolved in t (exact for an
  Earth-fixed frame; centrifugal is inside normal gravity). The tilt and magnitude change of
  the true gravity over the drive, δg = C_tn(p)·[0, 0, γ(lat, h)] − [0, 0, γ0], is added to
  the specific force fed to the preintegration, rotated with the keyframe attitude estimate.
  Outputs are converted to geodetic lla (ellipsoidal heights) and local-level NED.
- Variables per keyframe k: X(k) Pose3, V(k) velocity, B(k) IMU bias, C(k) baro
  Gauss-Markov bias, G(k) GNSS Gauss-Markov error on 1-3 NED axes (optional,
  ``GraphConfig.gnss_gm_sd_h`` / ``gnss_gm_sd_v``, the EKF's model ``sensors.gnss_model``; a
  linear chain like C); K(j) = (s, τd) baro
  calibration (one for the batch, one per segment in the incremental front end).
- C++ factors: ImuFactor (Forster et al. 2017) on B(k), GPSFactorArm and velocity priors for
  fixes at keyframe epochs, priors, and as linear factors the IMU biases' Gauss-Markov step
  (``cpp_factors.bias_link``, the ekf's discretisation, with the accelerometer scale factors A(0)
  when carried:
  ``problem.AccelScale``) and the exact Gauss-Markov chain b_{k+1} = e^{−Δt/τ} b_k + w,
  var w = σ²(1 − e^{−2Δt/τ}).
- Baro samples and GNSS fixes between keyframes: linearised in numpy, vectorised over all
  samples (``factors``), reduced to one information block per interval and added to the
  linearised C++ graph inside our own Gauss-Newton loop (batch), or wrapped once as
  ``LinearContainerFactor`` (incremental).

References: Forster et al., "On-Manifold Preintegration", IEEE T-RO 2017; Kaess et al.,
"iSAM2", IJRR 2012; Groves 2nd ed. §2.4, §5.4; seed 001 (baro error model).
"""

from __future__ import annotations

import time
from collections.abc import Sequence

import numpy as np
from gtsam.symbol_shorthand import K

from ....types import Drive, Estimate
from ...checks import checked
from ...gnss_auto import with_gm_auto
from ..model.builtin_sensors import builtin_extensions, mag_info
from ..model.cpp_factors import build_batch_graph, pims_for
from ..model.extend import GraphExtension, check_extensions, collect, make_view
from ..model.initial_guess import initial_states
from ..model.problem import setup
from ..settings import GraphConfig, low_rate_config
from ..solver.linalg import solver_context
from ..solver.outputs import (
    fallback_notes,
    gnss_gm_info,
    outputs,
    provides,
    solver_warnings,
)
from ..solver.solve import gauss_newton


class GraphBatch:
    """``graph-batch``: full-batch smoothing of the whole drive (offline)."""

    name = "graph-batch"

    def __init__(self, config: GraphConfig | None = None,
                 extensions: Sequence[GraphExtension] | None = None) -> None:
        """``extensions``: user factors and variables (``graph.extend``), each a callable
        ``view -> Terms`` called once per run; the solve picks the general path by itself
        when their factors do not fit the keyframe band."""
        self.config = config or GraphConfig()
        self.extensions = check_extensions(extensions)

    def run(self, drive: Drive) -> Estimate:
        """Solve; when the magnetometer was used and its hard iron fails the post-solve check
        (``estimators.checks.hard_iron_note``), solve again without it and say why in
        ``info["mag_note"]``. With ``gnss_gm_auto``: ``estimators.gnss_auto``."""
        if self.config.gnss_gm_auto:
            return with_gm_auto(drive, self.config, self.name,
                                lambda cfg: GraphBatch(cfg, self.extensions).run(drive))
        with solver_context():
            est = self._run(drive)
        def rerun(cfg: GraphConfig) -> Estimate:
            return GraphBatch(cfg, self.extensions).run(drive)

        # the post-solve hard-iron and baro-scale checks of both families, then the
        # calibration's prior-conflict notes
        return checked(est, self.config, rerun)

    def _run(self, drive: Drive) -> Estimate:
        t0 = time.perf_counter()
        P = setup(drive, low_rate_config(self.config, drive))
        pri = P.pri
        rot, pos, vel = initial_states(P)
        t1 = time.perf_counter()
        pims = pims_for(P, rot, pos)
        t2 = time.perf_counter()
        calib = np.zeros(P.n_kf, dtype=int)
        graph, vals = build_batch_graph(P, rot, pos, vel, pims, pri, calib)
        extensions = (*self.extensions, *builtin_extensions(drive, self.config))
        if extensions:
            added = collect(extensions, make_view(P, vals))
            added.add_to_batch(graph, vals)
        res = gauss_newton(P, graph, vals, calib, pri)
        t3 = time.perf_counter()
        out = outputs(P, res, pri, K(0) if drive.baro is not None else None)
        t4 = time.perf_counter()
        counts = added.counts if extensions else {}
        fallbacks = fallback_notes(res, self.config, out["cov_damping"])
        info = {"keyframes": P.n_kf, "iterations": res.iterations, "final_cost": res.cost,
                "extensions": counts,
                "converged": res.converged, "stop": res.stop,
                "predicted_decrease": res.predicted_decrease,
                "warnings": [*solver_warnings(res, self.config), *fallbacks],
                "fallbacks": fallbacks,
                "singular_damping": res.singular_damping, "cov_damped": out["cov_damping"] > 0,
                "baro_bias_lag_s": res.bias_lag, "solver": res.solver,
                **P.init_info(), **P.zupt_info(), **P.sensor_info(),
                "robust_weights": res.rows.weights,
                "extra_variables": out["extra"],
                **out["accel_scale"],
                "gnss_rejected": P.gnss_rejected, "gnss_rejected_pregate": P.g_rej_pre,
                "gnss_rejected_velocity_screen": P.g_rej_vel,
                "gnss_rejected_postsolve": P.g_rej_post,
                "observability": out["observability"],
                "timing_s": {"init": t1 - t0, "preintegration": t2 - t1, "solve": t3 - t2,
                             "outputs": t4 - t3},
                **mag_info(drive, self.config),
                **gnss_gm_info(P),
                "frame": "tangent-plane NED at origin; gravity-difference and Coriolis "
                         "corrections" if self.config.gravity_correction else "tangent-plane"}
        return Estimate(self.name, out["trajectory"], provides(drive), out["cov"],
                        out["t_cov"], out["baro"], time.perf_counter() - t0, info=info,
                        config=self.config)
