"""The kernel inputs the EKF reads from a drive, besides the alignment: the covariance and
output grids over the IMU epochs, the discrete process noise per grid interval, the roll/pitch
relevelling after IMU gaps, and the GNSS/baro/magnetometer samples and zero-velocity updates
merged into one time-sorted event list. ``ekf.filter.run_forward`` packs them into the
kernel records (``ekf.kernel``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ...config import ImuSpec
from ...nav.arrays import nearest_index
from ...nav.gaps import GAP_ACCEL_SD
from ...nav.levelling import coarse_level
from ...sensors.model import BaroPrior, SensorModel
from ...sensors.noise import gm_process_var, imu_bias_step, white_sd
from ...types import Drive
from ...types.streams import FloatArray, ImuStream
from . import model as km
from .alignment import track_heading
from .magnetometer import one_per_interval
from .settings import EkfConfig
from .updates import BARO, GNSS, MAG, ZUPT

NDArrayInt = Any

def _white_var(density: float, dt: FloatArray) -> FloatArray:
    """Variance density²·Δt of integrated white noise over Δt, via ``noise.white_sd``."""
    out = np.zeros_like(dt)
    for d in np.unique(dt):
        if d > 0:
            out[dt == d] = (white_sd(density, float(d)) * d) ** 2
    return out


@dataclass(frozen=True)
class Grids:
    """Which IMU epochs are covariance-grid, covariance-output and trajectory-output epochs.

    ``grid_idx``: IMU samples of the propagation grid (every ``m_grid``-th, the last, both
    ends of every IMU gap); ``grid_of[i]``: grid number of IMU sample i (−1 if none);
    ``cov_grid``: grid numbers output every ``e_cov``-th (and the last), ``cov_out_of[k]``
    their slot; ``out_idx`` / ``out_of``: the same for the trajectory (every ``d_out``-th
    sample, every grid epoch, the last); ``gap_step[i]``: IMU interval i → i+1 is a gap.
    """

    m_grid: int
    grid_idx: NDArrayInt
    grid_of: NDArrayInt
    e_cov: int
    cov_grid: NDArrayInt
    cov_out_of: NDArrayInt
    d_out: int
    out_idx: NDArrayInt
    out_of: NDArrayInt
    gap_step: NDArrayInt


def grids(t: FloatArray, gaps: NDArrayInt, rate: float, cfg: EkfConfig) -> Grids:
    n = t.size
    m_grid = max(1, round(rate / cfg.cov_rate_hz))
    gap_step = np.zeros(n - 1, dtype=bool)
    gap_step[gaps] = True
    grid_idx = np.union1d(np.union1d(np.arange(0, n, m_grid), [n - 1]),
                          np.r_[gaps, gaps + 1]).astype(np.int64)
    kk = grid_idx.size
    grid_of = np.full(n, -1, dtype=np.int64)
    grid_of[grid_idx] = np.arange(kk)
    e_cov = max(1, round(cfg.cov_rate_hz / cfg.cov_output_hz))
    cov_grid = np.arange(0, kk, e_cov)
    if cov_grid[-1] != kk - 1:
        cov_grid = np.append(cov_grid, kk - 1)
    cov_out_of = np.full(kk, -1, dtype=np.int64)
    cov_out_of[cov_grid] = np.arange(cov_grid.size)
    d_out = 1 if cfg.traj_rate_hz is None else max(1, round(rate / cfg.traj_rate_hz))
    out_idx = np.union1d(np.union1d(np.arange(0, n, d_out), grid_idx), [n - 1])
    out_of = np.full(n, -1, dtype=np.int64)
    out_of[out_idx] = np.arange(out_idx.size)
    return Grids(m_grid, grid_idx, grid_of, e_cov, cov_grid, cov_out_of, d_out, out_idx,
                  out_of, gap_step)


def process_noise(t: FloatArray, grid_idx: NDArrayInt, gaps: NDArrayInt, ispec: ImuSpec,
                   bp: BaroPrior, cfg: EkfConfig) -> FloatArray:
    """Discrete process-noise variances (diagonal) per grid interval, (K, NX) (noise.py)."""
    dtg = np.r_[0.0, np.diff(t[grid_idx])]
    qd = np.zeros((grid_idx.size, km.NX))
    qd[:, km.IVEL:km.IVEL + 3] = _white_var(ispec.accel_noise_density, dtg)[:, None]
    qd[:, km.IATT:km.IATT + 3] = _white_var(ispec.gyro_noise_density, dtg)[:, None]
    # the IMU biases' step (φ, var w) of both families (sensors.noise.imu_bias_step)
    qd[:, km.IBG:km.IBG + 3] = imu_bias_step(dtg, ispec.gyro_bias_tau, ispec.gyro_bias_sd,
                                             ispec.gyro_bias_rw)[1][:, None]
    qd[:, km.IBA:km.IBA + 3] = imu_bias_step(dtg, ispec.accel_bias_tau, ispec.accel_bias_sd,
                                             ispec.accel_bias_rw)[1][:, None]
    qd[:, km.IBB] = gm_process_var(dtg, bp.bias_tau, bp.bias_sd)
    gm = cfg.gnss_gm
    if gm is not None:
        for ax, sd in zip(gm.axes, gm.sd, strict=True):
            qd[:, km.IGE + ax] = gm_process_var(dtg, gm.tau_s, float(sd))
    qd[:, km.IMB:km.IMB + 3] = _white_var(cfg.mag_bias_rw, dtg)[:, None]
    # IMU gaps: the grid interval ending at gap end i+1 is exactly the gap (ekf.model docstring)
    kg = np.searchsorted(grid_idx, gaps + 1)
    dg = dtg[kg]
    qd[kg, km.IPOS:km.IPOS + 3] += (GAP_ACCEL_SD**2 * dg**3 / 3.0)[:, None]
    qd[kg, km.IVEL:km.IVEL + 3] = (GAP_ACCEL_SD**2 * dg)[:, None]
    qd[kg, km.IATT:km.IATT + 2] = cfg.gap_level_sd**2
    qd[kg, km.IATT + 2] = cfg.gap_yaw_rw**2 * dg
    return qd


def gap_relevel(imu: ImuStream, gaps: NDArrayInt, cfg: EkfConfig) -> FloatArray:
    """Roll/pitch [rad] after each IMU gap from the mean specific force of its first
    ``gap_level_s``, at the gap's end sample (NaN elsewhere), (N, 2)."""
    t = imu.t
    gap_rp = np.full((t.size, 2), np.nan)
    for i in gaps:
        j1 = max(int(np.searchsorted(t, t[i + 1] + cfg.gap_level_s, side="right")), i + 2)
        gap_rp[i + 1] = coarse_level(imu.accel_b[i + 1:j1].mean(axis=0))
    return gap_rp


