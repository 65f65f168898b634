"""Simulated sensor outputs from a true trajectory: the IMU, the barometer and the
magnetometer (GNSS in ``simulation.gnss``). Each follows its sensor's model in ``sensors/``:

- IMU: gyro_b = ω_ib^b + b_g(t) + n_g, b_g = GM(σ, τ) + RW; accel_b = (1 + k_a)·f_ib^b +
  b_a(t) + n_a, k_a per axis, a random constant;
- barometer: ``sensors.baro``'s h_b − h0 = (1 + s)·(h(t − τd) − h0) + b(t) + v, or the
  pressure of a non-standard atmosphere that produces it (``BaroSpec.physical``);
- magnetometer: z = C_nbᵀ m_n + b_hi + n (``sensors.magnetometer``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..config import BaroSpec, ImuSpec
from ..geo.atmosphere import isa_pressure
from ..sensors.magnetometer import MagSpec
from ..sensors.noise import white_sd
from ..types import BaroTruth, Trajectory
from ..types.streams import BaroStream, FloatArray, ImuStream, MagStream
from .noise import gauss_markov, random_walk


@dataclass(frozen=True)
class ImuErrors:
    """The realised IMU errors of one simulation (truth for the bias states)."""

    bias_gyro: FloatArray  # (N, 3) [rad/s]
    bias_accel: FloatArray  # (N, 3) [m/s^2]
    accel_scale: FloatArray  # (3,) [-]


def apply_imu_errors(
    t: FloatArray, gyro_true: FloatArray, accel_true: FloatArray, spec: ImuSpec,
    rng: np.random.Generator,
) -> tuple[ImuStream, ImuErrors]:
    """Corrupt true angular rate and specific force (N, 3) with ``spec``'s error model."""
    n = t.size
    dt = float(np.median(np.diff(t)))
    bg = gauss_markov(t, spec.gyro_bias_tau, spec.gyro_bias_sd, rng, 3) + random_walk(
        t, spec.gyro_bias_rw, rng, 3
    )
    ba = gauss_markov(t, spec.accel_bias_tau, spec.accel_bias_sd, rng, 3) + random_walk(
        t, spec.accel_bias_rw, rng, 3
    )
    ka = rng.normal(0.0, spec.accel_scale_sd, 3) if spec.accel_scale_sd > 0 else np.zeros(3)
    gyro = gyro_true + bg + rng.normal(size=(n, 3)) * white_sd(spec.gyro_noise_density, dt)
    accel = (1.0 + ka) * accel_true + ba + rng.normal(size=(n, 3)) * white_sd(
        spec.accel_noise_density, dt
    )
    return ImuStream(t, gyro, accel, spec), ImuErrors(bg, ba, ka)


def draw_baro_truth(spec: BaroSpec, rng: np.random.Generator) -> BaroTruth:
    """Draw the random constants (scale, latency) of one simulated altimeter."""
    s = spec.scale if spec.scale is not None else float(rng.normal(0.0, spec.scale_sd))
    if spec.latency_range_s is not None:
        tau = float(rng.uniform(*spec.latency_range_s))
    else:
        tau = spec.latency_s
    return BaroTruth(scale=s, latency_s=tau)


def _indicated_scale(h0: float, dT: float) -> float:
    """Slope − 1 of the standard-law altitude against the true height in an ISA + dT
    troposphere whose sea-level pressure makes the reading exact at h0 [m] (zero bias).

    With p = c·P0·(1 − L·h/(T0 + dT))^(g/RL) the standard law reads
    h_i = T0/L·(1 − c'·(1 − L·h/(T0 + dT))), c' = c^(RL/g): affine in h with slope
    c'·T0/(T0 + dT). c' ≠ 1 moves the slope by ≈ L·(h_i(h0) − h0)/T0 (5e-4 per 25 m), which is
    why this is ≈ T0/(T0 + dT) − 1 but not exactly.
    """
    from ..geo.atmosphere import G0, P0, R_AIR, T0, L

    c = (isa_pressure(h0) / isa_pressure(h0, dT, p0=1.0) / P0) ** (R_AIR * L / G0)
    return float(c * T0 / (T0 + dT) - 1.0)


