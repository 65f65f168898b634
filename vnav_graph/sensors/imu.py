"""IMU error model: white noise, Gauss-Markov bias, bias random walk, accelerometer scale.

gyro_b   = ω_ib^b + b_g(t) + n_g,        b_g = GM(σ, τ) + RW
accel_b  = (1 + k_a)·f_ib^b + b_a(t) + n_a,  k_a per axis, random constant
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..config import ImuSpec
from ..types.streams import FloatArray, ImuStream
from .noise import gauss_markov, random_walk, white_sd


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
