"""The sensor model every estimator of a drive receives: one place, one set of rules.

``sensor_model(drive)`` returns a frozen :class:`SensorModel` holding

- ``imu``: the IMU noise model (an :class:`~vnav_graph.config.ImuSpec`). A simulated drive
  carries its spec; a real log does not, and the model is inferred from the data
  (:func:`infer_imu_spec`). Numerical floors keep noiseless simulated drives regular.
- ``baro``: the prior of the baro error states (:class:`BaroPrior`: scale factor s, latency
  τd, Gauss-Markov bias b, white noise), from the drive's :class:`BaroSpec` or, on a real
  log, from the package-wide ``REAL_LOG_BARO``.
- ``gnss_pos_sd`` / ``gnss_vel_sd``: the per-fix GNSS σ [m, m/s] every estimator weights the
  fixes with (the receiver's σ, floored at ``GNSS_SD_FLOOR``). Where the velocities disagree
  with the position differences beyond both σ (``sensors.gnss_consistency``), the velocity σ
  get the missing variance (``gnss_vel_check``; ``gnss_vel_note`` says so). With an
  estimator's optional Gauss-Markov GNSS error state (``gnss_gm``: a
  :class:`~vnav_graph.sensors.gnss_model.GnssGM`), the σ of each carried axis is only the
  white rest of the receiver's (``GnssGM.split``).
- ``gaps``: the IMU logging gaps (:mod:`vnav_graph.nav.gaps`).

ekf, ekf-rts, vekf7 and both graph smoothers take every noise parameter from here; the test
``tests/unit/test_sensor_model.py`` checks that they receive identical values on simulated
drives and on every shared real log. Which estimator uses which part is tabled in README.md.

Units: SI throughout (m, s, rad); densities are root PSDs (unit/√Hz), random walks
unit/√s, as in :mod:`vnav_graph.config`.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace
from typing import Any

import numpy as np

from ..config import DEG, IMU_PRESETS, REAL_LOG_BARO, BaroSpec, ImuSpec
from ..nav.gaps import imu_gaps
from ..types.streams import FloatArray
from .gnss_consistency import VelocityConsistency, velocity_consistency
from .gnss_model import GNSS_SD_FLOOR, GnssGM

# Real-log IMU prior (a phone / autopilot MEMS IMU of unknown make): the consumer preset's
# densities, generous turn-on biases (a phone's uncalibrated gyro bias reaches 0.5 °/s, its
# accelerometer bias 0.1 m/s²) and a 1 % accelerometer scale factor. A turn-on bias is a
# random constant that then drifts slowly: the Gauss-Markov τ is set so that the in-run
# drift over 10 min is ≈ 0.05 °/s and 0.02 m/s² (σ_drift² = 2σ²·600 s/τ), consumer-MEMS
# bias instability with temperature; τ = 600 s would let the whole turn-on bias wander
# within ten minutes, which lets heading and tilt drift on a hovering multirotor.
_DRIFT_S = 600.0
REAL_LOG_IMU = ImuSpec(
    name="phone",
    gyro_noise_density=IMU_PRESETS["consumer"].gyro_noise_density,
    gyro_bias_sd=0.5 * DEG,
    gyro_bias_tau=2.0 * _DRIFT_S * (0.5 / 0.05) ** 2,  # 120 000 s
    gyro_bias_rw=IMU_PRESETS["consumer"].gyro_bias_rw,
    accel_noise_density=IMU_PRESETS["consumer"].accel_noise_density,
    accel_bias_sd=0.1,
    accel_bias_tau=2.0 * _DRIFT_S * (0.1 / 0.02) ** 2,  # 30 000 s
    accel_bias_rw=IMU_PRESETS["consumer"].accel_bias_rw,
    accel_scale_sd=0.01,
)

# Vibration rectification coefficient [1/√s] and the lowest IMU rate at which first
# differences measure vibration rather than manoeuvres (``infer_imu_spec``). The white noise
# is the variance of the first differences, which already holds a vibrating IMU's heavy
# tails; an accelerometer bias walk k_vre·σ_vib on top of it would count the same vibration
# twice, so by default there is none (measured on the shared logs: docs/real_logs.md,
# "Vibration rectification"). The term is kept for users who model it
# (``infer_imu_spec(k_vre=)``).
K_VRE = 0.0
VRE_MIN_RATE_HZ = 10.0
# ... except where the log shows an accelerometer that reads too little specific force. A
# working accelerometer cannot: |f| = |a − g| ≥ |g + a_up| at every instant, and vibration
# only raises a window's mean |f| (mean of norms ≥ norm of means). So over windows of
# ``DEFICIT_WINDOW_S`` the deficit e = mean|f| − g0 − a_up (a_up the baro's vertical
# acceleration) is ≥ 0 up to noise; a 5th percentile below −``DEFICIT_LIMIT`` is a sensor
# that loses specific force in flight (vibration rectification, clipping: for seconds it
# reads less than gravity while the vehicle climbs). There the bias walk ``K_VRE_DEFICIT``
# ·σ_robust lets the accelerometer bias follow the loss, instead of every estimator
# explaining the missing force with a tilted vehicle and a large horizontal accelerometer
# bias (``rectifying_walk``, used by ``infer_imu_spec`` and reported by ``io.sanity``;
# measured on the shared logs: docs/real_logs.md, "Accelerometers that lose specific force").
DEFICIT_WINDOW_S = 2.0
DEFICIT_LIMIT = 0.5  # m/s²
DEFICIT_QUANTILE = 5.0  # %
K_VRE_DEFICIT = 0.14

# Numerical floors: they keep a noiseless simulated drive's covariances regular and are far
# below any real sensor (gyro 1e-6 rad/s/√Hz = 0.003 °/√h).
MIN_GYRO_NOISE_DENSITY = 1e-6  # rad/s/√Hz
MIN_ACCEL_NOISE_DENSITY = 1e-4  # m/s²/√Hz
MIN_GYRO_BIAS_SD = 1e-6  # rad/s
MIN_ACCEL_BIAS_SD = 1e-4  # m/s²
MIN_SCALE_SD = 1e-4  # –
MIN_LATENCY_SD = 0.01  # s
MIN_BARO_NOISE_SD = 1e-3  # m
MIN_BARO_BIAS_SD = 1e-3  # m
# GNSS_SD_FLOOR (the per-fix σ floor, m and m/s) and the Gauss-Markov GNSS error state
# (``GnssGM``) live with the GNSS measurement model (``sensors.gnss_model``)


@dataclass(frozen=True)
class BaroPrior:
    """Prior of the baro error model h_baro(t) = h0 + (1 + s)·(h(t − τd) − h0) + b(t) + w
    (``sensors.baro``, docs/design.md).

    scale_sd [–] (mean 0), latency_mean / latency_sd [s], bias_sd [m] and bias_tau [s] of the
    first-order Gauss-Markov bias, noise_sd [m] of the white noise w.
    """

    scale_sd: float
    latency_mean: float
    latency_sd: float
    bias_sd: float
    bias_tau: float
    noise_sd: float


@dataclass(frozen=True)
class SensorModel:
    """What every estimator of one drive is given (module docstring)."""

    imu: ImuSpec
    imu_inferred: bool
    baro: BaroPrior | None
    gnss_pos_sd: FloatArray | None
    gnss_vel_sd: FloatArray | None
    gaps: np.ndarray  # (G,) int: IMU sample i → i+1 is a gap
    gnss_vel_check: VelocityConsistency | None = None

    def gnss_vel_note(self) -> str:
        """'' unless the velocity σ were raised (``sensors.gnss_consistency``), else a
        one-line note with R and the added σ per NED axis."""
        c = self.gnss_vel_check
        if c is None or not c.raised:
            return ""
        r = ", ".join(f"{x:.2f}" for x in c.ratio)
        a = ", ".join(f"{x:.3f}" for x in np.sqrt(c.added_var))
        return (f"GNSS velocity σ raised: the velocities disagree with the position "
                f"differences {r}× (N, E, D; variance ratio over {c.pairs} pairs) what the "
                f"receiver's σ allow; added σ ({a}) m/s"
                + (f"; {c.spikes} fixes left out as position spikes" if c.spikes else ""))

    def summary(self) -> dict[str, Any]:
        """JSON-ready parameters (arrays as their min / median / max) for comparisons."""
        out: dict[str, Any] = {"imu": asdict(self.imu), "imu_inferred": self.imu_inferred,
                               "baro": None if self.baro is None else asdict(self.baro),
                               "gaps": [int(i) for i in self.gaps],
                               "gnss_vel_check": (None if self.gnss_vel_check is None
                                                  else self.gnss_vel_check.summary())}
        for name in ("gnss_pos_sd", "gnss_vel_sd"):
            a = getattr(self, name)
            out[name] = None if a is None else [float(np.min(a)), float(np.median(a)),
                                                float(np.max(a))]
        return out


def measured_white_sd(x: FloatArray, rate_hz: float) -> FloatArray:
    """Per-axis white-noise σ of samples x (N, 3) from their first differences Δx (white
    noise of σ gives Δx of σ√2; slow motion gives Δx ≈ 0).

    At ≥ ``VRE_MIN_RATE_HZ`` the differences are vibration and sensor noise, heavy-tailed on
    a multirotor or a skier's phone: their standard deviation is used, because the variance
    is what the estimators propagate (a robust scale would understate it 2×, measured on the
    shared logs). Below that rate (1 Hz averaged phone logs) the differences are the
    vehicle's own manoeuvres, and the robust scale 1.4826·median|Δx| ignores them."""
    if x.shape[0] < 3:
        return np.zeros(x.shape[1])
    if rate_hz >= VRE_MIN_RATE_HZ:
        return np.std(np.diff(x, axis=0), axis=0) / np.sqrt(2.0)
    return robust_white_sd(x)


