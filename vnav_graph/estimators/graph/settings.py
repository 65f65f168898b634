"""Settings of the factor-graph smoothers: ``GraphConfig`` (SI units) and the keyframe spacing
rule for averaged low-rate IMU logs (``low_rate_config``)."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ...types import Drive
from ..robust import LOSSES
from ..shared_settings import SharedSettings


@dataclass(frozen=True)
class GraphConfig(SharedSettings):
    """Settings of the factor-graph smoothers (SI units); docs/graph.md gives the measurements
    behind the defaults. The fields both families read are ``SharedSettings``'s.

    keyframe_dt: keyframe spacing [s] (``low_rate_config``: 5 s on averaged ≤ 2 Hz IMU logs).
    bias_lag_tol: re-set the baro bias read lag λ when τd moves further than this [s].
    max_iterations: Gauss-Newton iterations per solve and per gate round.
    rel_tol: stop when an iteration lowers ½χ² by less than rel_tol·cost.
    abs_tol: stop when the predicted (or, after a stall, the gained) decrease is below it [½χ²].
    output_rate_hz: rate of the output trajectory, interpolated between keyframes [Hz].
    cov_epochs: at most this many keyframes carry an 18×18 covariance.
    gravity_correction: tangent-frame normal-gravity difference (off only for studies).
    coriolis: Earth-rate Coriolis term in the preintegration (off only for studies).
    segment_s: length of a baro-calibration segment in graph-isam2's online pass [s].
    calib_rw: random-walk root PSD of (s [1/√s], τd [s/√s]) between segments.
    relinearize_threshold: iSAM2's scalar threshold, used when relinearize_typed is None.
    relinearize_skip: iSAM2 relinearizeSkip.
    partial_relinearization_check: iSAM2 option of that name.
    relinearize_typed: iSAM2 thresholds (rot [rad], trans [m], vel [m/s], b_a [m/s²], b_g [rad/s]).
    wildfire_threshold: iSAM2 back-substitution threshold (None: GTSAM's 1e-3).
    final_batch: also run the batch solver from iSAM2's estimate, as its check.
    isam2_batch_fallback: return the check's solution when it ends significantly lower.
    isam2_lag_s: lag L of graph-isam2's fixed-lag estimate ``Estimate.lag`` [s].
    isam2_gate_s: span of graph-isam2's post-solve GNSS gate after each update [s] (None: off).
    final_rounds: at most this many forced-relinearisation updates after the last keyframe.
    isam2_window_s: seconds of keyframes kept in iSAM2 (None: all; at least two segments).
    observable_ratio: posterior/prior σ below which a baro parameter counts as observed.
    gnss_gate_prob: probability of the GNSS χ² gates (0 switches gating off).
    gate_rounds: at most this many post-solve gate rounds.
    velocity_screen: pre-gate GNSS velocity against the IMU's specific-force integral.
    verbose: print the solver's progress.
    solver: "auto", "banded" (error when the graph does not fit) or "general".
    mag_loss_sd: Huber threshold of the heading factors [σ].
    accel_scale_rw: online per-segment k_a random walk, times k_a's prior σ [1/√s].
    init_attitude: initial keyframe attitudes: "auto", "triad" or "ekf".
    """

    keyframe_dt: float = 1.0
    bias_lag_tol: float = 0.02
    max_iterations: int = 100
    rel_tol: float = 1e-7
    abs_tol: float = 0.05
    output_rate_hz: float = 20.0
    cov_epochs: int = 60
    gravity_correction: bool = True
    coriolis: bool = True
    segment_s: float = 60.0
    calib_rw: tuple[float, float] = (1e-7, 1e-6)
    relinearize_threshold: float = 0.05
    relinearize_skip: int = 1
    partial_relinearization_check: bool = False
    relinearize_typed: tuple[float, float, float, float, float] | None = (
        0.002, 0.1, 0.05, 0.01, 0.0005)
    wildfire_threshold: float | None = 0.01
    final_batch: bool = True
    # otherwise a check that ends lower is a warning and iSAM2's own estimate is returned
    isam2_batch_fallback: bool = False
    isam2_lag_s: float = 10.0
    isam2_gate_s: float | None = 20.0
    final_rounds: int = 8
    isam2_window_s: float | None = 600.0
    observable_ratio: float = 0.8
    gnss_gate_prob: float = 0.9999
    gate_rounds: int = 3
    velocity_screen: bool = True
    verbose: bool = False
    solver: str = "auto"
    mag_loss_sd: float = 3.0
    accel_scale_rw: float = 2e-3
    init_attitude: str = "auto"

    def __post_init__(self) -> None:
        self.gnss_gm  # noqa: B018 -- validates the Gauss-Markov GNSS error settings
        if self.solver not in ("auto", "banded", "general"):
            raise ValueError(f"GraphConfig.solver must be 'auto', 'banded' or 'general', not "
                             f"{self.solver!r}")
        if self.isam2_window_s is not None and not (
                np.isfinite(self.isam2_window_s) and self.isam2_window_s >= 2 * self.segment_s):
            raise ValueError("GraphConfig.isam2_window_s must be None or at least two segments "
                             f"(2 × segment_s = {2 * self.segment_s:g} s), not "
                             f"{self.isam2_window_s!r}")
        if not (np.isfinite(self.isam2_lag_s) and self.isam2_lag_s >= 0):
            raise ValueError("GraphConfig.isam2_lag_s must be a finite lag ≥ 0 [s], not "
                             f"{self.isam2_lag_s!r}")
        if self.isam2_gate_s is not None and not (np.isfinite(self.isam2_gate_s)
                                                  and self.isam2_gate_s >= 0):
            raise ValueError("GraphConfig.isam2_gate_s must be None or a finite span ≥ 0 [s], "
                             f"not {self.isam2_gate_s!r}")
        if self.isam2_window_s is not None and self.isam2_lag_s >= self.isam2_window_s:
            raise ValueError(f"GraphConfig.isam2_lag_s ({self.isam2_lag_s:g} s) must be shorter "
                             f"than isam2_window_s ({self.isam2_window_s:g} s)")
        if self.init_attitude not in INIT_ATTITUDES:
            raise ValueError(f"GraphConfig.init_attitude must be one of {INIT_ATTITUDES}, "
                             f"not {self.init_attitude!r}")
        self.check_losses(LOSSES)


INIT_ATTITUDES = ("auto", "triad", "ekf")


# averaged low-rate IMU logs (median IMU spacing ≥ LOW_RATE_DT, e.g. the 1 Hz phone logs):
# keyframes every LOW_RATE_KEYFRAME_DT. With a keyframe every 0.5 s at 1 Hz, each IMU factor
# spans one or two averaged samples, which hold too little motion to constrain the attitude,
# and the batch runs into a far minimum in long outages; with 5 s keyframes each factor holds
# five samples (docs/real_logs.md, "graph-isam2 on the shared logs").
LOW_RATE_DT = 0.5
LOW_RATE_KEYFRAME_DT = 5.0


def low_rate_config(cfg: GraphConfig, drive: Drive) -> GraphConfig:
    """``cfg`` with LOW_RATE_KEYFRAME_DT keyframes on a low-rate IMU when its keyframe_dt is
    the default (a user's own keyframe_dt is kept)."""
    dt = np.diff(drive.imu.t)
    if (dt.size and float(np.median(dt)) >= LOW_RATE_DT
            and cfg.keyframe_dt == GraphConfig().keyframe_dt):
        return replace(cfg, keyframe_dt=LOW_RATE_KEYFRAME_DT)
    return cfg
