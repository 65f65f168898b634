"""The sensor streams on one clock (immutable IMU, GNSS, baro and magnetometer samples) and
the ``Drive`` that bundles them with its origin and optional truth (a ``Trajectory``).

The conventions are those of ``vnav_graph.types`` (which exports the classes shipped
here): one clock in seconds, SI units, ``b`` the IMU body frame forward-right-down, ``lla``
geodetic latitude and longitude [rad] and height [m]. Each record validates in
``__post_init__`` (``types.checks``) and raises a ``ValueError`` naming the stream and the
field; nothing is repaired here.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .checks import ALT_RANGE, as_array, check_finite, check_lla, check_shape, check_time
from .trajectory import Trajectory

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]
BoolArray = NDArray[np.bool_]


# Physical plausibility limits used by validation (generous; they catch unit mistakes).
_MAX_GYRO = 50.0  # rad/s (≈ 2900 deg/s): larger means degrees were passed as radians
_MAX_ACCEL = 2000.0  # m/s^2 (≈ 200 g)
_PRESSURE_RANGE = (2.0e3, 1.2e5)  # Pa: 20 hPa (≈ 26 km) .. 1200 hPa


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
            object.__setattr__(self, f, as_array(getattr(self, f)))
        check_time("imu", self.t)
        n = self.t.size
        check_shape("imu.gyro_b", self.gyro_b, (n, 3))
        check_shape("imu.accel_b", self.accel_b, (n, 3))
        check_finite("imu.gyro_b", self.gyro_b)
        check_finite("imu.accel_b", self.accel_b)
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
            object.__setattr__(self, f, as_array(getattr(self, f)))
        for f in ("vel_n", "vel_sd"):
            if getattr(self, f) is not None:
                object.__setattr__(self, f, as_array(getattr(self, f)))
        check_time("gnss", self.t)
        n = self.t.size
        check_shape("gnss.lla", self.lla, (n, 3))
        check_shape("gnss.pos_sd", self.pos_sd, (n, 3))
        check_shape("gnss.vel_n", self.vel_n, (n, 3))
        check_shape("gnss.vel_sd", self.vel_sd, (n, 3))
        check_shape("gnss.lever_arm_b", self.lever_arm_b, (3,))
        for f in ("lla", "pos_sd", "vel_n", "vel_sd", "lever_arm_b"):
            check_finite(f"gnss.{f}", getattr(self, f))
        check_lla("gnss.lla", self.lla)
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
        object.__setattr__(self, "t", as_array(self.t))
        check_time("baro", self.t)
        n = self.t.size
        if self.pressure is None and self.alt is None:
            raise ValueError("baro: needs pressure or alt")
        if self.pressure is not None:
            object.__setattr__(self, "pressure", as_array(self.pressure))
            check_shape("baro.pressure", self.pressure, (n,))
            check_finite("baro.pressure", self.pressure)
            lo, hi = _PRESSURE_RANGE
            if np.any(self.pressure < lo) or np.any(self.pressure > hi):
                hint = " (hPa passed as Pa?)" if np.max(self.pressure) < 1200 else ""
                raise ValueError(f"baro.pressure: outside [{lo:g}, {hi:g}] Pa{hint}")
        if self.alt is not None:
            object.__setattr__(self, "alt", as_array(self.alt))
            check_shape("baro.alt", self.alt, (n,))
            check_finite("baro.alt", self.alt)
            lo, hi = ALT_RANGE
            if np.any(self.alt < lo) or np.any(self.alt > hi):
                raise ValueError(f"baro.alt: outside [{lo:g}, {hi:g}] m (feet or Pa passed?)")

    def __len__(self) -> int:
        return int(self.t.size)

    @property
    def altitude(self) -> FloatArray:
        """Barometric altitude [m, +up]: ``alt`` if given, else ISA altitude of ``pressure``."""
        if self.alt is not None:
            return self.alt
        from ..geo.atmosphere import isa_altitude

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
        object.__setattr__(self, "t", as_array(self.t))
        check_time("mag", self.t)
        object.__setattr__(self, "field_b", as_array(self.field_b))
        check_shape("mag.field_b", self.field_b, (self.t.size, 3))
        check_finite("mag.field_b", self.field_b)
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


# ``Drive.height_reference`` values and what they mean
HEIGHT_DATUMS = {
    "ellipsoid": "height above the WGS-84 ellipsoid",
    "msl": "height above mean sea level (as the log's GNSS reports it)",
}


@dataclass(frozen=True)
class BaroTruth:
    """True barometer error parameters of a simulated drive (model of docs/design.md).

    ``h_baro(t) - h0 = (1 + scale) * (h(t - latency_s) - h0) + b(t) + v`` with
    ``h0 = Drive.origin_lla[2]``; b(t) is stored in ``Drive.truth.bias_baro``.
    """

    scale: float
    latency_s: float


# The Drive's optional streams (fields named so): each is checked against the IMU's time span
# and cut by ``Drive.until``; a new sensor's stream is a field and a name here.
EVENT_STREAMS = ("gnss", "baro", "mag")


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
        for name in EVENT_STREAMS:
            s = getattr(self, name)
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
        for name in EVENT_STREAMS:
            s = getattr(self, name)
            if s is not None:
                kw[name] = s.select(s.t <= t1)
        return self.replace(**kw)
