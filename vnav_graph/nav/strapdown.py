"""Strapdown inertial mechanisation in the local-level NED frame (geodetic position).

State: latitude, longitude [rad], ellipsoidal height h [m], NED velocity v [m/s] and the
attitude quaternion q_nb. One step from IMU point samples k → k+1 (Δt), with biases removed:

- attitude (Bortz, two-sample coning for linearly varying rate):
  φ = ½(ω_k + ω_{k+1})Δt + (1/12) ω_k × ω_{k+1} Δt²,
  C_nb ← exp(−[ω_in^n Δt ×]) C_nb exp([φ×]),   ω_in = ω_ie + ω_en;
- velocity (exact to second order for linearly varying rate and specific force, which
  includes the two-sample sculling and rotation compensation):
  Δv_b = ½(f_k + f_{k+1})Δt + ∫₀^Δt θ(τ) × f(τ) dτ,
  v ← v + (I − ½[ω_in Δt ×]) C_nb Δv_b + (g(lat, h) − (2ω_ie + ω_en) × v_mid) Δt;
- position: trapezoidal in velocity with the radii of curvature (Groves eq. 5.56).

Reference: Groves, 2nd ed., §5.4-5.5; Savage, *Strapdown Analytics*, ch. 7. The simulator
(``vnav_graph.simulation.trajectories``) produces exact point samples of the same kinematics;
``tests/integration/test_roundtrip.py`` checks that this integration reproduces its truth.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from ..geo.earth import OMEGA_IE, gravity_scalar, radii_scalar
from ..types import Trajectory
from ..types.streams import FloatArray, ImuStream
from .rotations import cross3 as _cross
from .rotations import quat_exp, quat_mul, quat_to_dcm


@njit(cache=True)
def nav_rates(lat, h, v):
    """Earth rate ω_ie^n and transport rate ω_en^n [rad/s] at (lat, h) for NED velocity v."""
    rn, re = radii_scalar(lat)
    w_ie = np.array([OMEGA_IE * np.cos(lat), 0.0, -OMEGA_IE * np.sin(lat)])
    w_en = np.array([v[1] / (re + h), -v[0] / (rn + h), -v[1] * np.tan(lat) / (re + h)])
    return w_ie, w_en


@njit(cache=True)
def strapdown_step(lla, v, q, w0, w1, f0, f1, dt):
    """One mechanisation step; w0/w1, f0/f1 are bias-corrected rates and specific forces at
    the start and end of the interval. Returns the new (lla, v, q) as new arrays."""
    lat, lon, h = lla[0], lla[1], lla[2]
    # attitude increment with coning
    phi = 0.5 * (w0 + w1) * dt + _cross(w0, w1) * (dt * dt / 12.0)
    # velocity increment with rotation/sculling: θ(τ) = w0 τ + bτ², f(τ) = f0 + cτ
    b = (w1 - w0) / (2.0 * dt)
    c = (f1 - f0) / dt
    dv_b = 0.5 * (f0 + f1) * dt + _cross(w0, f0) * (dt**2 / 2.0) + (
        _cross(w0, c) + _cross(b, f0)) * (dt**3 / 3.0) + _cross(b, c) * (dt**4 / 4.0)
    w_ie, w_en = nav_rates(lat, h, v)
    w_in = w_ie + w_en
    c_nb = quat_to_dcm(q)
    dv_n = c_nb @ dv_b
    dv_n = dv_n - 0.5 * _cross(w_in * dt, dv_n)
    h_mid = h - 0.5 * v[2] * dt
    g = gravity_scalar(lat, h_mid)
    v_pred = v + dv_n + np.array([0.0, 0.0, g * dt])
    v_mid = 0.5 * (v + v_pred)
    w_ie, w_en = nav_rates(lat, h_mid, v_mid)
    cor = _cross(2.0 * w_ie + w_en, v_mid)
    v_new = v + dv_n + (np.array([0.0, 0.0, g]) - cor) * dt
    # attitude: body rotation then navigation-frame rotation (mid-interval rates)
    q_new = quat_mul(quat_exp(-(w_ie + w_en) * dt), quat_mul(q, quat_exp(phi)))
    q_new = q_new / np.sqrt(np.sum(q_new * q_new))
    # position (trapezoid)
    h_new = h - 0.5 * (v[2] + v_new[2]) * dt
    h_m = 0.5 * (h + h_new)
    rn, re = radii_scalar(lat)
    lat_new = lat + 0.5 * (v[0] + v_new[0]) / (rn + h_m) * dt
    lat_m = 0.5 * (lat + lat_new)
    rn, re = radii_scalar(lat_m)
    lon_new = lon + 0.5 * (v[1] + v_new[1]) / ((re + h_m) * np.cos(lat_m)) * dt
    return np.array([lat_new, lon_new, h_new]), v_new, q_new


@njit(cache=True)
def _integrate(t, gyro, accel, lla0, v0, q0, bg, ba):
    n = t.size
    lla = np.empty((n, 3))
    vel = np.empty((n, 3))
    q = np.empty((n, 4))
    lla[0], vel[0], q[0] = lla0, v0, q0
    for k in range(n - 1):
        dt = t[k + 1] - t[k]
        lla[k + 1], vel[k + 1], q[k + 1] = strapdown_step(
            lla[k], vel[k], q[k], gyro[k] - bg, gyro[k + 1] - bg, accel[k] - ba,
            accel[k + 1] - ba, dt)
    return lla, vel, q


@dataclass(frozen=True)
class NavState:
    """Initial navigation state for free-inertial integration."""

    lla: FloatArray  # (3,) rad, rad, m
    vel_n: FloatArray  # (3,) m/s
    q_nb: FloatArray  # (4,) w, x, y, z


def integrate(
    imu: ImuStream, init: NavState, bias_gyro: FloatArray | None = None,
    bias_accel: FloatArray | None = None,
) -> Trajectory:
    """Free-inertial navigation over the whole IMU stream from ``init`` (constant biases
    removed). Returns a Trajectory at the IMU epochs."""
    bg = np.zeros(3) if bias_gyro is None else np.asarray(bias_gyro, dtype=float)
    ba = np.zeros(3) if bias_accel is None else np.asarray(bias_accel, dtype=float)
    lla, vel, q = _integrate(
        imu.t, imu.gyro_b, imu.accel_b, np.asarray(init.lla, float),
        np.asarray(init.vel_n, float), np.asarray(init.q_nb, float), bg, ba,
    )
    q = np.where(q[:, :1] < 0, -q, q)
    return Trajectory(imu.t, lla, vel, q)
