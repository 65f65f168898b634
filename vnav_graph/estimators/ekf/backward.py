"""The filter run backward in time, and the forward/backward separation of ``ekf-rts``
(``EkfConfig.fb_separation``): a quality check without truth, as flight-test
post-processors show it.

Backward pass: the same forward EKF over the drive played backward, on the clock
s = t0 + t1 − t. Position and attitude histories are the same; the velocity changes sign,
the specific force is unchanged, and the gyro measures −ω_ib. Played backward, the
rotating Earth turns the other way: with v' = −v the reversed dynamics are
dv'/ds = C f + g + 2Ω×v' − ω_en(v')×v' and dC/ds = −C[ω_ib×] + [(ω_ie − ω_en(v'))×]C, while
the filter integrates C f' + g − 2Ω×v' − ω_en(v')×v' and C[ω'×] − [(ω_ie + ω_en(v'))×]C. The
backward samples are therefore
    ω' = −ω_ib + 2 Cᵀ ω_ie,    f' = f + Cᵀ (4 ω_ie × v'),
with C and v from the forward smoothed solution (a 1° attitude error moves these terms by
1.7 % of the Earth rate). GNSS fixes keep their positions and σ, their velocities change sign;
a baro sample h_b(t) = h(t − τ) would need a negative latency backward, so it is stamped
s + 2τ̂ (τ̂ the forward smoothed latency), which leaves the filter's model h(s − τ') with
τ' = 2τ̂ − τ ≈ τ. The magnetometer is left out and the heading is acquired again in motion
(no information from the forward pass enters the backward filter's measurements). Played
backward a car drives in reverse, which breaks what the alignment assumes (course = heading,
the launch acceleration along +x): the backward body axes are turned 180° about z (``TURN``:
IMU axes and lever arm), so the reversed vehicle moves forward again in its own frame.

Separation: the forward filter (``ekf``'s pass, causal) and the backward filter are both
filtered estimates with independent measurement histories; their difference at the forward
output epochs, |h_f − h_b| and the horizontal distance, is what a post-processor plots
(e.g. NovAtel Inertial Explorer's "combined separation"). ``alt_p95_m`` / ``horiz_p95_m`` are
their 95th percentiles over the drive; the series at 1 Hz goes into ``info`` for the plot.

Does it track the smoothed error? (``benchmarks/fb_separation.py``, correlation over seeds of
the separation's p95 with the ekf-rts error's p95; Pearson / Spearman.) urban, 4 seeds:
altitude 0.91 / 0.80, horizontal 0.95 / 1.00, error ≈ 0.7 × separation; default, 6 seeds:
altitude 0.83 / 0.71, horizontal 0.55 / 0.60 (its 60 s outage makes the horizontal
separation 40–70 m against 0.9–1.8 m of smoothed error: each filter alone crosses the outage
dead-reckoning); cold-start-phone, 6 seeds: −0.30 / −0.37 and 0.24 / 0.09 — its seeds' errors
differ little (altitude 0.7–1.3 m), and the separation does not rank them. It says how hard
a drive is, not which of two similar drives came out better. With a consumer IMU and
sparse GNSS (a phone with 1 Hz position-only fixes) the backward filter's start can be poor,
and the horizontal separation then orders of magnitude above the smoothed error: the number
is best read as "the data do not pin the horizontal down without smoothing"
(docs/real_logs.md, "Forward-backward separation").
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from ...geo.earth import OMEGA_IE, radii
from ...geo.frames import quat_to_mat
from ...types import Drive, Estimate, Trajectory
from ...types.streams import BaroStream, GnssStream, ImuStream
from .settings import EkfConfig

SERIES_HZ = 1.0  # rate of the separation series kept for the plot [Hz]
# body axes of the backward drive: turned 180° about z (x' = −x, y' = −y), so that a vehicle
# played backward still moves forward along its x axis
TURN = np.array([-1.0, -1.0, 1.0])


def reversed_drive(drive: Drive, traj: Trajectory, latency_s: float) -> Drive:
    """``drive`` played backward (module docstring); ``traj``: the forward smoothed solution
    (attitude, velocity, latitude for the Earth-rate terms), ``latency_s``: its baro latency."""
    imu = drive.imu
    t = imu.t
    span = float(t[0] + t[-1])
    j = np.clip(np.searchsorted(traj.t, t), 0, traj.t.size - 1)
    c = quat_to_mat(traj.q_nb[j])  # (N, 3, 3) C_nb
    lat = np.interp(t, traj.t, traj.lla[:, 0])
    w_ie = OMEGA_IE * np.column_stack([np.cos(lat), np.zeros_like(lat), -np.sin(lat)])
    v_rev = -np.column_stack([np.interp(t, traj.t, traj.vel_n[:, a]) for a in range(3)])
    gyro = -imu.gyro_b + 2.0 * np.einsum("kji,kj->ki", c, w_ie)
    accel = imu.accel_b + np.einsum("kji,kj->ki", c, 4.0 * np.cross(w_ie, v_rev))
    rev_imu = ImuStream(span - t[::-1], gyro[::-1] * TURN, accel[::-1] * TURN, imu.spec)
    gnss = drive.gnss
    rev_gnss = None
    if gnss is not None:
        g_lat = float(getattr(gnss.spec, "latency_s", 0.0)) if gnss.spec is not None else 0.0
        rev_gnss = GnssStream(span - gnss.t[::-1] + 2.0 * g_lat, gnss.lla[::-1],
                              gnss.pos_sd[::-1],
                              None if gnss.vel_n is None else -gnss.vel_n[::-1],
                              None if gnss.vel_sd is None else gnss.vel_sd[::-1],
                              np.asarray(gnss.lever_arm_b, dtype=float) * TURN, gnss.spec)
    baro = drive.baro
    rev_baro = None
    if baro is not None:
        rev_baro = BaroStream(span - baro.t[::-1] + 2.0 * latency_s,
                              None if baro.pressure is None else baro.pressure[::-1],
                              np.asarray(baro.altitude, dtype=float)[::-1], baro.spec)
    meta = {**dict(drive.meta), "name": f"{drive.name} (backward)"}
    return Drive(rev_imu, rev_gnss, rev_baro, drive.origin_lla, meta=meta)


def backward_config(cfg: EkfConfig) -> EkfConfig:
    """The backward filter's settings: the forward ones with the heading acquired in motion
    (a given heading is the start's, not the end's) and no compass."""
    return replace(cfg, initial_heading=None, use_mag=False, carry_heading_back=False,
                   post_gate=False, fb_separation=False)


def separation(forward: Trajectory, backward: Trajectory, span: float) -> dict[str, Any]:
    """|h_f − h_b| and the horizontal distance between the forward filter and the backward
    filter (on the reversed clock, ``span`` = t0 + t1) at the forward output epochs: their
    95th percentiles and the series at ``SERIES_HZ``."""
    tb = span - backward.t[::-1]
    lla_b = np.column_stack([np.interp(forward.t, tb, backward.lla[::-1, a])
                             for a in range(3)])
    lla_f = forward.lla
    rn, re = radii(lla_f[:, 0])
    alt = np.abs(lla_f[:, 2] - lla_b[:, 2])
    horiz = np.hypot((lla_f[:, 0] - lla_b[:, 0]) * (rn + lla_f[:, 2]),
                     (lla_f[:, 1] - lla_b[:, 1]) * (re + lla_f[:, 2]) * np.cos(lla_f[:, 0]))
    keep = np.searchsorted(forward.t, np.arange(forward.t[0], forward.t[-1], 1.0 / SERIES_HZ))
    return {"alt_p95_m": float(np.percentile(alt, 95)),
            "horiz_p95_m": float(np.percentile(horiz, 95)),
            "series": {"t": forward.t[keep].tolist(), "alt_m": alt[keep].tolist(),
                       "horiz_m": horiz[keep].tolist()}}


def fb_separation(drive: Drive, est: Estimate, cfg: EkfConfig, run_backward: Any
                  ) -> dict[str, Any] | None:
    """The forward/backward separation of ``est`` (an ``ekf-rts`` estimate with its
    forward pass in ``online``), or None without GNSS; ``run_backward(drive, cfg)`` runs the
    forward filter on the reversed drive and returns its estimate."""
    if drive.gnss is None or est.online is None:
        return None
    latency = est.baro.latency_s.est if est.baro is not None else 0.0
    rev = reversed_drive(drive, est.trajectory, float(latency))
    back: Estimate = run_backward(rev, backward_config(cfg))
    return separation(est.online, back.trajectory, float(drive.imu.t[0] + drive.imu.t[-1]))