def robust_white_sd(x: FloatArray) -> FloatArray:
    """Per-axis 1.4826·median|Δx|/√2: the white σ of x (N, 3), robust to manoeuvre steps."""
    if x.shape[0] < 3:
        return np.zeros(x.shape[1])
    return 1.4826 * np.median(np.abs(np.diff(x, axis=0)), axis=0) / np.sqrt(2.0)


def specific_force_deficit(imu: Any, baro: Any, g0: float,
                           window_s: float = DEFICIT_WINDOW_S) -> float | None:
    """The ``DEFICIT_QUANTILE`` percentile of e = |f|̄ − g0 − a_up [m/s²] (see
    ``DEFICIT_LIMIT``), both sides averaged with one kernel: on a 0.1 s grid of bin means, a_up
    is the second difference (step W = ``window_s``) of the W-box-averaged baro altitude over
    W², which is the vertical acceleration averaged with box_W ∗ triangle_W, and |f| gets that
    same kernel; taken every W seconds. None without a barometer or with fewer than 10
    points."""
    if baro is None or baro.t.size < 10 or imu.t.size < 10:
        return None
    dt = 0.1
    t0, t1 = max(imu.t[0], baro.t[0]), min(imu.t[-1], baro.t[-1])
    nb = int((t1 - t0) / dt)
    nw = int(round(window_s / dt))
    if nb < 6 * nw:
        return None

    def bins(t: FloatArray, x: FloatArray) -> FloatArray:
        j = np.floor((t - t0) / dt).astype(int)
        m = (j >= 0) & (j < nb)
        cnt = np.bincount(j[m], minlength=nb)
        tot = np.bincount(j[m], weights=x[m], minlength=nb)
        have = cnt > 0
        tc = t0 + (np.arange(nb) + 0.5) * dt
        return np.interp(tc, tc[have], tot[have] / cnt[have])

    f = bins(imu.t, np.linalg.norm(imu.accel_b, axis=1))
    h = bins(baro.t, np.asarray(baro.altitude, float))
    box = np.full(nw, 1.0 / nw)
    tri = (nw - np.abs(np.arange(-nw + 1, nw))) / nw**2
    hb = np.convolve(h, box, mode="valid")  # hb[i]: mean of h[i : i + nw]
    a_up = (hb[2 * nw:] - 2.0 * hb[nw:-nw] + hb[:-2 * nw]) / window_s**2
    fk = np.convolve(np.convolve(f, box, mode="valid"), tri, mode="valid")
    # a_up[i] is centred on grid index i + nw + (nw − 1)/2, fk[i] on i + nw − 1 + (nw − 1)/2
    fk = fk[1:]
    n = min(a_up.size, fk.size)
    e = (fk[:n] - g0 - a_up[:n])[::nw]
    if e.size < 10:
        return None
    return float(np.percentile(e, DEFICIT_QUANTILE))