def simulate_baro(
    t: FloatArray, t_truth: FloatArray, h_truth: FloatArray, h0: float, spec: BaroSpec,
    rng: np.random.Generator,
) -> tuple[BaroStream, BaroTruth, FloatArray]:
    """Generate baro samples at ``t`` from the true height ``h_truth`` sampled at ``t_truth``.

    Returns the stream, the drawn constants and the bias b(t) at ``t`` [m].
    In ``physical`` mode the pressure is produced by a non-standard atmosphere (ISA + dT with
    dT = −s·T0/(1+s), giving scale s exactly at the reference, and a sea-level pressure
    drifting as a Gauss-Markov process that gives b); the returned bias is then the
    indicated-altitude error at h0 (exact there; away from h0 the ISA law adds a small
    nonlinearity that the linear model does not have), and the stream carries pressure [Pa].
    With ``spec.isa_offset_k`` = ΔT the day is ISA + ΔT on top of the sensor's s:
    dT = (T0 + ΔT)/(1+s) − T0 = −s·T0/(1+s) + ΔT/(1+s), so T0/(T0 + dT) = (1+s)·T0/(T0 + ΔT).
    The returned ``BaroTruth.scale`` is then the effective scale an estimator should find: the
    exact slope − 1 of the reading against the true height (``_indicated_scale``), which the
    reading's setting at h0 moves from T0/(T0 + dT) − 1 by ≈ −L·h0·dT/(T0 + dT)² (−1.5e-3 at
    h0 = 890 m for s = −3 %, ΔT = 15 K). In the ISA troposphere the reading is affine in h, so
    that slope holds at every height. At ΔT = 0 the returned scale stays the drawn s.
    """
    truth = draw_baro_truth(spec, rng)
    t_del = t - truth.latency_s
    if t_del[0] < t_truth[0]:
        t_del = np.maximum(t_del, t_truth[0])  # the first τd seconds repeat the first height
    h_del = np.interp(t_del, t_truth, h_truth)
    x0 = None if spec.bias_init is None else np.array([spec.bias_init])
    bias = gauss_markov(t, spec.bias_tau, spec.bias_sd, rng, 1, x0=x0)[:, 0]
    noise = rng.normal(0.0, spec.noise_sd, t.size) if spec.noise_sd > 0 else np.zeros(t.size)
    if not spec.physical:
        alt = h0 + (1.0 + truth.scale) * (h_del - h0) + bias + noise
        return BaroStream(t, alt=alt, spec=spec), truth, bias
    from ..geo.atmosphere import R_AIR, T0, isa_temperature

    # ISA + dT with dT = −s·T0/(1+s) makes the standard-law altimeter read (1+s)·h; the day's
    # offset ΔT enters as ΔT/(1+s) (docstring), and adds exactly 0.0 when it is 0.
    dT = -truth.scale * T0 / (1.0 + truth.scale) + spec.isa_offset_k / (1.0 + truth.scale)
    # Sea-level pressure p0(t) chosen so the indicated altitude at h0 is exactly h0 + b(t).
    p0 = isa_pressure(h0 + bias) / isa_pressure(h0, dT, p0=1.0)
    if spec.isa_offset_k != 0.0:
        truth = BaroTruth(scale=_indicated_scale(h0, dT), latency_s=truth.latency_s)
    p = p0 * isa_pressure(h_del, dT, p0=1.0)
    # white noise of noise_sd metres through the hydrostatic gradient dp/dh = −p·g/(R·T)
    p = p - noise * p * 9.80665 / (R_AIR * isa_temperature(h_del, dT))
    return BaroStream(t, pressure=p, spec=spec), truth, bias


def simulate_mag(truth: Trajectory, spec: MagSpec, field_ned_ut: FloatArray,
                 rng: np.random.Generator) -> MagStream:
    """Magnetometer samples z = C_nbᵀ m_n + b_hi + n at ``spec.rate_hz`` over the truth span.

    ``truth`` must carry the attitude q_nb (body → NED, slerped to the sample times);
    ``field_ned_ut`` (3,) is m_n [µT], north-east-down, taken constant over the drive (the
    main field changes by ~5 nT/km: nothing over a drive of tens of km); b_hi is
    ``spec.hard_iron_ut`` and n white, σ ``spec.sd_ut`` per axis, drawn from ``rng`` (one
    (N, 3) normal draw). Returns the stream in body axes forward-right-down [µT].
    """
    from ..geo.frames import quat_to_mat

    if truth.q_nb is None:
        raise ValueError("simulate_mag: the truth trajectory has no attitude (q_nb)")
    m_n = np.asarray(field_ned_ut, dtype=float).reshape(3)
    t = np.arange(truth.t[0], truth.t[-1] + 1e-9, 1.0 / spec.rate_hz)
    c_nb = quat_to_mat(truth.at(t).q_nb)
    field_b = np.einsum("nji,j->ni", c_nb, m_n)  # C_nbᵀ m_n
    field_b += np.asarray(spec.hard_iron_ut) + rng.normal(0.0, spec.sd_ut, (t.size, 3))
    return MagStream(t, field_b, spec.sd_ut)