@dataclass(frozen=True)
class Events:
    """GNSS fixes and baro samples merged into one time-sorted event list, with the per-fix
    arrays the kernel reads (empty without the stream)."""

    ev_t: FloatArray
    ev_type: NDArrayInt  # 0 GNSS fix, 1 baro sample, 2 magnetometer sample, 3 ZUPT
    ev_idx: NDArrayInt  # index into the stream
    max_pending: int  # most events inside one grid interval, + 1
    g_lla: FloatArray
    g_psd: FloatArray
    g_vel: FloatArray
    g_vsd: FloatArray
    has_vel: bool
    tr_yaw: FloatArray
    tr_speed: FloatArray
    tr_sd: FloatArray
    b_alt: FloatArray
    m_field: FloatArray


def events(drive: Drive, model: SensorModel, grid_idx: NDArrayInt, g_latency: float,
            cfg: EkfConfig, use_mag: bool, zupt_t: FloatArray | None = None) -> Events:
    """The merged event list; ``zupt_t``: stamps of the zero-velocity updates [s]
    (``nav.standstill.Standstill.update_times``), None for none."""
    t = drive.imu.t
    gnss, baro = drive.gnss, drive.baro
    ev_t_l, ev_type_l, ev_idx_l = [], [], []
    if gnss is not None:
        ev_t_l.append(gnss.t - g_latency)
        ev_type_l.append(np.full(gnss.t.size, GNSS, dtype=np.int64))
        ev_idx_l.append(np.arange(gnss.t.size))
        tr = track_heading(gnss, cfg.sideslip_sd, drive.imu)
        g_lla, g_psd = gnss.lla, model.gnss_pos_sd
        has_vel = gnss.vel_n is not None and model.gnss_vel_sd is not None
        g_vel = gnss.vel_n if has_vel else np.zeros((gnss.t.size, 3))
        g_vsd = model.gnss_vel_sd if has_vel else np.ones((gnss.t.size, 3))
        tr_yaw, tr_speed, tr_sd = tr.yaw, tr.speed, tr.yaw_sd
    else:
        g_lla = g_psd = g_vel = g_vsd = np.zeros((0, 3))
        has_vel = False
        tr_yaw = tr_speed = tr_sd = np.zeros(0)
    if baro is not None:
        ev_t_l.append(baro.t)
        ev_type_l.append(np.full(baro.t.size, BARO, dtype=np.int64))
        ev_idx_l.append(np.arange(baro.t.size))
        b_alt = np.asarray(baro.altitude, dtype=float)
    else:
        b_alt = np.zeros(0)
    if use_mag:
        assert drive.mag is not None
        im = one_per_interval(drive.mag.t, cfg.mag_interval_s)
        ev_t_l.append(drive.mag.t[im])
        ev_type_l.append(np.full(im.size, MAG, dtype=np.int64))
        ev_idx_l.append(np.arange(im.size))
        m_field = np.ascontiguousarray(drive.mag.field_b[im])
    else:
        m_field = np.zeros((0, 3))
    if zupt_t is not None and zupt_t.size:
        ev_t_l.append(np.asarray(zupt_t, dtype=float))
        ev_type_l.append(np.full(zupt_t.size, ZUPT, dtype=np.int64))
        ev_idx_l.append(np.arange(zupt_t.size))
    if ev_t_l:
        ev_t = np.concatenate(ev_t_l)
        order = np.argsort(ev_t, kind="stable")
        ev_t = ev_t[order]
        ev_type = np.concatenate(ev_type_l)[order]
        ev_idx = np.concatenate(ev_idx_l)[order]
    else:
        ev_t, ev_type, ev_idx = np.zeros(0), np.zeros(0, np.int64), np.zeros(0, np.int64)
    # events stamped on an IMU sample up to float round-off are put exactly on it, so that a
    # measurement at a grid epoch is processed there without back-propagation
    if ev_t.size:
        j = nearest_index(t, ev_t)
        ev_t = np.where(np.abs(t[j] - ev_t) < 1e-6, t[j], ev_t)
    counts = np.diff(np.searchsorted(ev_t, t[grid_idx], side="right"))
    max_pending = int(counts.max()) + 1 if counts.size else 1
    return Events(ev_t, ev_type, ev_idx, max_pending, np.ascontiguousarray(g_lla),
                   np.ascontiguousarray(g_psd), np.ascontiguousarray(g_vel),
                   np.ascontiguousarray(g_vsd), bool(has_vel), tr_yaw, tr_speed, tr_sd, b_alt,
                   m_field)