def rectifying_walk(imu: Any, baro: Any, g0: float) -> tuple[float | None, float]:
    """(``specific_force_deficit``, the accelerometer bias walk [m/s²/√s] it calls for):
    ``K_VRE_DEFICIT``·σ_robust when the deficit is below −``DEFICIT_LIMIT`` on an IMU at
    ≥ ``VRE_MIN_RATE_HZ``, else 0. The deficit is None where it is not measured (no baro,
    too short, or a low-rate IMU whose differences are manoeuvres)."""
    if baro is None or float(imu.rate_hz) < VRE_MIN_RATE_HZ:
        return None, 0.0
    d = specific_force_deficit(imu, baro, g0)
    if d is None or not np.isfinite(d) or d >= -DEFICIT_LIMIT:
        return d, 0.0
    return d, K_VRE_DEFICIT * float(np.max(robust_white_sd(imu.accel_b)))


def infer_imu_spec(imu: Any, g0: float, base: ImuSpec = REAL_LOG_IMU,
                   k_vre: float = K_VRE, baro: Any = None) -> ImuSpec:
    """IMU noise model of a log without a spec: ``base`` raised to what the data show.

    - white-noise densities ≥ max_axis σ_white / √f_s [unit/√Hz] (``measured_white_sd``;
      a multirotor's vibration is noise at the estimators' time scales);
    - accelerometer bias random walk ≥ k_vre·σ_robust,accel [m/s²/√s] (vibration
      rectification: a vibrating MEMS accelerometer — clipping, asymmetric response — shows
      bias shifts that grow with the vibration; the default ``K_VRE`` is 0, the white noise
      already holding the vibration, and k_vre = ``K_VRE_DEFICIT`` = 0.14 /√s on the robust
      scale where the accelerometer reads less specific force than gravity and the climb
      need, below; docs/real_logs.md, "Vibration rectification"). Only for
      IMUs sampled at ≥ ``VRE_MIN_RATE_HZ``: at 1 Hz (averaged phone logs) the differences
      are the vehicle's own manoeuvres;
    - accelerometer bias σ ≥ 2·|median |f| − g0| [m/s²], the specific-force magnitude error
      (a vehicle spends most of its time unaccelerated);
    - with ``baro``: where the accelerometer loses specific force in flight
      (``specific_force_deficit`` below −``DEFICIT_LIMIT``), k_vre is at least
      ``K_VRE_DEFICIT`` (the name gets "-rectifying").
    """
    if imu.t.size < 10:
        return base
    rate = float(imu.rate_hz)
    rt = np.sqrt(rate)
    g_nd = float(np.max(measured_white_sd(imu.gyro_b, rate))) / rt
    a_sd = float(np.max(measured_white_sd(imu.accel_b, rate)))
    vib = rate >= VRE_MIN_RATE_HZ
    a_rob = float(np.max(robust_white_sd(imu.accel_b)))  # the scale k_vre was set on
    fmag = float(np.median(np.linalg.norm(imu.accel_b, axis=1)))
    walk = rectifying_walk(imu, baro, g0)[1]
    name = f"{base.name}-measured" + ("-rectifying" if walk > 0 else "")
    return replace(base, name=name,
                   gyro_noise_density=max(base.gyro_noise_density, g_nd),
                   accel_noise_density=max(base.accel_noise_density, a_sd / rt),
                   accel_bias_rw=max(base.accel_bias_rw, k_vre * a_rob if vib else 0.0,
                                     walk),
                   accel_bias_sd=max(base.accel_bias_sd, 2.0 * abs(fmag - g0)))


