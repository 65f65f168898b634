"""Configuration: frozen dataclasses with SI defaults and validation.

Noise specs state their kind in the field name:
``*_noise_density`` is a white-noise root PSD (rad/s/√Hz or m/s²/√Hz), ``*_bias_sd`` the
steady-state sigma of a first-order Gauss-Markov bias with correlation time ``*_bias_tau``,
``*_bias_rw`` a bias random walk root PSD (rad/s/√s or m/s²/√s), ``*_scale_sd`` a random
constant scale-factor sigma. Discrete variances are computed only in
``vnav_graph.sensors.noise``.

IMU presets (datasheet values, typical, 1σ; converted to SI below):

- ``consumer`` — TDK InvenSense MPU-9250 (PS-MPU-9250A-01 rev 1.1): gyro rate noise
  0.01 °/s/√Hz, accel noise 300 µg/√Hz. Bias instability is not in that datasheet; we use
  the values commonly measured by Allan variance on this part (≈ 10 °/h gyro, ≈ 0.1 mg accel)
  plus a turn-on residual after a static calibration (0.05 °/s, 5 mg).
- ``industrial`` — Analog Devices ADIS16465-1 datasheet (rev. C): gyro in-run bias stability
  2 °/h, angle random walk 0.15 °/√h; accel in-run bias stability 3.6 µg, velocity random
  walk 0.012 m/s/√h; turn-on residual after calibration assumed 10 °/h and 1 mg.
- ``tactical`` — Honeywell HG4930 datasheet: gyro in-run bias stability 0.25 °/h, ARW
  0.04 °/√h; accel in-run bias stability 0.025 mg, VRW 0.03 m/s/√h; bias repeatability
  7 °/h and 1.7 mg are not simulated as turn-on (we assume a calibrated unit: 1 °/h, 0.1 mg).
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from .sensors.magnetometer import MagSpec

DEG = np.pi / 180.0
DEG_PER_HR = DEG / 3600.0
G0 = 9.80665
MG = 1e-3 * G0  # milli-g [m/s^2]
UG = 1e-6 * G0


def _positive(obj: Any, *names: str) -> None:
    for n in names:
        v = getattr(obj, n)
        if not np.isfinite(v) or v < 0:
            raise ValueError(f"{type(obj).__name__}.{n}: must be finite and >= 0, got {v!r}")


def _range(obj: Any, *names: str) -> None:
    for n in names:
        w = getattr(obj, n)
        if len(w) != 2 or not (np.isfinite(w[0]) and np.isfinite(w[1]) and 0 < w[0] <= w[1]):
            raise ValueError(f"{type(obj).__name__}.{n}: must be (lo, hi) with 0 < lo <= hi, "
                             f"got {w!r}")


@dataclass(frozen=True)
class ImuSpec:
    """IMU error model, identical on the three axes.

    name: the preset's name (``IMU_PRESETS``) or "custom".
    gyro_noise_density: gyro white noise [rad/s/√Hz].
    gyro_bias_sd: steady-state σ of the Gauss-Markov gyro bias [rad/s].
    gyro_bias_tau: its correlation time [s] (inf: a random constant).
    gyro_bias_rw: gyro bias random walk on top of it [rad/s/√s].
    accel_noise_density: accelerometer white noise [m/s²/√Hz].
    accel_bias_sd: steady-state σ of the Gauss-Markov accelerometer bias [m/s²].
    accel_bias_tau: its correlation time [s] (inf: a random constant).
    accel_bias_rw: accelerometer bias random walk on top of it [m/s²/√s].
    accel_scale_sd: σ of the random-constant accelerometer scale factor per axis [-].
    """

    name: str = "custom"
    gyro_noise_density: float = 0.01 * DEG
    gyro_bias_sd: float = 0.05 * DEG
    gyro_bias_tau: float = 3600.0
    gyro_bias_rw: float = 0.0
    accel_noise_density: float = 300 * UG
    accel_bias_sd: float = 5 * MG
    accel_bias_tau: float = 3600.0
    accel_bias_rw: float = 0.0
    accel_scale_sd: float = 0.0

    def __post_init__(self) -> None:
        _positive(
            self, "gyro_noise_density", "gyro_bias_sd", "gyro_bias_rw", "accel_noise_density",
            "accel_bias_sd", "accel_bias_rw", "accel_scale_sd",
        )
        for n in ("gyro_bias_tau", "accel_bias_tau"):
            if not getattr(self, n) > 0:
                raise ValueError(f"ImuSpec.{n}: must be > 0 (inf for a random constant)")

    def noiseless(self) -> ImuSpec:
        return ImuSpec(name=f"{self.name}-noiseless", gyro_noise_density=0.0, gyro_bias_sd=0.0,
                       accel_noise_density=0.0, accel_bias_sd=0.0)


IMU_PRESETS: dict[str, ImuSpec] = {
    "consumer": ImuSpec(
        name="consumer",
        gyro_noise_density=0.01 * DEG,  # MPU-9250: 0.01 °/s/√Hz
        gyro_bias_sd=0.05 * DEG,
        gyro_bias_tau=600.0,
        gyro_bias_rw=10 * DEG_PER_HR / np.sqrt(600.0),
        accel_noise_density=300 * UG,  # MPU-9250: 300 µg/√Hz
        accel_bias_sd=5 * MG,
        accel_bias_tau=600.0,
        accel_bias_rw=0.1 * MG / np.sqrt(600.0),
        accel_scale_sd=1e-3,
    ),
    "industrial": ImuSpec(
        name="industrial",
        gyro_noise_density=0.15 * DEG / 60.0,  # ADIS16465: ARW 0.15 °/√h
        gyro_bias_sd=10 * DEG_PER_HR,
        gyro_bias_tau=3600.0,
        gyro_bias_rw=2 * DEG_PER_HR / np.sqrt(3600.0),  # in-run stability 2 °/h
        accel_noise_density=0.012 / 60.0,  # VRW 0.012 m/s/√h
        accel_bias_sd=1 * MG,
        accel_bias_tau=3600.0,
        accel_bias_rw=3.6 * UG / np.sqrt(3600.0),
        accel_scale_sd=2e-4,
    ),
    "tactical": ImuSpec(
        name="tactical",
        gyro_noise_density=0.04 * DEG / 60.0,  # HG4930: ARW 0.04 °/√h
        gyro_bias_sd=1 * DEG_PER_HR,
        gyro_bias_tau=3600.0,
        gyro_bias_rw=0.25 * DEG_PER_HR / np.sqrt(3600.0),  # in-run 0.25 °/h
        accel_noise_density=0.03 / 60.0,  # VRW 0.03 m/s/√h
        accel_bias_sd=0.1 * MG,
        accel_bias_tau=3600.0,
        accel_bias_rw=0.025 * MG / np.sqrt(3600.0),
        accel_scale_sd=1e-4,
    ),
}


@dataclass(frozen=True)
class GnssSpec:
    """GNSS receiver error model; the urban part (``gm_*``, ``burst_*``, ``random_outage*``,
    ``vnav_graph.simulation.gnss``) is off at its defaults and draws from its own generator.

    rate_hz: fix rate [Hz].
    pos_sd_h, pos_sd_v: white position noise per fix, horizontal / vertical [m].
    vel_sd: white velocity noise per axis [m/s] (0: no velocity output).
    latency_s: a fix is valid this long before its stamp [s] (0: perfectly stamped).
    lever_arm_b: antenna position in the body frame [m].
    outages: ((t0, t1), ...) windows without fixes [s].
    outlier_prob: probability that a fix is an outlier.
    outlier_sd: σ of the error added to an outlier [m].
    gm_sd_h, gm_sd_v: σ of the Gauss-Markov position error, north/east and down [m] (0: off).
    gm_tau_s: correlation time of that error [s].
    burst_fraction: fraction of the drive inside multipath bursts, in [0, 0.9] (0: off).
    burst_len_s: range of burst durations [s], drawn uniformly.
    burst_err_m: range of a burst's position offset [m], drawn uniformly per burst.
    burst_vel_sd: σ of the white velocity error per axis inside a burst [m/s].
    random_outages_per_hour: mean rate of random outages (Poisson) [1/h] (0: off).
    random_outage_len_s: range of random-outage durations [s], drawn uniformly.
    """

    rate_hz: float = 10.0
    pos_sd_h: float = 1.0
    pos_sd_v: float = 2.0
    vel_sd: float = 0.1
    latency_s: float = 0.0
    lever_arm_b: tuple[float, float, float] = (0.0, 0.0, 0.0)
    outages: tuple[tuple[float, float], ...] = ()
    outlier_prob: float = 0.0
    outlier_sd: float = 30.0
    # the slowly varying residual of atmosphere, orbit and diffuse multipath; with it on the
    # reported GnssStream.pos_sd is sqrt(pos_sd² + gm_sd²): the receiver's accuracy estimate
    # covers its ordinary errors
    gm_sd_h: float = 0.0
    gm_sd_v: float = 0.0
    gm_tau_s: float = 60.0
    burst_fraction: float = 0.0
    burst_len_s: tuple[float, float] = (5.0, 30.0)
    # inside a burst a fix gets the offset along a random direction (azimuth uniform, elevation
    # uniform in ±30°: mostly horizontal) plus a correlated jitter of 20 % of it; the reported
    # pos_sd does not change, so it understates the error there
    burst_err_m: tuple[float, float] = (5.0, 50.0)
    # Doppler is hit less than code ranges by multipath; the reported vel_sd does not change
    burst_vel_sd: float = 0.5
    random_outages_per_hour: float = 0.0
    random_outage_len_s: tuple[float, float] = (5.0, 20.0)

    def __post_init__(self) -> None:
        _positive(self, "pos_sd_h", "pos_sd_v", "vel_sd", "latency_s", "outlier_prob",
                  "outlier_sd", "gm_sd_h", "gm_sd_v", "burst_vel_sd",
                  "random_outages_per_hour")
        if not (np.isfinite(self.gm_tau_s) and self.gm_tau_s > 0):
            raise ValueError(f"GnssSpec.gm_tau_s: must be finite and > 0, got {self.gm_tau_s!r}")
        if not 0.0 <= self.burst_fraction <= 0.9:
            raise ValueError(f"GnssSpec.burst_fraction: must be in [0, 0.9], "
                             f"got {self.burst_fraction!r}")
        _range(self, "burst_len_s", "burst_err_m", "random_outage_len_s")
        if not self.rate_hz > 0:
            raise ValueError("GnssSpec.rate_hz: must be > 0")
        if not (self.pos_sd_h > 0 and self.pos_sd_v > 0):
            raise ValueError("GnssSpec.pos_sd_h/pos_sd_v: must be > 0")
        for w in self.outages:
            if len(w) != 2 or not w[1] > w[0]:
                raise ValueError(f"GnssSpec.outages: bad window {w!r}")


@dataclass(frozen=True)
class BaroSpec:
    """Barometric altimeter error model (docs/design.md "One barometer model"):
    h_baro(t) = h0 + (1 + s)·(h(t − τd) − h0) + b(t) + v,  ḃ = −b/τb + w,
    with h0 = ``Drive.origin_lla[2]``, as everywhere in the package (``sensors.baro``).

    rate_hz: sample rate [Hz].
    scale_sd: σ of the random-constant scale error s [-].
    scale: s itself [-] (None: drawn with ``scale_sd``).
    latency_s: τd [s], fixed.
    latency_range_s: (lo, hi): τd drawn uniformly in it instead [s] (None: ``latency_s``).
    bias_sd: steady-state σ of the Gauss-Markov bias b [m].
    bias_tau: correlation time τb of b [s].
    bias_init: b at t = 0 [m] (None: drawn with ``bias_sd``).
    noise_sd: σ of the white noise v [m].
    physical: pressure through the ISA, s from a temperature offset, b from a drifting QNH.
    isa_offset_k: the day's temperature offset from the ISA, hot > 0 [K] (``physical`` only).
    """

    rate_hz: float = 25.0
    scale_sd: float = 0.01
    scale: float | None = None
    latency_s: float = 0.1
    latency_range_s: tuple[float, float] | None = None
    bias_sd: float = 3.0
    bias_tau: float = 1800.0
    bias_init: float | None = None
    noise_sd: float = 0.3
    physical: bool = False
    # the atmosphere is ISA + dT with T0/(T0 + dT) = (1 + s)·T0/(T0 + isa_offset_k), so the
    # altimeter's effective scale is (1 + s)·T0/(T0 + isa_offset_k) − 1 (≈ s − 0.35 %/K ·
    # isa_offset_k); s is the sensor's part and BaroTruth.scale the effective one
    isa_offset_k: float = 0.0

    def __post_init__(self) -> None:
        _positive(self, "scale_sd", "bias_sd", "noise_sd")
        if not (np.isfinite(self.isa_offset_k) and abs(self.isa_offset_k) <= 50.0):
            raise ValueError(f"BaroSpec.isa_offset_k: must be within ±50 K, "
                             f"got {self.isa_offset_k!r}")
        if self.isa_offset_k != 0.0 and not self.physical:
            raise ValueError("BaroSpec.isa_offset_k: needs physical = True (it acts on pressure)")
        if not self.rate_hz > 0 or not self.bias_tau > 0:
            raise ValueError("BaroSpec.rate_hz / bias_tau: must be > 0")
        if self.latency_s > 2.0:
            raise ValueError("BaroSpec.latency_s: above 2 s (milliseconds passed as seconds?)")
        # A negative latency (down to -0.5 s) simulates a baro stamped late / advanced relative
        # to GNSS, as in seed 001 Table 1 (Td down to -0.035 s).
        if not np.isfinite(self.latency_s) or self.latency_s < -0.5:
            raise ValueError(f"BaroSpec.latency_s: must be finite and >= -0.5 s, "
                             f"got {self.latency_s!r}")


# Prior baro model of a real log that carries no spec — ONE definition, used by every
# estimator (the comparison must run on the same sensor models). Wide on purpose: MEMS and
# phone barometers are aligned to GNSS only at the start, drift with weather, airflow and
# temperature over minutes to hours (b: σ 10 m, the datasheet absolute accuracy of consumer
# MEMS barometers, ±0.5–1.5 hPa ≈ 4–12 m; τ 1 h), have ±2 % scale errors (temperature: a day
# 6 K off the ISA alone makes 2 %; seed 001), 0.5 m of noise, and an unknown latency
# N(0.1 s, 0.1 s) — expressed as a uniform range of that mean and σ (σ = width/√12), which
# is how every estimator reads a latency prior.
# Checked by benchmarks/prior_study.py: on the simulated scenarios, whose biases drift 4–6×
# slower (q = 2σ²/τ 0.010–0.014 m²/s against 0.056 here), the σ come out too wide (sortie
# rms z 0.5–0.6). τ = 1 h is the order of a real baro's error drift, which follows downwash,
# the airflow around a moving phone and temperature within minutes, faster than weather; a
# longer τ makes real logs' withheld-GNSS altitude worse (docs/baro_prior.md, "Why the
# default stays τ 1 h").
REAL_LOG_LATENCY_S = 0.1
REAL_LOG_LATENCY_SD = 0.1
REAL_LOG_BARO = BaroSpec(
    scale_sd=0.02, latency_s=REAL_LOG_LATENCY_S,
    latency_range_s=(REAL_LOG_LATENCY_S - np.sqrt(3.0) * REAL_LOG_LATENCY_SD,
                     REAL_LOG_LATENCY_S + np.sqrt(3.0) * REAL_LOG_LATENCY_SD),
    bias_sd=10.0, bias_tau=3600.0, noise_sd=0.5)


def replace_fields(obj: Any, **changes: Any) -> Any:
    """``dataclasses.replace`` that ignores keys which are not fields (for TOML overlays)."""
    from dataclasses import replace

    names = {f.name for f in fields(obj)}
    unknown = set(changes) - names
    if unknown:
        raise ValueError(f"{type(obj).__name__}: unknown field(s) {sorted(unknown)}")
    return replace(obj, **changes)


@dataclass(frozen=True)
class ScenarioConfig:
    """A simulated test drive: trajectory kind, duration, rates and sensor error models.

    name: the scenario's name (``vnav-graph run --scenario NAME``).
    kind: trajectory kind, "hill-drive", "sortie" or "vertical".
    duration_s: length of the drive [s].
    imu_rate_hz: IMU sample rate [Hz].
    imu, gnss, baro: the sensors' error models (``ImuSpec``, ``GnssSpec``, ``BaroSpec``).
    origin_lat_deg, origin_lon_deg, origin_alt_m: the drive's origin [deg, deg, m].
    params: kind-specific trajectory parameters (``simulation.trajectories``).
    description: one line for ``vnav-graph list``.
    magnetometer: a simulated magnetometer (TOML ``[magnetometer]``; None: none).
    side_slip_gain: car side-slip β = side_slip_gain·a_lat [rad per m/s²] (0: none).
    imu_mount_rph_deg: roll, pitch, yaw of the IMU axes in the vehicle frame [deg].
    """

    name: str
    kind: str
    duration_s: float
    imu_rate_hz: float = 200.0
    imu: ImuSpec = field(default_factory=lambda: IMU_PRESETS["consumer"])
    gnss: GnssSpec = field(default_factory=GnssSpec)
    baro: BaroSpec = field(default_factory=BaroSpec)
    origin_lat_deg: float = 47.0
    origin_lon_deg: float = 11.0
    origin_alt_m: float = 500.0
    params: dict[str, Any] = field(default_factory=dict)
    description: str = ""
    magnetometer: MagSpec | None = None
    side_slip_gain: float = 0.0
    imu_mount_rph_deg: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        if self.kind not in ("hill-drive", "sortie", "vertical"):
            raise ValueError(f"ScenarioConfig.kind: unknown trajectory kind {self.kind!r}")
        if not self.duration_s > 0 or not self.imu_rate_hz > 0:
            raise ValueError("ScenarioConfig.duration_s / imu_rate_hz: must be > 0")
        mount = tuple(float(x) for x in self.imu_mount_rph_deg)
        object.__setattr__(self, "imu_mount_rph_deg", mount)
        if len(mount) != 3 or not all(np.isfinite(mount) & (np.abs(mount) < 90.0)):
            raise ValueError("ScenarioConfig.imu_mount_rph_deg: three finite angles in "
                             f"(-90, 90) degrees, got {self.imu_mount_rph_deg!r}")
        if not np.isfinite(self.side_slip_gain) or (self.kind == "vertical" and (
                self.side_slip_gain or any(mount))):
            raise ValueError("ScenarioConfig.side_slip_gain / imu_mount_rph_deg: finite, and "
                             "only for the hill-drive and sortie kinds")
