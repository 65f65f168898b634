"""Core data types: drives, trajectories and estimates on one clock, and the sensor streams
(``vnav_graph.types.streams``).

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

from .streams import (
    BaroStream,
    FloatArray,
    GnssStream,
    ImuStream,
    MagStream,
    as_array,
    check_lla,
    check_shape,
    check_time,
)

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

# ``Drive.height_reference`` values and what they mean
HEIGHT_DATUMS = {
    "ellipsoid": "height above the WGS-84 ellipsoid",
    "msl": "height above mean sea level (as the log's GNSS reports it)",
}

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

AT_MEMO = 2  # Trajectory.at results kept per trajectory


@dataclass(frozen=True)
class Trajectory:
    """A navigation trajectory (truth or estimate).

    Parameters
    ----------
    t : (N,) [s]
    lla : (N, 3) latitude [rad], longitude [rad], ellipsoidal height [m]. Estimators that
        only estimate the vertical channel set latitude/longitude to NaN (``provides`` says so).
    vel_n : (N, 3) NED velocity [m/s]; NaN north/east for vertical-only estimators.
    q_nb : (N, 4) or None, attitude quaternion (w, x, y, z) mapping b into n.
    bias_gyro, bias_accel : (N, 3) or None [rad/s], [m/s^2]
    bias_baro : (N,) or None, baro Gauss-Markov bias b(t) [m]
    """

    t: FloatArray
    lla: FloatArray
    vel_n: FloatArray
    q_nb: FloatArray | None = None
    bias_gyro: FloatArray | None = None
    bias_accel: FloatArray | None = None
    bias_baro: FloatArray | None = None

    def __post_init__(self) -> None:
        for f in ("t", "lla", "vel_n", "q_nb", "bias_gyro", "bias_accel", "bias_baro"):
            if getattr(self, f) is not None:
                object.__setattr__(self, f, as_array(getattr(self, f)))
        check_time("trajectory", self.t)
        n = self.t.size
        check_shape("trajectory.lla", self.lla, (n, 3))
        check_shape("trajectory.vel_n", self.vel_n, (n, 3))
        check_shape("trajectory.q_nb", self.q_nb, (n, 4))
        check_shape("trajectory.bias_gyro", self.bias_gyro, (n, 3))
        check_shape("trajectory.bias_accel", self.bias_accel, (n, 3))
        check_shape("trajectory.bias_baro", self.bias_baro, (n,))
        if not np.all(np.isfinite(self.lla[:, 2])):
            raise ValueError("trajectory.lla: height contains NaN or inf")

    def __len__(self) -> int:
        return int(self.t.size)

    @property
    def alt(self) -> FloatArray:
        """Ellipsoidal height [m, +up]."""
        return self.lla[:, 2]

    @property
    def vel_down(self) -> FloatArray:
        return self.vel_n[:, 2]

    def pos_n(self, origin_lla: FloatArray) -> FloatArray:
        """Tangent-plane NED position relative to ``origin_lla`` [m], shape (N, 3)."""
        from ..geo.frames import lla_to_ned

        return lla_to_ned(self.lla, origin_lla)

    def at(self, t_query: FloatArray) -> Trajectory:
        """Interpolate to ``t_query`` (linear; slerp for attitude). Queries must lie inside.

        The last ``AT_MEMO`` results are kept (evaluating ten estimators interpolates the
        truth to the same epochs again and again; the slerp costs ~0.1 s per 24,000 epochs);
        their arrays are read-only."""
        tq = np.asarray(t_query, dtype=float)
        import hashlib

        key = (tq.shape, hashlib.blake2b(np.ascontiguousarray(tq).tobytes(),
                                         digest_size=16).digest())
        memo: dict[Any, Trajectory] = self.__dict__.setdefault("_at_memo", {})
        hit = memo.get(key)
        if hit is None:
            hit = self._interp(tq)
            for a in (hit.t, hit.lla, hit.vel_n, hit.q_nb, hit.bias_gyro, hit.bias_accel,
                      hit.bias_baro):
                if a is not None:
                    a.flags.writeable = False
            while len(memo) >= AT_MEMO:
                memo.pop(next(iter(memo)))
            memo[key] = hit
        return hit

    def __getstate__(self) -> dict[str, Any]:
        return {k: v for k, v in self.__dict__.items() if k != "_at_memo"}

    def _interp(self, tq: FloatArray) -> Trajectory:
        if tq.size and (tq[0] < self.t[0] - 1e-9 or tq[-1] > self.t[-1] + 1e-9):
            raise ValueError("trajectory.at: query times outside the trajectory span")
        tq = np.clip(tq, self.t[0], self.t[-1])  # absorb round-off at the ends

        def lin(a: FloatArray | None) -> FloatArray | None:
            if a is None:
                return None
            if a.ndim == 1:
                return np.interp(tq, self.t, a)
            return np.column_stack([np.interp(tq, self.t, a[:, j]) for j in range(a.shape[1])])

        q = None
        if self.q_nb is not None:
            from ..geo.frames import slerp_quat

            q = slerp_quat(self.t, self.q_nb, tq)
        return Trajectory(
            tq,
            lin(self.lla),  # type: ignore[arg-type]
            lin(self.vel_n),  # type: ignore[arg-type]
            q,
            lin(self.bias_gyro),
            lin(self.bias_accel),
            lin(self.bias_baro),
        )

    def slice(self, t0: float, t1: float) -> Trajectory:
        m = (self.t >= t0) & (self.t <= t1)

        def s(a: FloatArray | None) -> FloatArray | None:
            return None if a is None else a[m]

        return Trajectory(
            self.t[m], self.lla[m], self.vel_n[m], s(self.q_nb), s(self.bias_gyro),
            s(self.bias_accel), s(self.bias_baro),
        )

    def to_rph(self) -> FloatArray:
        """Roll, pitch, yaw [rad], shape (N, 3) (requires ``q_nb``)."""
        if self.q_nb is None:
            raise ValueError("trajectory.q_nb: no attitude in this trajectory")
        from ..geo.frames import quat_to_rph

        return quat_to_rph(self.q_nb)


@dataclass(frozen=True)
class BaroTruth:
    """True barometer error parameters of a simulated drive (model of docs/design.md).

    ``h_baro(t) - h0 = (1 + scale) * (h(t - latency_s) - h0) + b(t) + v`` with
    ``h0 = Drive.origin_lla[2]``; b(t) is stored in ``Drive.truth.bias_baro``.
    """

    scale: float
    latency_s: float


@dataclass(frozen=True)
class Drive:
    """One recorded or simulated test drive: streams on one clock plus optional truth."""

    imu: ImuStream
    gnss: GnssStream | None
    baro: BaroStream | None
    origin_lla: FloatArray
    truth: Trajectory | None = None
    baro_truth: BaroTruth | None = None
    meta: MappingProxyType[str, Any] = field(default_factory=lambda: MappingProxyType({}))
    mag: MagStream | None = None  # magnetometer, when the log or simulation has one

    def __post_init__(self) -> None:
        object.__setattr__(self, "origin_lla", as_array(self.origin_lla))
        check_shape("drive.origin_lla", self.origin_lla, (3,))
        check_lla("drive.origin_lla", self.origin_lla[None, :])
        if not isinstance(self.meta, MappingProxyType):
            object.__setattr__(self, "meta", MappingProxyType(dict(self.meta)))
        t0, t1 = self.imu.t[0], self.imu.t[-1]
        for name, s in (("gnss", self.gnss), ("baro", self.baro), ("mag", self.mag)):
            if s is not None and (s.t[-1] < t0 or s.t[0] > t1):
                raise ValueError(f"drive.{name}: stream does not overlap the IMU time span "
                                 "(time stamps in different units or clocks?)")

    @property
    def name(self) -> str:
        return str(self.meta.get("name", "drive"))

    @property
    def duration_s(self) -> float:
        return float(self.imu.t[-1] - self.imu.t[0])

    @property
    def source(self) -> str:
        return str(self.meta.get("source", "log"))

    @property
    def height_reference(self) -> str:
        """Datum of every height in the drive: ``"ellipsoid"`` (WGS-84; simulated drives,
        phones, PX4 with an ellipsoidal height) or ``"msl"`` (a log whose GNSS gives heights
        above mean sea level, e.g. ArduPilot's GPS.Alt); ``height_datum`` says it in words."""
        return str(self.meta.get("height_reference", "ellipsoid"))

    @property
    def height_datum(self) -> str:
        return HEIGHT_DATUMS.get(self.height_reference, self.height_reference)

    def replace(self, **changes: Any) -> Drive:
        from dataclasses import replace

        return replace(self, **changes)

    def until(self, t1: float) -> Drive:
        """The drive with every stream and the truth ending at ``t1`` (the drive's clock [s]):
        what a causal estimator has seen at ``t1``."""
        t0 = float(self.imu.t[0])
        kw: dict[str, Any] = {"imu": self.imu.slice(t0, t1)}
        if self.truth is not None:
            kw["truth"] = self.truth.slice(t0, t1)
        for name in ("gnss", "baro", "mag"):
            s = getattr(self, name)
            if s is not None:
                kw[name] = s.select(s.t <= t1)
        return self.replace(**kw)


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
