"""Core data types: the estimates and the error-state layout (defined here) and the time
series on one clock, the sensor streams and ``Drive`` (``vnav_graph.types.streams``) and
``Trajectory`` (``vnav_graph.types.trajectory``); all are imported from here (``__all__``).

Conventions (see also the package docstring)
--------------------------------------------
- One clock for every stream, in seconds (float64), strictly increasing.
- ``lla`` columns are geodetic latitude [rad], longitude [rad], WGS-84 ellipsoidal height [m].
- ``n`` is the local-level NED frame at the current position (local-level mechanization);
  ``pos_n`` (tangent-plane NED relative to ``Drive.origin_lla``) is derived from ``lla``.
- ``b`` is the IMU body frame, forward-right-down.
- ``q_nb`` is a unit quaternion, scalar first ``(w, x, y, z)``, Hamilton convention, that maps
  b-coordinates into n (``mat_nb @ accel_b`` is the specific force resolved in n).
- ``alt`` is +up, ``down`` is +down. SI units everywhere; non-SI only at I/O boundaries.

Every class validates in ``__post_init__`` and raises ``ValueError`` naming the stream and the
field. Nothing is silently repaired: readers repair and report, types only check.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

import numpy as np

from .checks import as_array, check_shape
from .streams import (
    HEIGHT_DATUMS,
    BaroStream,
    BaroTruth,
    Drive,
    FloatArray,
    GnssStream,
    ImuStream,
    MagStream,
)
from .trajectory import Trajectory

# The public import path of the core types (``from vnav_graph.types import Drive, Estimate``):
# the estimates defined here and the time series of ``types.streams`` / ``types.trajectory``.
__all__ = [
    "ERROR_STATE", "ERROR_STATE_DIM", "HEIGHT_DATUMS", "QUANTITIES", "SD_COLUMNS",
    "BaroEstimate", "BaroStream", "BaroTruth", "Drive", "Estimate", "GnssStream", "ImuStream",
    "MagStream", "ParamEstimate", "Trajectory",
]

# Error-state layout shared by every estimator that reports a covariance. Rows/columns an
# estimator does not estimate are NaN. Position and velocity errors are NED [m], [m/s];
# attitude errors are small tilt angles resolved in n [rad] (true = exp(-[psi x]) estimated,
# i.e. psi = estimated minus true); gyro bias [rad/s], accel bias [m/s^2]; baro scale [-],
# baro latency [s], baro Gauss-Markov bias [m].
ERROR_STATE: MappingProxyType[str, slice] = MappingProxyType(
    {
        "pos_n": slice(0, 3),
        "vel_n": slice(3, 6),
        "att_n": slice(6, 9),
        "bias_gyro": slice(9, 12),
        "bias_accel": slice(12, 15),
        "baro_scale": slice(15, 16),
        "baro_latency": slice(16, 17),
        "baro_bias": slice(17, 18),
    }
)
ERROR_STATE_DIM = 18

# Column of ``Estimate.to_dataframe()`` holding the one-sigma of each ERROR_STATE component.
# The down-position sigma is the altitude sigma and keeps the first Parquet layout's name.
SD_COLUMNS: tuple[str, ...] = (
    "pos_n_sd_m", "pos_e_sd_m", "alt_sd_m",
    "vel_n_sd_mps", "vel_e_sd_mps", "vel_d_sd_mps",
    "att_n_sd_rad", "att_e_sd_rad", "att_d_sd_rad",
    "bias_gyro_x_sd_radps", "bias_gyro_y_sd_radps", "bias_gyro_z_sd_radps",
    "bias_accel_x_sd_mps2", "bias_accel_y_sd_mps2", "bias_accel_z_sd_mps2",
    "baro_scale_sd", "baro_latency_sd_s", "baro_bias_sd_m",
)

# Quantities an Estimate may provide (``Estimate.provides``).
QUANTITIES = frozenset({"alt", "vel_d", "pos_h", "vel_h", "att", "baro", "cov"})

@dataclass(frozen=True)
class ParamEstimate:
    """A scalar parameter estimate with its one-sigma uncertainty, prior sigma and (where the
    estimator reports it) prior mean."""

    est: float
    sd: float | None
    prior_sd: float | None = None
    prior_mean: float | None = None

    @property
    def observable(self) -> bool | None:
        """False when the data barely informed the parameter (posterior sd > 0.8 prior sd)."""
        if self.sd is None or self.prior_sd is None or self.prior_sd <= 0:
            return None
        return bool(self.sd < 0.8 * self.prior_sd)


@dataclass(frozen=True)
class BaroEstimate:
    """Estimated barometer errors. ``bias_m`` is the time average of b(t) over the drive."""

    scale: ParamEstimate | None = None
    latency_s: ParamEstimate | None = None
    bias_m: ParamEstimate | None = None


@dataclass(frozen=True)
class Estimate:
    """What every estimator returns.

    Parameters
    ----------
    estimator : registry name
    trajectory : the estimate (smoothed for smoothers)
    provides : subset of ``QUANTITIES``
    cov : (M, 18, 18) or None, error covariance in the ``ERROR_STATE`` layout at ``t_cov``
    baro : estimated baro errors with sigmas, or None
    runtime_s : wall time of ``run`` [s]
    online : the causal estimate, each epoch's state right after its own update (filters:
        the trajectory itself; graph-isam2: the newest keyframe after its update); None for
        pure smoothers
    online_cov : (M, 18, 18) or None, error covariance of ``online`` at ``online.t``
        (``ERROR_STATE`` layout); None when the estimator does not report one
    lag : graph-isam2's fixed-lag estimate: the state at t − L right after the update at t,
        L = ``info["lag_s"]``; None elsewhere
    lag_cov : (M, 18, 18) or None, error covariance of ``lag`` at ``lag.t``
    innovations : normalised innovations per measurement type
    info : free-form diagnostics (rejected GNSS count ``gnss_rejected``, observability, ...)
    config : the estimator's settings
    origin_lla : (3,) or None, the drive's tangent-plane origin (``vnav_graph.run.runner`` sets it;
        ``to_dataframe()`` uses it)
    """

    estimator: str
    trajectory: Trajectory
    provides: frozenset[str]
    cov: FloatArray | None = None
    t_cov: FloatArray | None = None
    baro: BaroEstimate | None = None
    runtime_s: float = 0.0
    online: Trajectory | None = None
    online_cov: FloatArray | None = None
    lag: Trajectory | None = None
    lag_cov: FloatArray | None = None
    innovations: MappingProxyType[str, FloatArray] = field(
        default_factory=lambda: MappingProxyType({})
    )
    info: MappingProxyType[str, Any] = field(default_factory=lambda: MappingProxyType({}))
    config: Any = None
    origin_lla: FloatArray | None = None  # the drive's origin (set by the runner)

    def __post_init__(self) -> None:
        unknown = set(self.provides) - QUANTITIES
        if unknown:
            raise ValueError(f"estimate.provides: unknown quantities {sorted(unknown)}")
        object.__setattr__(self, "provides", frozenset(self.provides))
        if self.cov is not None:
            cov = as_array(self.cov)
            if self.t_cov is None:
                raise ValueError("estimate.t_cov: required when cov is given")
            t_cov = as_array(self.t_cov)
            check_shape("estimate.cov", cov, (t_cov.size, ERROR_STATE_DIM, ERROR_STATE_DIM))
            object.__setattr__(self, "cov", cov)
            object.__setattr__(self, "t_cov", t_cov)
        for name, tr in (("online", self.online), ("lag", self.lag)):
            c = getattr(self, f"{name}_cov")
            if c is None:
                continue
            if tr is None:
                raise ValueError(f"estimate.{name}_cov: given without estimate.{name}")
            c = as_array(c)
            check_shape(f"estimate.{name}_cov", c, (tr.t.size, ERROR_STATE_DIM, ERROR_STATE_DIM))
            object.__setattr__(self, f"{name}_cov", c)
        for f in ("innovations", "info"):
            v = getattr(self, f)
            if not isinstance(v, MappingProxyType):
                object.__setattr__(self, f, MappingProxyType(dict(v)))

    def to_dataframe(self, origin_lla: Any = None) -> Any:
        """The estimate as a table: one row per trajectory epoch, every state and its sigma.

        This is also the layout of ``estimates/<name>.parquet`` written by ``vnav-graph run``.

        Parameters
        ----------
        origin_lla : (3,) or None, tangent-plane origin (lat [rad], lon [rad], height [m]) for
            the ``pos_*_m`` columns; None takes the estimate's own ``origin_lla`` (the drive's
            origin, set when the estimator ran through ``vnav_graph.run.runner``, e.g.
            ``run_estimators``), and leaves the columns out when it has none.

        Returns
        -------
        pandas.DataFrame with these columns (SI units, the unit in the name):

        - always: ``t_s``; ``lat_rad``, ``lon_rad``, ``alt_m`` (ellipsoidal height, +up);
          ``vel_n_mps``, ``vel_e_mps``, ``vel_d_mps``. Components an estimator does not
          estimate are NaN (the vertical-only estimators: latitude, longitude, north and
          east velocity; ``provides`` says which).
        - when estimated, else absent: ``pos_n_m``, ``pos_e_m``, ``pos_d_m`` (tangent-plane
          NED from ``origin_lla``, needs ``"pos_h"`` in ``provides``); ``roll_rad``,
          ``pitch_rad``, ``yaw_rad`` (from ``q_nb``); ``bias_gyro_{x,y,z}_radps`` and
          ``bias_accel_{x,y,z}_mps2`` (body axes); ``baro_bias_m`` (b(t)); ``baro_scale``
          [-] and ``baro_latency_s`` (``Estimate.baro``: constants of the baro model, so
          the same value on every row).
        - sigmas, from the covariance (absent when ``cov`` is None): ``SD_COLUMNS``, one per
          ``ERROR_STATE`` component (``alt_sd_m`` is the down-position sigma; ``att_*`` are
          the tilt-error sigmas about n's axes), present when that component's variance is
          finite at some covariance epoch; plus ``horiz_sd_m`` = √(σ_N² + σ_E²) when both
          are. σ = √diag(cov) at the epochs ``t_cov``, interpolated linearly in time between
          them, held for one epoch spacing beyond the first and last epoch and NaN further
          out (never extrapolated over a span with no covariance).
        """
        import pandas as pd

        tr = self.trajectory
        cols: dict[str, FloatArray] = {
            "t_s": tr.t, "lat_rad": tr.lla[:, 0], "lon_rad": tr.lla[:, 1], "alt_m": tr.alt,
        }
        if origin_lla is None:
            origin_lla = self.origin_lla
        if origin_lla is not None and "pos_h" in self.provides:
            pos = tr.pos_n(np.asarray(origin_lla, dtype=float))
            cols.update(pos_n_m=pos[:, 0], pos_e_m=pos[:, 1], pos_d_m=pos[:, 2])
        cols.update(vel_n_mps=tr.vel_n[:, 0], vel_e_mps=tr.vel_n[:, 1],
                    vel_d_mps=tr.vel_n[:, 2])
        if tr.q_nb is not None:
            rph = tr.to_rph()
            cols.update(roll_rad=rph[:, 0], pitch_rad=rph[:, 1], yaw_rad=rph[:, 2])
        for name, unit, a in (("bias_gyro", "radps", tr.bias_gyro),
                              ("bias_accel", "mps2", tr.bias_accel)):
            if a is not None:
                cols.update({f"{name}_{ax}_{unit}": a[:, j] for j, ax in enumerate("xyz")})
        if tr.bias_baro is not None:
            cols["baro_bias_m"] = tr.bias_baro
        n = tr.t.size
        if self.baro is not None and self.baro.scale is not None:
            cols["baro_scale"] = np.full(n, float(self.baro.scale.est))
        if self.baro is not None and self.baro.latency_s is not None:
            cols["baro_latency_s"] = np.full(n, float(self.baro.latency_s.est))
        if self.cov is not None and self.t_cov is not None:
            var = np.diagonal(self.cov, axis1=1, axis2=2)  # (M, 18)
            have = np.any(np.isfinite(var), axis=0)
            for j in np.flatnonzero(have):
                cols[SD_COLUMNS[j]] = self._sd_at(tr.t, var[:, j])
            if have[0] and have[1]:
                cols["horiz_sd_m"] = self._sd_at(tr.t, var[:, 0] + var[:, 1])
        return pd.DataFrame(cols)

    def sigma_at(self, t: FloatArray, component: int) -> FloatArray | None:
        """One-sigma of ``ERROR_STATE`` component ``component`` at the times ``t`` (the rules
        of ``to_dataframe``'s sigma columns); None without a covariance or a finite variance
        of that component."""
        if self.cov is None or self.t_cov is None:
            return None
        var = self.cov[:, component, component]
        if not np.any(np.isfinite(var)):
            return None
        return self._sd_at(np.asarray(t, dtype=float), var)

    def _sd_at(self, t: FloatArray, var: FloatArray) -> FloatArray:
        """√var at the covariance epochs, interpolated to ``t`` (see ``to_dataframe``)."""
        assert self.t_cov is not None
        tc = self.t_cov
        sd = np.sqrt(np.clip(var, 0.0, None))
        out = np.interp(t, tc, sd)
        hold = float(np.median(np.diff(tc))) if tc.size > 1 else 0.0
        out[(t < tc[0] - hold) | (t > tc[-1] + hold)] = np.nan
        return out

    def replace(self, **changes: Any) -> Estimate:
        from dataclasses import replace

        return replace(self, **changes)

    def with_real_time_of(self, first: Estimate, why: str) -> Estimate:
        """This estimate (a pass run again after a whole-drive check of ``first``) with
        ``first``'s real-time answers (``online``, ``lag``, their covariances and
        ``info["online_from_s"]``): a decision taken at the end of the drive may change the
        final answer only. ``info["real_time_pass"]``: {"pass": "first", "why",
        "decided_at_s": the end of the drive, from its start}."""
        info = dict(self.info)
        if "online_from_s" in first.info:
            info["online_from_s"] = first.info["online_from_s"]
        if first.online is None:
            return self
        t = self.trajectory.t
        info["real_time_pass"] = {"pass": "first", "why": why,
                                  "decided_at_s": float(t[-1] - t[0]) if t.size else 0.0}
        return self.replace(online=first.online, online_cov=first.online_cov, lag=first.lag,
                            lag_cov=first.lag_cov, info=info)
