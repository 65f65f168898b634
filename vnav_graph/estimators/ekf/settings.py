"""``EkfConfig``: the settings of the reference EKF (``ekf``, ``ekf-rts``).

In a module of its own so that the filter's set-up (``filter``) and its alignment
(``alignment``) both import it without importing each other; ``filter`` re-exports it.
"""

from __future__ import annotations

from dataclasses import dataclass

from ...config import DEG
from ...sensors.magnetometer import MAG_BIAS_SD_UT, MAG_HEADING_FLOOR, MAG_INTERVAL_S
from ...sensors.model import GnssHeightGM, gnss_gm


@dataclass(frozen=True)
class EkfConfig:
    """Settings of ``ekf`` / ``ekf-rts`` (SI units).

    cov_rate_hz: covariance propagation grid; cov_output_hz: rate of ``Estimate.cov``;
    traj_rate_hz: output trajectory rate (None = every IMU epoch); gate_prob: χ² gate
    probability for GNSS position (horizontal pair χ²₂, height χ²₁), GNSS velocity and baro
    innovations; max_consecutive_rejects: after this many consecutive rejections the next
    horizontal GNSS pair / baro sample is accepted (recovers from a diverged filter instead of
    refusing GNSS forever; the baro after baro_reaccept_s [s] of refusals, at least 3 samples),
    and the GNSS-height probation gate is widened by the baro-bias
    prior (with a baro) or the height accepted (without); max_gnss_sd_v: GNSS heights whose
    own σ_v [m] exceeds this are not used; gnss_probation_s: a GNSS height, once rejected, is
    used again after passing the gate this long without a break (``ekf.model`` docstring);
    IMU logging gaps (``nav.gaps``: the shared rule) are bridged at constant velocity with the
    shared unknown motion ``GAP_ACCEL_SD``, gap_yaw_rw [rad/√s] added to the covariance,
    roll/pitch re-levelled from the mean specific force of the first gap_level_s after it
    with σ gap_level_sd [rad]; align_max_s: maximum
    static levelling window; initial_heading / initial_heading_sd: given heading [rad] (None =
    from the GNSS track once moving faster than heading_speed_min [m/s], σ from the velocity
    noise and sideslip_sd); accel_scale: estimate accelerometer scale factors (None = when the
    IMU spec has accel_scale_sd > 0 or there is no spec: sensors.model.accel_scale_sd, the
    rule the graph smoothers share); heading_source: "auto" (acceleration
    matching when the GNSS stream has velocity, else the track), "accel" or "track";
    align_chunk_s, align_forget_s, align_sd_max: acceleration-matching chunk length [s],
    forgetting time [s] and the σ [rad] below which the heading is accepted (also the course
    of the GNSS track);
    gap_heading_forget_s: IMU gaps at least this long [s] make the heading unknown again
    (``ekf.model`` docstring);
    use_mag: use the drive's magnetometer heading when it has one (``sensors.magnetometer``;
    the first sample acquires an unknown heading); mag_interval_s: at most one magnetometer
    heading per this many seconds (its errors — interference, soft iron — are correlated
    over seconds, so 10 Hz of them would be trusted 10× too much); mag_heading_floor [rad]:
    heading σ floor for declination and soft-iron errors, added to σ_m/H; mag_bias_sd [µT]:
    prior σ of each hard-iron component left after the log's own calibration; mag_bias_rw
    [µT/√s]: its random walk; mag_reaccept_s: after this long of refused headings the next is
    forced in;
    gnss_gm_sd_v [m] / gnss_gm_tau_s [s]: the time-correlated GNSS height error as a
    first-order Gauss-Markov state of that σ and τ (``sensors.model.GnssHeightGM``, the same
    model as ``GraphConfig``'s); 0 = off (the default; ``docs/real_logs.md`` has the holdout
    comparison);
    baro_scale_sd: prior σ of the baro scale factor (None: the shared sensor model's,
    ``sensors.model.baro_prior``); set to ``sensors.baro.STIFF_SCALE_SD`` by the post-solve
    scale check when the scale left its physical range (``sensors.baro.SCALE_LIMIT``).
    """

    cov_rate_hz: float = 10.0
    cov_output_hz: float = 5.0
    traj_rate_hz: float | None = 50.0
    gate_prob: float = 0.9995
    max_consecutive_rejects: int = 50
    align_max_s: float = 20.0
    initial_heading: float | None = None
    initial_heading_sd: float = 2.0 * DEG
    heading_speed_min: float = 0.5
    sideslip_sd: float = 2.0 * DEG
    accel_scale: bool | None = None
    min_tilt_sd: float = 1e-4  # rad, levelling residual besides the accel-bias term
    max_gnss_sd_v: float = 15.0
    baro_reaccept_s: float = 1.0
    gnss_probation_s: float = 10.0
    gap_level_sd: float = 0.05  # rad
    gap_level_s: float = 1.0
    gap_yaw_rw: float = 0.05  # rad/√s
    heading_source: str = "auto"
    align_chunk_s: float = 1.0
    align_forget_s: float = 30.0
    align_sd_max: float = 15.0 * DEG
    gap_heading_forget_s: float = 5.0
    use_mag: bool = True
    mag_interval_s: float = MAG_INTERVAL_S
    mag_heading_floor: float = MAG_HEADING_FLOOR
    mag_bias_sd: float = MAG_BIAS_SD_UT
    mag_bias_rw: float = 0.01
    mag_reaccept_s: float = 20.0
    gnss_gm_sd_v: float = 0.0
    gnss_gm_tau_s: float = 300.0
    baro_scale_sd: float | None = None

    @property
    def gnss_gm(self) -> GnssHeightGM | None:
        return gnss_gm(self.gnss_gm_sd_v, self.gnss_gm_tau_s, "EkfConfig")

    def __post_init__(self) -> None:
        self.gnss_gm  # noqa: B018 -- validates the Gauss-Markov GNSS height settings
        if not (self.cov_rate_hz > 0 and self.cov_output_hz > 0):
            raise ValueError("EkfConfig.cov_rate_hz / cov_output_hz: must be > 0")
        if not 0.5 < self.gate_prob < 1.0:
            raise ValueError("EkfConfig.gate_prob: must be in (0.5, 1)")
