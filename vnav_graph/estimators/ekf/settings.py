"""``EkfConfig``: the settings of the reference EKF (``ekf``, ``ekf-rts``).

In a module of its own so that the filter's set-up (``filter``) and its alignment
(``alignment``) both import it without importing each other; ``filter`` re-exports it.
"""

from __future__ import annotations

from dataclasses import dataclass

from ...config import DEG
from ...nav.course import SIDESLIP_SD
from ..shared_settings import SharedSettings

# the EKF's robust losses (the graph has "cauchy" too)
LOSSES = ("none", "huber")


@dataclass(frozen=True)
class EkfConfig(SharedSettings):
    """Settings of ``ekf`` / ``ekf-rts`` (SI units); the gates and gap rules are described in
    docs/ekf.md. The fields both families read are ``SharedSettings``'s.

    cov_rate_hz: covariance propagation grid [Hz].
    cov_output_hz: rate of ``Estimate.cov`` [Hz].
    traj_rate_hz: output trajectory rate [Hz] (None: every IMU epoch).
    gate_prob: χ² gate probability of GNSS position, GNSS velocity and baro innovations.
    max_consecutive_rejects: after this many refusals in a row the next GNSS pair is forced in.
    max_rejected_s: that limit as a span of GNSS time instead of a count [s] (None: the count).
    align_max_s: longest static levelling window [s].
    initial_heading: given initial heading [rad] (None: from GNSS or the magnetometer).
    initial_heading_sd: σ of the given heading [rad].
    heading_speed_min: speed above which the GNSS track gives a heading [m/s].
    sideslip_sd: σ of the track's sideslip against the body heading [rad].
    min_tilt_sd: levelling σ floor besides the accelerometer-bias term [rad].
    max_gnss_sd_v: GNSS heights whose own σ_v exceeds this are not used [m].
    baro_reaccept_s: after this long of refused baro samples (≥ 3) the next is forced in [s].
    gnss_probation_s: a refused GNSS height is used again after passing the gate this long [s].
    gap_level_sd: σ of the roll/pitch re-levelled after an IMU logging gap [rad].
    gap_level_s: mean specific force over this long after a gap re-levels it [s].
    gap_yaw_rw: heading random walk added across an IMU logging gap [rad/√s].
    heading_source: "auto" (matching and the course it confirms), "accel", "track".
    course_confirm_sd: "auto": the matching's σ at or below which it can confirm a course [rad].
    align_chunk_s: acceleration-matching chunk length [s].
    align_forget_s: acceleration-matching forgetting time [s].
    align_sd_max: heading σ below which the matched heading is accepted [rad].
    gap_heading_forget_s: IMU gaps at least this long make the heading unknown again [s].
    mag_bias_rw: hard-iron random walk [µT/√s].
    mag_reaccept_s: after this long of refused headings the next is forced in [s].
    post_gate: ``ekf-rts``: drop fixes that misfit the smoothed trajectory, rerun (``ekf.regate``).
    post_gate_rounds: at most this many post-smoothing gate rounds.
    post_gate_prob: p of the post-smoothing gate's 1 − (1 − p)² χ² quantile (= graph's).
    post_huber_rounds: ``ekf-rts``: passes with the Huber weights of smoothed residuals.
    carry_heading_back: ``ekf-rts``: rerun from the start with a heading acquired in motion.
    fb_separation: ``ekf-rts``: run the filter backward too (``info["fb_separation"]``).
    tilt_consider: hold the attitude as consider states while heading is unknown and tilt σ > 5°.
    """

    cov_rate_hz: float = 10.0
    cov_output_hz: float = 5.0
    traj_rate_hz: float | None = 50.0
    gate_prob: float = 0.9995
    max_consecutive_rejects: int = 50
    # the count is this span over the median fix interval, so it does not depend on the rate
    max_rejected_s: float | None = None
    align_max_s: float = 20.0
    initial_heading: float | None = None
    initial_heading_sd: float = 2.0 * DEG
    heading_speed_min: float = 0.5
    sideslip_sd: float = SIDESLIP_SD
    min_tilt_sd: float = 1e-4  # rad, levelling residual besides the accel-bias term
    max_gnss_sd_v: float = 15.0
    baro_reaccept_s: float = 1.0
    gnss_probation_s: float = 10.0
    gap_level_sd: float = 0.05  # rad
    gap_level_s: float = 1.0
    gap_yaw_rw: float = 0.05  # rad/√s
    heading_source: str = "auto"
    course_confirm_sd: float = 30.0 * DEG
    align_chunk_s: float = 1.0
    align_forget_s: float = 30.0
    align_sd_max: float = 15.0 * DEG
    gap_heading_forget_s: float = 5.0
    mag_bias_rw: float = 0.01
    mag_reaccept_s: float = 20.0
    # the graph's post-solve gate for ekf-rts: remove the fixes that do not fit the smoothed
    # trajectory and run the forward and RTS passes again
    post_gate: bool = True
    post_gate_rounds: int = 3
    post_gate_prob: float = 0.9999
    # the graph's IRLS for ekf-rts: each fix's Huber weight from its residual against the
    # smoothed trajectory instead of its forward innovation, passes run again with it
    post_huber_rounds: int = 3
    # a heading acquired in motion is carried back to the drive's start and the forward and RTS
    # passes run again from there with it (ekf.carry)
    carry_heading_back: bool = True
    # forward/backward separation (ekf.backward)
    fb_separation: bool = True
    # a levelling in motion: the GNSS and baro updates hold the attitude as Schmidt consider
    # states (ekf.steps.tilt_held)
    tilt_consider: bool = True

    def huber_k(self) -> tuple[float, float, float]:
        """The kernel's Huber thresholds (GNSS position, velocity, baro) [σ], 0 where the
        loss is "none"."""
        losses = (self.loss_gnss_pos, self.loss_gnss_vel, self.loss_baro)
        return tuple(float(k) if loss == "huber" else 0.0  # type: ignore[return-value]
                     for loss, k in zip(losses, self.loss_threshold_sd, strict=True))

    def __post_init__(self) -> None:
        self.gnss_gm  # noqa: B018 -- validates the Gauss-Markov GNSS error settings
        if not (self.cov_rate_hz > 0 and self.cov_output_hz > 0):
            raise ValueError("EkfConfig.cov_rate_hz / cov_output_hz: must be > 0")
        self.check_losses(LOSSES)
        if self.post_huber_rounds < 0:
            raise ValueError("EkfConfig.post_huber_rounds: must be ≥ 0")
        if not 0.5 < self.gate_prob < 1.0:
            raise ValueError("EkfConfig.gate_prob: must be in (0.5, 1)")
        if not 0.5 < self.post_gate_prob < 1.0:
            raise ValueError("EkfConfig.post_gate_prob: must be in (0.5, 1)")
