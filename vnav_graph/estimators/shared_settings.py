"""The settings the filter family (``EkfConfig``) and the graph family (``GraphConfig``)
share: one field, one name and one default per quantity, so that a comparison runs both on
one configuration. A flat ``--config`` key sets it in whichever section names it."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..sensors.gnss_model import GnssErrorSettings
from ..sensors.magnetometer import MAG_BIAS_SD_UT, MAG_HEADING_FLOOR, MAG_INTERVAL_S


@dataclass(frozen=True)
class SharedSettings(GnssErrorSettings):
    """Settings both families read (SI units); each family checks the values it accepts.

    loss_gnss_pos: robust loss of GNSS positions: "none", "huber" or (graphs only) "cauchy".
    loss_gnss_vel: robust loss of GNSS velocities (the same choices).
    loss_baro: robust loss of baro samples (the same choices).
    loss_threshold_sd: loss thresholds k (GNSS position, GNSS velocity, baro) [σ].
    use_mag: magnetometer headings when the drive has a magnetometer.
    mag_interval_s: at most one magnetometer heading per this many seconds [s].
    mag_heading_floor: heading σ floor for declination and soft-iron errors [rad].
    mag_bias_sd: prior σ of each hard-iron component [µT].
    accel_scale: estimate accelerometer scale factors (None: the shared rule of sensors.model).
    baro_scale_sd: prior σ of the baro scale (None: the shared sensor model's).
    zupt: zero-velocity updates inside the detected standstills (``nav.standstill``).
    """

    # Huber: a row's variance R/w, w = min(1, k/e), e the Mahalanobis norm of its residual
    # in σ (the horizontal pair and the height each on its own in the ekf)
    loss_gnss_pos: str = "none"
    loss_gnss_vel: str = "none"
    loss_baro: str = "none"
    loss_threshold_sd: tuple[float, float, float] = (2.0, 2.0, 2.0)
    use_mag: bool = True
    # magnetometer errors (interference, soft iron) are correlated over seconds: 10 Hz of
    # headings would be trusted 10× too much
    mag_interval_s: float = MAG_INTERVAL_S
    mag_heading_floor: float = MAG_HEADING_FLOOR
    mag_bias_sd: float = MAG_BIAS_SD_UT
    accel_scale: bool | None = None
    baro_scale_sd: float | None = None
    # zero-velocity updates (ekf) or priors (graphs) where the IMU and the GNSS speed agree
    # on a standstill
    zupt: bool = True

    def check_losses(self, allowed: tuple[str, ...]) -> None:
        """``ValueError`` naming the config class unless each loss is one of ``allowed`` (the
        family's) and the thresholds are three finite values > 0."""
        who = type(self).__name__
        for what in ("loss_gnss_pos", "loss_gnss_vel", "loss_baro"):
            if getattr(self, what) not in allowed:
                raise ValueError(f"{who}.{what} must be one of {', '.join(allowed)}, not "
                                 f"{getattr(self, what)!r}")
        if len(self.loss_threshold_sd) != 3 or not all(
                np.isfinite(k) and k > 0 for k in self.loss_threshold_sd):
            raise ValueError(f"{who}.loss_threshold_sd must be three positive thresholds [σ] "
                             f"(GNSS position, GNSS velocity, baro), not "
                             f"{self.loss_threshold_sd!r}")
