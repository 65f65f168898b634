"""Core data types: immutable sensor streams on one clock, drives, trajectories, estimates.

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
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

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

# Physical plausibility limits used by validation (generous; they catch unit mistakes).
_MAX_GYRO = 50.0  # rad/s (≈ 2900 deg/s): larger means degrees were passed as radians
_MAX_ACCEL = 2000.0  # m/s^2 (≈ 200 g)
_PRESSURE_RANGE = (2.0e3, 1.2e5)  # Pa: 20 hPa (≈ 26 km) .. 1200 hPa
_ALT_RANGE = (-1000.0, 60000.0)  # m


def _arr(x: Any, dtype: Any = np.float64) -> FloatArray:
    # an array that is already read-only, of this dtype and owns its memory (another record's
    # field, e.g. a drive rebuilt with ``Drive.replace``) cannot change: shared, not copied
    # (the copies doubled the truth arrays while a simulated drive was assembled)
    if (isinstance(x, np.ndarray) and x.dtype == dtype and x.base is None
            and not x.flags.writeable and x.flags.c_contiguous):
        return x
    a = np.array(x, dtype=dtype, copy=True)
    a.setflags(write=False)
    return a


def _check_time(name: str, t: FloatArray) -> None:
    if t.ndim != 1:
        raise ValueError(f"{name}.t: expected shape (N,), got {t.shape}")
    if t.size == 0:
        raise ValueError(f"{name}.t: stream is empty")
    if not np.all(np.isfinite(t)):
        raise ValueError(f"{name}.t: contains NaN or inf")
    d = np.diff(t)
    if np.any(d == 0):
        i = int(np.flatnonzero(d == 0)[0])
        raise ValueError(f"{name}.t: duplicated time stamp {t[i]!r} at index {i + 1}")
    if np.any(d < 0):
        i = int(np.flatnonzero(d < 0)[0])
        raise ValueError(f"{name}.t: not monotonic (t[{i + 1}] = {t[i + 1]!r} < {t[i]!r})")


def _check_shape(name: str, a: FloatArray | None, shape: tuple[int, ...]) -> None:
    if a is None:
        return
    if a.shape != shape:
        raise ValueError(f"{name}: expected shape {shape}, got {a.shape}")


def _check_finite(name: str, a: FloatArray | None) -> None:
    if a is not None and not np.all(np.isfinite(a)):
        n_bad = int(np.sum(~np.isfinite(a)))
        raise ValueError(f"{name}: contains {n_bad} NaN or inf value(s)")


def _check_lla(name: str, lla: FloatArray) -> None:
    if np.any(np.abs(lla[:, 0]) > np.pi / 2 + 1e-12) or np.any(np.abs(lla[:, 1]) > 2 * np.pi):
        raise ValueError(
            f"{name}: latitude/longitude out of range for radians (degrees passed as radians?)"
        )
    lo, hi = _ALT_RANGE
    if np.any(lla[:, 2] < lo) or np.any(lla[:, 2] > hi):
        raise ValueError(f"{name}: height outside [{lo:g}, {hi:g}] m")


@dataclass(frozen=True)
class ImuStream:
    """Inertial samples, instantaneous (point) values at ``t``.

    Parameters
    ----------
    t : (N,) [s]
    gyro_b : (N, 3) angular rate of b relative to inertial space, resolved in b [rad/s]
    accel_b : (N, 3) specific force (gravity included: a level IMU at rest reads
        about (0, 0, -9.8)) resolved in b [m/s^2]
    spec : the ``ImuSpec`` the data were generated with or are believed to follow
    """

    t: FloatArray
    gyro_b: FloatArray
    accel_b: FloatArray
    spec: Any = None

    def __post_init__(self) -> None:
        for f in ("t", "gyro_b", "accel_b"):
            object.__setattr__(self, f, _arr(getattr(self, f)))
        _check_time("imu", self.t)
        n = self.t.size
        _check_shape("imu.gyro_b", self.gyro_b, (n, 3))
        _check_shape("imu.accel_b", self.accel_b, (n, 3))
        _check_finite("imu.gyro_b", self.gyro_b)
        _check_finite("imu.accel_b", self.accel_b)
        if np.max(np.abs(self.gyro_b)) > _MAX_GYRO:
            raise ValueError(
                f"imu.gyro_b: |rate| up to {np.max(np.abs(self.gyro_b)):.1f} rad/s "
                "(degrees/s passed as rad/s?)"
            )
        if np.max(np.abs(self.accel_b)) > _MAX_ACCEL:
            raise ValueError("imu.accel_b: specific force above 200 g (wrong unit?)")

    def __len__(self) -> int:
        return int(self.t.size)

    @property
    def rate_hz(self) -> float:
        return float(1.0 / np.median(np.diff(self.t))) if self.t.size > 1 else float("nan")

    def slice(self, t0: float, t1: float) -> ImuStream:
        m = (self.t >= t0) & (self.t <= t1)
        return ImuStream(self.t[m], self.gyro_b[m], self.accel_b[m], self.spec)


@dataclass(frozen=True)
class GnssStream:
    """GNSS position (and optionally velocity) fixes of the antenna.

    Parameters
    ----------
    t : (N,) [s] time of validity on the common clock
    lla : (N, 3) antenna latitude [rad], longitude [rad], ellipsoidal height [m]
    pos_sd : (N, 3) one-sigma of the fix along north, east, down [m]
    vel_n : (N, 3) or None, antenna velocity in NED [m/s]
    vel_sd : (N, 3) or None [m/s]
    lever_arm_b : (3,) antenna position relative to the IMU, resolved in b [m]
    spec : the ``GnssSpec``
    """

    t: FloatArray
    lla: FloatArray
    pos_sd: FloatArray
    vel_n: FloatArray | None = None
    vel_sd: FloatArray | None = None
    lever_arm_b: FloatArray = field(default_factory=lambda: np.zeros(3))
    spec: Any = None

    def __post_init__(self) -> None:
        for f in ("t", "lla", "pos_sd", "lever_arm_b"):
            object.__setattr__(self, f, _arr(getattr(self, f)))
        for f in ("vel_n", "vel_sd"):
            if getattr(self, f) is not None:
                object.__setattr__(self, f, _arr(getattr(self, f)))
        _check_time("gnss", self.t)
        n = self.t.size
        _check_shape("gnss.lla", self.lla, (n, 3))
        _check_shape("gnss.pos_sd", self.pos_sd, (n, 3))
        _check_shape("gnss.vel_n", self.vel_n, (n, 3))
        _check_shape("gnss.vel_sd", self.vel_sd, (n, 3))
        _check_shape("gnss.lever_arm_b", self.lever_arm_b, (3,))
        for f in ("lla", "pos_sd", "vel_n", "vel_sd", "lever_arm_b"):
            _check_finite(f"gnss.{f}", getattr(self, f))
        _check_lla("gnss.lla", self.lla)
        if np.any(self.pos_sd <= 0):
            raise ValueError("gnss.pos_sd: standard deviations must be > 0")
        if (self.vel_n is None) != (self.vel_sd is None):
            raise ValueError("gnss.vel_sd: must be given exactly when vel_n is given")
        if self.vel_sd is not None and np.any(self.vel_sd <= 0):
            raise ValueError("gnss.vel_sd: standard deviations must be > 0")
        if self.vel_n is not None and np.max(np.abs(self.vel_n)) > 1000.0:
            raise ValueError("gnss.vel_n: speed above 1000 m/s (wrong unit?)")

    def __len__(self) -> int:
        return int(self.t.size)

    @property
    def alt(self) -> FloatArray:
        """Antenna height [m, +up]: ``lla[:, 2]``, in the drive's height datum
        (``Drive.height_reference``)."""
        return self.lla[:, 2]

    def select(self, mask: NDArray[np.bool_]) -> GnssStream:
        """Sub-stream of the fixes where ``mask`` is True (used for outages and holdout)."""
        return GnssStream(
            self.t[mask],
            self.lla[mask],
            self.pos_sd[mask],
            None if self.vel_n is None else self.vel_n[mask],
            None if self.vel_sd is None else self.vel_sd[mask],
            self.lever_arm_b,
            self.spec,
        )


@dataclass(frozen=True)
class BaroStream:
    """Barometric altimeter samples: static pressure and/or the altimeter's altitude.

    Parameters
    ----------
    t : (N,) [s]
    pressure : (N,) or None, static pressure [Pa]
    alt : (N,) or None, barometric altitude [m, +up]. When only ``pressure`` is given the
        standard-atmosphere altitude is used (``vnav_graph.geo.atmosphere``).
    spec : the ``BaroSpec``
    """

    t: FloatArray
    pressure: FloatArray | None = None
    alt: FloatArray | None = None
    spec: Any = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "t", _arr(self.t))
        _check_time("baro", self.t)
        n = self.t.size
        if self.pressure is None and self.alt is None:
            raise ValueError("baro: needs pressure or alt")
        if self.pressure is not None:
            object.__setattr__(self, "pressure", _arr(self.pressure))
            _check_shape("baro.pressure", self.pressure, (n,))
            _check_finite("baro.pressure", self.pressure)
            lo, hi = _PRESSURE_RANGE
            if np.any(self.pressure < lo) or np.any(self.pressure > hi):
                hint = " (hPa passed as Pa?)" if np.max(self.pressure) < 1200 else ""
                raise ValueError(f"baro.pressure: outside [{lo:g}, {hi:g}] Pa{hint}")
        if self.alt is not None:
            object.__setattr__(self, "alt", _arr(self.alt))
            _check_shape("baro.alt", self.alt, (n,))
            _check_finite("baro.alt", self.alt)
            lo, hi = _ALT_RANGE
            if np.any(self.alt < lo) or np.any(self.alt > hi):
                raise ValueError(f"baro.alt: outside [{lo:g}, {hi:g}] m (feet or Pa passed?)")

    def __len__(self) -> int:
        return int(self.t.size)

    @property
    def altitude(self) -> FloatArray:
        """Barometric altitude [m, +up]: ``alt`` if given, else ISA altitude of ``pressure``."""
        if self.alt is not None:
            return self.alt
        from .geo.atmosphere import isa_altitude

        assert self.pressure is not None
        return isa_altitude(self.pressure)

    def select(self, mask: NDArray[np.bool_]) -> BaroStream:
        return BaroStream(
            self.t[mask],
            None if self.pressure is None else self.pressure[mask],
            None if self.alt is None else self.alt[mask],
            self.spec,
        )


_MAX_FIELD_UT = 1000.0  # µT: the Earth's field is 22–67 µT; larger means nT or mG passed


@dataclass(frozen=True)
class MagStream:
    """Three-axis magnetometer samples in body axes (forward-right-down, as the IMU).

    Parameters
    ----------
    t : (N,) [s], on the drive's clock
    field_b : (N, 3) magnetic flux density in b [µT]; calibration the log applied (offsets)
        stays applied, what is left is the estimators' hard-iron bias state
    sd_ut : white noise σ per axis [µT] (sensor noise plus unmodelled interference)
    """

    t: FloatArray
    field_b: FloatArray
    sd_ut: float = 1.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "t", _arr(self.t))
        _check_time("mag", self.t)
        object.__setattr__(self, "field_b", _arr(self.field_b))
        _check_shape("mag.field_b", self.field_b, (self.t.size, 3))
        _check_finite("mag.field_b", self.field_b)
        if np.any(np.abs(self.field_b) > _MAX_FIELD_UT):
            raise ValueError(f"mag.field_b: |component| above {_MAX_FIELD_UT:g} µT "
                             "(nT or milligauss passed as µT?)")
        if not (np.isfinite(self.sd_ut) and self.sd_ut > 0):
            raise ValueError(f"mag.sd_ut: must be a positive number of µT, got {self.sd_ut!r}")
        object.__setattr__(self, "sd_ut", float(self.sd_ut))

    def __len__(self) -> int:
        return int(self.t.size)

    def select(self, mask: NDArray[np.bool_]) -> MagStream:
        return MagStream(self.t[mask], self.field_b[mask], self.sd_ut)


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
                object.__setattr__(self, f, _arr(getattr(self, f)))
        _check_time("trajectory", self.t)
        n = self.t.size
        _check_shape("trajectory.lla", self.lla, (n, 3))
        _check_shape("trajectory.vel_n", self.vel_n, (n, 3))
        _check_shape("trajectory.q_nb", self.q_nb, (n, 4))
        _check_shape("trajectory.bias_gyro", self.bias_gyro, (n, 3))
        _check_shape("trajectory.bias_accel", self.bias_accel, (n, 3))
        _check_shape("trajectory.bias_baro", self.bias_baro, (n,))
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
        from .geo.frames import lla_to_ned

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
            from .geo.frames import slerp_quat

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
        from .geo.frames import quat_to_rph

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
        object.__setattr__(self, "origin_lla", _arr(self.origin_lla))
        _check_shape("drive.origin_lla", self.origin_lla, (3,))
        _check_lla("drive.origin_lla", self.origin_lla[None, :])
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
    origin_lla : (3,) or None, the drive's tangent-plane origin (``vnav_graph.runner`` sets it;
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
            cov = _arr(self.cov)
            if self.t_cov is None:
                raise ValueError("estimate.t_cov: required when cov is given")
            t_cov = _arr(self.t_cov)
            _check_shape("estimate.cov", cov, (t_cov.size, ERROR_STATE_DIM, ERROR_STATE_DIM))
            object.__setattr__(self, "cov", cov)
            object.__setattr__(self, "t_cov", t_cov)
        for name, tr in (("online", self.online), ("lag", self.lag)):
            c = getattr(self, f"{name}_cov")
            if c is None:
                continue
            if tr is None:
                raise ValueError(f"estimate.{name}_cov: given without estimate.{name}")
            c = _arr(c)
            _check_shape(f"estimate.{name}_cov", c, (tr.t.size, ERROR_STATE_DIM, ERROR_STATE_DIM))
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
            origin, set when the estimator ran through ``vnav_graph.runner``, e.g.
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
