"""What the seed-001 vertical EKF (``vekf7``) is fed: its state layout, the noise densities
of its inputs, its initial state, the measurement events and the GNSS lever arm.

``input_error_psd`` is the density of the vertical-input error (tilt times horizontal
acceleration, shared with ``vkf4``); ``noise_densities`` collects every process and
measurement noise of a run (``Noise``); ``initial_state`` starts the filter from the first
fix; ``measurement_events`` merges GNSS and baro epochs into one time-ordered list;
``transport_rate2`` and ``lever_arm_dz`` give the (ω_en)² vertical term and the lever arm's
vertical offset at the IMU epochs. The equations are in the ``vekf7`` module docstring.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ...geo.earth import radii
from ...sensors.model import SensorModel
from ...sensors.noise import gm_process_var, gm_transition
from ...types import Drive
from ...types.streams import FloatArray, IntArray
from .gnss_reference import nominal_interval
from .inputs import VerticalInputs

NX = 8  # 7 filter states + the accumulator I = ∫ b dt
IH, IV, IB, IK, IS, ITD, IBB, II = range(NX)


def input_error_psd(
    drive: Drive, vi: VerticalInputs, base_psd: float, tilt_sd: float, gyro_bias_sd: float,
    corr_s: float,
) -> FloatArray:
    """PSD of the vertical specific-force input error at the IMU epochs [(m/s²)²/Hz], (N,).

    The attitude reference (``vertical.inputs``) is GNSS-aided: with fixes its tilt error is
    ≈ ``tilt_sd``; in a GNSS outage it grows with the gyro bias, σ_ψ = tilt_sd + σ_bg·t_gap,
    and it has no Coriolis term there (no horizontal velocity). The f_D error is then
    σ_f² = (σ_ψ·|f_h|)² + (2Ω_ie·|v_h|)²·[in outage], |f_h| the horizontal specific force, and
    is treated as white with PSD base_psd + 2·corr_s·σ_f² (first-order Markov of correlation
    time corr_s and variance σ_f², integrated over its correlation time).
    """
    from ...geo.earth import OMEGA_IE
    from ...geo.frames import quat_to_mat

    t = vi.t
    f_n = np.einsum("nij,nj->ni", quat_to_mat(vi.q_nb), drive.imu.accel_b)
    f_h = np.hypot(f_n[:, 0], f_n[:, 1])
    gn = drive.gnss
    if gn is None or gn.t.size < 2:
        t_gap = t - t[0]
        v_h = np.zeros(t.size)
    else:
        nominal = nominal_interval(gn.t)
        i = np.searchsorted(gn.t, t, side="right") - 1
        t_last = np.where(i >= 0, gn.t[np.maximum(i, 0)], t[0])
        t_gap = np.maximum(t - t_last - nominal, 0.0)
        v_h = np.zeros(t.size) if gn.vel_n is None else np.hypot(
            gn.vel_n[np.maximum(i, 0), 0], gn.vel_n[np.maximum(i, 0), 1])
    sig_psi = tilt_sd + gyro_bias_sd * t_gap
    var_f = (sig_psi * f_h) ** 2 + np.where(t_gap > 0, (2 * OMEGA_IE * v_h) ** 2, 0.0)
    return base_psd + 2.0 * corr_s * var_f


def given(value: float | None, shared: float) -> float:
    """A config override when set, else the shared sensor model's value."""
    return float(shared if value is None else value)


@dataclass(frozen=True)
class Noise:
    """Process noise per IMU step and priors of one run (discrete values from sensors.noise)."""

    q_acc: FloatArray  # vertical specific-force PSD at the IMU epochs [(m/s²)²/Hz]
    phi_b: FloatArray  # baro-bias transition per IMU step
    q_b: FloatArray  # baro-bias process variance per IMU step [m²]
    phi_ab: FloatArray  # B_z transition per IMU step
    q_ab: FloatArray  # B_z process variance per IMU step [(m/s²)²]
    r_baro: float  # baro noise variance [m²]
    ab_sd: float  # prior σ of B_z [m/s²]
    k_sd: float  # prior σ of K_z
    scale_sd: float  # prior σ of dSF
    latency_mean: float  # prior mean of Td [s]
    latency_sd: float  # prior σ of Td [s]
    b_sd: float  # prior σ of the baro bias [m]


def noise_densities(drive: Drive, vi: VerticalInputs, model: SensorModel, cfg: Any) -> Noise:
    """The shared sensor model (``sensors.model``) with ``cfg``'s overrides."""
    ims = model.imu
    bp = model.baro
    assert bp is not None
    t = drive.imu.t
    dt = np.diff(t)
    if cfg.accel_psd is not None:
        q_acc = np.full(t.size, cfg.accel_psd)
    else:
        q_acc = input_error_psd(
            drive, vi, ims.accel_noise_density**2 + cfg.input_error_psd, cfg.tilt_sd,
            ims.gyro_bias_sd, cfg.input_corr_s)
    ab_sd = given(cfg.accel_bias_sd, ims.accel_bias_sd)
    ab_tau = given(cfg.accel_bias_tau, ims.accel_bias_tau)
    ab_rw = max(cfg.accel_bias_rw, ims.accel_bias_rw)
    b_sd = given(cfg.baro_bias_sd, bp.bias_sd)
    b_tau = given(cfg.baro_bias_tau, bp.bias_tau)
    return Noise(
        q_acc=q_acc,
        phi_b=gm_transition(dt, b_tau),
        q_b=gm_process_var(dt, b_tau, b_sd),
        phi_ab=gm_transition(dt, ab_tau),
        q_ab=gm_process_var(dt, ab_tau, ab_sd) + ab_rw**2 * dt,
        r_baro=given(cfg.baro_noise_sd, bp.noise_sd) ** 2,
        ab_sd=ab_sd,
        k_sd=given(cfg.accel_scale_sd, ims.accel_scale_sd),
        scale_sd=given(cfg.baro_scale_sd, bp.scale_sd),
        latency_mean=given(cfg.baro_latency_mean, bp.latency_mean),
        latency_sd=given(cfg.baro_latency_sd, bp.latency_sd),
        b_sd=b_sd,
    )


