"""Settings of the factor-graph smoothers: ``GraphConfig`` (SI units) and the keyframe spacing
rule for averaged low-rate IMU logs (``low_rate_config``)."""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ...sensors.magnetometer import MAG_BIAS_SD_UT, MAG_HEADING_FLOOR, MAG_INTERVAL_S
from ...sensors.model import GnssHeightGM, gnss_gm
from ...types import Drive
from .robust import check_loss


@dataclass(frozen=True)
class GraphConfig:
    """Settings of the factor-graph smoothers (SI units).

    keyframe_dt: keyframe spacing [s]; max_iterations / rel_tol / abs_tol: Gauss-Newton
    stops when an iteration lowers the cost ½χ² by less than rel_tol·cost or (if the model
    predicted < 1 for it, ``solve.STALL_MAX_PREDICTED``) abs_tol, or
    when the decrease predicted for the next step is below abs_tol (0.05: a χ² change of
    0.1, a tenth of the change that moves one parameter by 1σ; that step is not taken and
    its factorisation gives the covariance); max_iterations per solve (and per gate round):
    4 suffice on the simulated drives, real logs need up to ≈ 100 (ski: 93 — the cap of 12
    used until session 4 left it unconverged with a −26 % scale and 23 wrongly gated fixes;
    ``info["converged"]`` says whether the cap was hit, ``info["predicted_decrease"]`` what
    the model still expected at its last linearisation); bias_lag_tol [s]: the baro bias is read at
    t_s − λ, λ the latency at the start of the solve, re-set when τd moves further than this
    (``factors.baro_rows``);
    output_rate_hz: rate of the output trajectory (interpolated between keyframes with the
    IMU-shaped interpolant); cov_epochs: maximum number of keyframes with an 18×18 covariance;
    gravity_correction / coriolis: tangent-frame corrections (off only for studies);
    segment_s: length of a baro-calibration segment in the incremental front end;
    calib_rw: random-walk root PSD of (s [1/√s], τd [s/√s]) between segments: the model
    is a random constant (the batch's one K, the ekf's states), the walk only keeps the
    front end's Bayes tree a chain, so it is stiff (1e-7/√s: 6e-6 in s over an hour; with
    2e-5 the online vertical RMSE on the sortie lagged the ekf's by 6.6 ± 4.5 mm over 16
    seeds, with 1e-7 by 1.0 ± 2.2 mm, docs/graph.md);
    relinearize_threshold: iSAM2 relinearisation threshold (one value for every component;
    used only when ``relinearize_typed`` is None; 0 switches relinearisation off);
    relinearize_typed: per-type thresholds (rotation [rad], translation [m], velocity [m/s],
    accel bias [m/s²], gyro bias [rad/s]) — the baro bias C and calibration K only appear in
    linear factors and are never relinearised by iSAM2; the rotation and translation
    thresholds also decide when the custom baro/GNSS terms are rebuilt (``relin``; K by
    ``relin.CALIB_THRESHOLD``); relinearize_skip: iSAM2 relinearizeSkip (the defaults, 10×
    tighter than before issue 14 item 4, keep the online estimate within ~1 m of the
    filtering optimum through a 60 s GNSS outage, ``docs/graph.md``);
    partial_relinearization_check: iSAM2 option of that name; wildfire_threshold: iSAM2
    back-substitution threshold (None: GTSAM's 1e-3); see ``docs/graph.md`` for the measured
    per-update latencies; final_rounds: forced-relinearisation updates after the last
    keyframe (at most; ``relin.settle``) that make iSAM2's own estimate the smoothed optimum;
    final_batch: also run the batch solver from iSAM2's estimate, as the check of it and as
    the fallback when iSAM2's estimate is not at the optimum (``info["final_batch"]``).
    isam2_window_s: graph-isam2 keeps this many seconds of keyframes in iSAM2 and
    marginalises older ones, keeping their conditionals for the smoothed estimate
    (``graph.window``: memory and per-update cost bounded on long drives; drives shorter
    than it are not affected); None keeps every keyframe. At least two segments.
    solver: linear algebra of the batch solve — "auto" (the banded-arrow fast path when every
    factor couples keyframes at most one apart and the added variables are few, else GTSAM's
    sparse elimination), "banded" (error when the graph does not fit) or "general" (GTSAM
    elimination always; same solution, slower; ``layout``, ``general``).
    loss_gnss_pos, loss_gnss_vel, loss_baro: robust loss of each measurement type, "none",
    "huber" or "cauchy" (``robust``), with the thresholds ``loss_threshold_sd`` [σ] in that
    order (GNSS position, GNSS velocity, baro); a GNSS fix's loss is of the Mahalanobis norm
    of its 3-vector residual. The final weights are in ``Estimate.info["robust_weights"]``.
    use_mag: heading factors from the drive's magnetometer when it has one, with a hard-iron
    bias variable H(0) (``graph.magnetometer``; the model is the EKF's); mag_interval_s: at
    most one per this many seconds; mag_heading_floor [rad]: heading σ floor; mag_bias_sd
    [µT]: prior σ of each hard-iron component; mag_loss_sd: Huber threshold [σ].
    accel_scale: carry the accelerometer scale factors k_a as one variable A(0) (3, random
    constant) — None: by the rule every estimator shares (``sensors.model.accel_scale_sd``:
    real logs, and simulated IMUs whose spec has a scale error). B(k) then holds the
    effective accelerometer bias of interval k, b_a + diag(ā_k)·k_a (ā_k the mean measured
    specific force over it), and the bias chain carries diag(ā_k+1 − ā_k)·k_a
    (``builders.bias_link``); the reported accelerometer bias is b_a. accel_scale_rw [1/√s]:
    graph-isam2's online pass carries k_a per segment, like (s, τd), linked by a random walk
    of root PSD accel_scale_rw times k_a's prior σ (the final rounds tie them into the
    batch's one constant). Not stiff like calib_rw: the online estimate does not depend on
    it on the simulated drives (1e-5 gave the sortie's numbers to 0.1 mm), and on 181.BIN's
    holdout a stiff k_a walk together with the stiff calib_rw made the online pass diverge.
    gnss_gate_prob: probability of the χ² gates on GNSS fixes (0 switches gating off):
    a causal pre-gate of the GNSS height against the barometer and a post-solve gate of
    each fix's normalised position (+ velocity) residual, repeated ≤ ``gate_rounds`` times.
    velocity_screen: in the pre-gate, also refuse fixes whose velocity change disagrees with
    the IMU's specific-force integral (``nav.velocity_screen``, attitude-free; same χ²
    probability).
    init_attitude: initial keyframe attitudes — "auto" (the forward ekf's on a hover-capable
    vehicle, ``Drive.meta["vehicle"]`` multirotor, helicopter or vtol, when the graph uses no
    compass; else TRIAD and the compass, ``graph.init``), "triad" or "ekf". An initial guess
    only: the solution is the graph's own optimum, but which one Gauss-Newton reaches
    depends on it (181.BIN: ½χ² 2054 from TRIAD, 1260 from the ekf's attitude).
    baro_scale_sd: prior σ of the baro scale factor (None: the shared sensor model's,
    ``sensors.model.baro_prior``); set to ``sensors.baro.STIFF_SCALE_SD`` by the post-solve
    scale check when the scale left its physical range (``sensors.baro.SCALE_LIMIT``).
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
    final_rounds: int = 8
    isam2_window_s: float | None = 600.0
    observable_ratio: float = 0.8
    gnss_gate_prob: float = 0.9999
    gate_rounds: int = 3
    velocity_screen: bool = True
    verbose: bool = False
    solver: str = "auto"
    loss_gnss_pos: str = "none"
    loss_gnss_vel: str = "none"
    loss_baro: str = "none"
    loss_threshold_sd: tuple[float, float, float] = (2.0, 2.0, 2.0)
    use_mag: bool = True
    mag_interval_s: float = MAG_INTERVAL_S
    mag_heading_floor: float = MAG_HEADING_FLOOR
    mag_bias_sd: float = MAG_BIAS_SD_UT
    mag_loss_sd: float = 3.0
    gnss_gm_sd_v: float = 0.0
    gnss_gm_tau_s: float = 300.0
    accel_scale: bool | None = None
    accel_scale_rw: float = 2e-3
    baro_scale_sd: float | None = None
    init_attitude: str = "auto"

    @property
    def gnss_gm(self) -> GnssHeightGM | None:
        return gnss_gm(self.gnss_gm_sd_v, self.gnss_gm_tau_s, "GraphConfig")

    def __post_init__(self) -> None:
        self.gnss_gm  # noqa: B018 -- validates the Gauss-Markov GNSS height settings
        if self.solver not in ("auto", "banded", "general"):
            raise ValueError(f"GraphConfig.solver must be 'auto', 'banded' or 'general', not "
                             f"{self.solver!r}")
        if self.isam2_window_s is not None and not (
                np.isfinite(self.isam2_window_s) and self.isam2_window_s >= 2 * self.segment_s):
            raise ValueError("GraphConfig.isam2_window_s must be None or at least two segments "
                             f"(2 × segment_s = {2 * self.segment_s:g} s), not "
                             f"{self.isam2_window_s!r}")
        if self.init_attitude not in INIT_ATTITUDES:
            raise ValueError(f"GraphConfig.init_attitude must be one of {INIT_ATTITUDES}, "
                             f"not {self.init_attitude!r}")
        for f in ("loss_gnss_pos", "loss_gnss_vel", "loss_baro"):
            check_loss(getattr(self, f), f)
        if len(self.loss_threshold_sd) != 3 or not all(
                np.isfinite(k) and k > 0 for k in self.loss_threshold_sd):
            raise ValueError("GraphConfig.loss_threshold_sd must be three positive thresholds "
                             "[σ] (GNSS position, GNSS velocity, baro), not "
                             f"{self.loss_threshold_sd!r}")


INIT_ATTITUDES = ("auto", "triad", "ekf")


# averaged low-rate IMU logs (median IMU spacing ≥ LOW_RATE_DT, e.g. the 1 Hz phone logs):
# keyframes every LOW_RATE_KEYFRAME_DT. With a keyframe every 0.5 s at 1 Hz, each IMU factor
# spans one or two averaged samples and the batch ran into a far minimum in the 60 s holdout
# outages of car 07-18 (48.7 m height / 284 m horizontal RMSE, 242 s); with 5 s keyframes it
# gives 1.29 m / 2.75 m in 8 s (the keyframes graph-isam2 already used there).
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