def floor_imu_spec(spec: ImuSpec) -> ImuSpec:
    """``spec`` with the numerical floors applied (module constants)."""
    return replace(spec,
                   gyro_noise_density=max(spec.gyro_noise_density, MIN_GYRO_NOISE_DENSITY),
                   accel_noise_density=max(spec.accel_noise_density, MIN_ACCEL_NOISE_DENSITY),
                   gyro_bias_sd=max(spec.gyro_bias_sd, MIN_GYRO_BIAS_SD),
                   accel_bias_sd=max(spec.accel_bias_sd, MIN_ACCEL_BIAS_SD))


def baro_prior(spec: BaroSpec) -> BaroPrior:
    """Prior of the baro states from a spec — a prior, never the simulated truth.

    A spec *draws* its scale s ~ N(0, scale_sd) and its latency uniformly in
    ``latency_range_s``: those are datasheet-like statements and give the prior (the range its
    mean and width/√12). A spec that *fixes* a value (``scale`` set or ``scale_sd`` = 0; a
    fixed ``latency_s`` without a range) states the truth of a simulation, which an estimator
    must not be told: it gets the documented default prior of ``REAL_LOG_BARO`` instead
    (scale σ 2 %, latency N(0.1 s, 0.1 s)). Bias and noise σ are process statistics and are
    taken as given. Every σ is floored (module constants)."""
    if spec.scale is None and spec.scale_sd > 0:
        s_sd = spec.scale_sd
    else:
        s_sd = REAL_LOG_BARO.scale_sd
    rng = spec.latency_range_s if spec.latency_range_s is not None else \
        REAL_LOG_BARO.latency_range_s
    assert rng is not None
    lo, hi = rng
    tau_m, tau_sd = 0.5 * (lo + hi), (hi - lo) / np.sqrt(12.0)
    return BaroPrior(scale_sd=float(max(s_sd, MIN_SCALE_SD)), latency_mean=float(tau_m),
                     latency_sd=float(max(tau_sd, MIN_LATENCY_SD)),
                     bias_sd=float(max(spec.bias_sd, MIN_BARO_BIAS_SD)),
                     bias_tau=float(spec.bias_tau),
                     noise_sd=float(max(spec.noise_sd, MIN_BARO_NOISE_SD)))