def transport_rate2(drive: Drive, vi: VerticalInputs) -> FloatArray:
    """ρ_E² + ρ_N² at the IMU epochs from the GNSS horizontal velocity of the last fix at or
    before each epoch, held (0 before the first fix and without receiver velocity)."""
    t = drive.imu.t
    h0 = float(drive.origin_lla[2])
    gn = drive.gnss
    rho2 = np.zeros(t.size)
    if gn is not None and gn.vel_n is not None and gn.t.size:
        i = np.searchsorted(gn.t, t, side="right") - 1
        v = np.where((i >= 0)[:, None], gn.vel_n[np.maximum(i, 0), :2], 0.0)
        vn, ve = v[:, 0], v[:, 1]
        rn, re = radii(vi.lat)
        rho2 = (ve / (re + h0)) ** 2 + (vn / (rn + h0)) ** 2
    return rho2


def initial_fix(gn: Any, t0: float) -> int | None:
    """Index of the last GNSS fix at or before ``t0`` and at most 5 s old (None: no such
    fix): the filters start from data they have at their first epoch, never a later fix."""
    if gn is None or gn.t.size == 0:
        return None
    i = int(np.searchsorted(gn.t, t0, side="right")) - 1
    return i if i >= 0 and t0 - gn.t[i] <= 5.0 else None


def initial_state(drive: Drive, g_psd: FloatArray | None,
                   nz: Noise) -> tuple[FloatArray, FloatArray]:
    """Nominal state and covariance at the first IMU epoch: GNSS height and vertical velocity
    of the last fix at or before it (``initial_fix``), else the last baro altitude at or
    before it (the first one when none) with the bias prior."""
    assert drive.baro is not None
    t0 = drive.imu.t[0]
    gn = drive.gnss
    nom = np.zeros(NX)
    p = np.zeros((NX, NX))
    i0 = initial_fix(gn, t0)
    if i0 is not None:
        assert g_psd is not None
        nom[IH] = float(gn.lla[i0, 2])
        p[IH, IH] = float(g_psd[i0, 2]) ** 2
    else:
        kb = max(int(np.searchsorted(drive.baro.t, t0, side="right")) - 1, 0)
        nom[IH] = float(drive.baro.altitude[kb])
        p[IH, IH] = nz.b_sd**2 + 1.0
    if i0 is not None and gn.vel_n is not None:
        nom[IV] = -float(gn.vel_n[i0, 2])
    p[IV, IV] = 0.5**2
    nom[ITD] = nz.latency_mean
    np.fill_diagonal(p, np.diag(p) + np.array(
        [0.0, 0.0, nz.ab_sd**2 + 1e-12, nz.k_sd**2 + 1e-12, nz.scale_sd**2 + 1e-12,
         nz.latency_sd**2, nz.b_sd**2, 0.0]))
    return nom, p


def measurement_events(drive: Drive) -> tuple[FloatArray, IntArray, IntArray, IntArray]:
    """Measurement events inside the IMU span sorted by time (baro first on a tie): stamp,
    kind (0 baro, 1 GNSS), sample index, and the first IMU epoch at or after the stamp (where
    the event is processed)."""
    assert drive.baro is not None
    t = drive.imu.t
    gn = drive.gnss
    ev_t = [drive.baro.t]
    ev_kind = [np.zeros(drive.baro.t.size, dtype=np.int64)]
    ev_idx = [np.arange(drive.baro.t.size)]
    if gn is not None:
        ev_t.append(gn.t)
        ev_kind.append(np.ones(gn.t.size, dtype=np.int64))
        ev_idx.append(np.arange(gn.t.size))
    et = np.concatenate(ev_t)
    ek = np.concatenate(ev_kind)
    ei = np.concatenate(ev_idx)
    order = np.lexsort((ek, et))
    et, ek, ei = et[order], ek[order], ei[order]
    keep = (et >= t[0]) & (et <= t[-1])
    et, ek, ei = et[keep], ek[keep], ei[keep]
    return et, ek, ei, np.searchsorted(t, et, side="left")


def lever_arm_dz(drive: Drive, vi: VerticalInputs) -> FloatArray:
    """Antenna height offset −[C_nb l]_D from the attitude reference (zero lever arm: 0)."""
    gn = drive.gnss
    if gn is not None and np.any(gn.lever_arm_b != 0):
        from ...geo.frames import quat_to_mat

        return -(quat_to_mat(vi.q_nb) @ gn.lever_arm_b)[:, 2]
    return np.zeros(drive.imu.t.size)
