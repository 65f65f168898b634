"""GNSS receiver error model: white position/velocity noise, rate, latency, lever arm,
outage windows and occasional gross outliers."""

from __future__ import annotations

import numpy as np

from ..config import GnssSpec
from ..geo.earth import radii
from ..geo.frames import quat_to_mat
from ..types import FloatArray, GnssStream, Trajectory


def antenna_position_velocity(
    truth: Trajectory, t: FloatArray, gyro_nb_b: FloatArray | None, lever_arm_b: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """True antenna lla (N, 3) and NED velocity (N, 3) at times ``t``.

    p_ant = p_imu + C_nb·l (converted to lat/lon/h with the radii of curvature);
    v_ant = v_imu + C_nb·(ω_nb^b × l). ``gyro_nb_b`` (N, 3) is ω_nb^b at ``t`` or None for
    a static lever-arm contribution only.
    """
    tr = truth.at(t)
    lla = tr.lla.copy()
    vel = tr.vel_n.copy()
    if np.any(lever_arm_b != 0):
        if tr.q_nb is None:
            raise ValueError("gnss: a lever arm needs the truth attitude")
        c = quat_to_mat(tr.q_nb)
        d_n = c @ lever_arm_b
        rn, re = radii(lla[:, 0])
        lla[:, 0] += d_n[:, 0] / (rn + lla[:, 2])
        lla[:, 1] += d_n[:, 1] / ((re + lla[:, 2]) * np.cos(lla[:, 0]))
        lla[:, 2] -= d_n[:, 2]
        if gyro_nb_b is not None:
            vel += np.einsum("nij,nj->ni", c, np.cross(gyro_nb_b, lever_arm_b))
    return lla, vel


def simulate_gnss(
    truth: Trajectory, gyro_nb_b_fn, spec: GnssSpec, rng: np.random.Generator,
    t_start: float | None = None,
) -> tuple[GnssStream, FloatArray]:
    """Sample fixes at ``spec.rate_hz`` over the truth span, minus outage windows.

    Returns the stream and a boolean (N,) array marking fixes that were made outliers.
    ``gyro_nb_b_fn(t)`` gives ω_nb^b (N, 3) for the lever-arm velocity term (or None).
    """
    t0 = truth.t[0] if t_start is None else t_start
    dt = 1.0 / spec.rate_hz
    t = np.arange(t0 + dt, truth.t[-1] + 1e-9, dt)
    # time of validity is latency_s before the stamp
    t_valid = np.maximum(t - spec.latency_s, truth.t[0])
    for a, b in spec.outages:
        t_keep = ~((t >= a) & (t < b))
        t, t_valid = t[t_keep], t_valid[t_keep]
    lever = np.asarray(spec.lever_arm_b, dtype=float)
    w = None if gyro_nb_b_fn is None else gyro_nb_b_fn(t_valid)
    lla, vel = antenna_position_velocity(truth, t_valid, w, lever)
    n = t.size
    sd = np.tile([spec.pos_sd_h, spec.pos_sd_h, spec.pos_sd_v], (n, 1))
    err_n = rng.normal(size=(n, 3)) * sd
    outlier = rng.random(n) < spec.outlier_prob
    err_n[outlier] += rng.normal(size=(int(outlier.sum()), 3)) * spec.outlier_sd
    rn, re = radii(lla[:, 0])
    lla = lla + np.column_stack(
        [err_n[:, 0] / (rn + lla[:, 2]), err_n[:, 1] / ((re + lla[:, 2]) * np.cos(lla[:, 0])),
         -err_n[:, 2]]
    )
    vel_n = vel_sd = None
    if spec.vel_sd > 0:
        vel_n = vel + rng.normal(size=(n, 3)) * spec.vel_sd
        vel_sd = np.full((n, 3), spec.vel_sd)
    stream = GnssStream(t, lla, sd, vel_n, vel_sd, lever, spec)
    return stream, outlier