def drive_baro_spec(drive: Any) -> BaroSpec | None:
    """The drive's baro spec, ``REAL_LOG_BARO`` for a log without one, None without a baro."""
    if drive.baro is None:
        return None
    spec = drive.baro.spec
    return spec if isinstance(spec, BaroSpec) else REAL_LOG_BARO


def _gnss_sd(a: Any) -> FloatArray | None:
    if a is None:
        return None
    a = np.asarray(a, dtype=float)
    return np.where(np.isfinite(a), np.maximum(a, GNSS_SD_FLOOR), a)


def sensor_model(drive: Any, gnss_gm: GnssGM | None = None) -> SensorModel:
    """The shared sensor model of ``drive`` (module docstring); ``gnss_gm``: the estimator's
    Gauss-Markov GNSS error state, if any (the fixes' σ is then its white rest on the axes it
    carries)."""
    from ..geo.earth import gravity
    from ..geo.frames import lla_to_ned

    imu = drive.imu
    inferred = not isinstance(imu.spec, ImuSpec)
    if inferred:
        lat, h = float(drive.origin_lla[0]), float(drive.origin_lla[2])
        spec = infer_imu_spec(imu, float(gravity(lat, h)), baro=drive.baro)
    else:
        spec = imu.spec
    bspec = drive_baro_spec(drive)
    gn = drive.gnss
    pos_sd = None if gn is None else _gnss_sd(gn.pos_sd)
    vel_sd = None if gn is None else _gnss_sd(gn.vel_sd)
    check = None
    if gn is not None and vel_sd is not None and pos_sd is not None:
        # judged on the receiver's whole σ (before a Gauss-Markov state takes its share)
        check = velocity_consistency(gn.t, lla_to_ned(gn.lla, drive.origin_lla), pos_sd,
                                     gn.vel_n, vel_sd)
        if check is not None and check.raised:
            vel_sd = np.sqrt(vel_sd**2 + check.added_var)
    if pos_sd is not None and gnss_gm is not None:
        pos_sd = gnss_gm.split(pos_sd)
    return SensorModel(
        imu=floor_imu_spec(spec), imu_inferred=inferred,
        baro=None if bspec is None else baro_prior(bspec),
        gnss_pos_sd=pos_sd, gnss_vel_sd=vel_sd,
        gaps=imu_gaps(imu.t), gnss_vel_check=check)


# Prior σ of the accelerometer scale factors when the IMU model is inferred from a real log
# whose spec gives none (0.1 %, a calibrated MEMS accelerometer).
MIN_INFERRED_ACCEL_SCALE_SD = 1e-3


def accel_scale_sd(model: SensorModel, enabled: bool | None = None) -> float:
    """Prior σ [-] of the three accelerometer scale-factor states (random constants,
    f_meas = (1 + k_a)·f + b_a), 0 when they are not carried. The one rule of ekf, ekf-rts
    and both graph smoothers: carried when ``enabled`` says so or, when it is None, on a
    real log (inferred IMU model) and on a simulated drive whose spec has
    ``accel_scale_sd`` > 0; σ is the spec's, at least ``MIN_INFERRED_ACCEL_SCALE_SD`` on a
    real log."""
    on = enabled if enabled is not None else (model.imu_inferred
                                              or model.imu.accel_scale_sd > 0)
    if not on:
        return 0.0
    return float(max(model.imu.accel_scale_sd,
                     MIN_INFERRED_ACCEL_SCALE_SD if model.imu_inferred else 0.0))
