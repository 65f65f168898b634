"""The kernel inputs the EKF reads from a drive, besides the alignment and the measurement
records (``ekf.updates``): the covariance and output grids over the IMU epochs, the discrete
process noise per grid interval, the roll/pitch relevelling after IMU gaps, and the events of
every measurement kind merged into one time-sorted list (``events``, from the stamps of
``updates.measurements``; it knows no kind by name). ``ekf.filter.run_forward`` packs them
into the kernel records (``ekf.kernel``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ...config import ImuSpec
from ...nav.arrays import nearest_index
from ...nav.gaps import GAP_ACCEL_SD
from ...nav.levelling import coarse_level
from ...sensors.model import BaroPrior
from ...sensors.noise import gm_process_var, imu_bias_step, white_sd
from ...types.streams import FloatArray, ImuStream
from . import model as km
from .settings import EkfConfig

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
    # IMU gaps: the grid interval ending at gap end i+1 is exactly the gap (docs/ekf.md, "IMU gaps")
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
    """The measurement events of every kind merged into one time-sorted list."""

    ev_t: FloatArray
    ev_type: NDArrayInt  # event kind: the position of its record in ``updates.Measurements``
    ev_idx: NDArrayInt  # index into the kind's record
    max_pending: int  # most events inside one grid interval, + 1


def events(t: FloatArray, grid_idx: NDArrayInt, stamps: list[FloatArray]) -> Events:
    """The merged event list of the stamps [s] of each kind (``updates.measurements``, in
    the kinds' order), over the IMU stamps ``t`` and the grid epochs ``grid_idx``."""
    ev_t_l = [np.asarray(s, dtype=float) for s in stamps]
    ev_type_l = [np.full(s.size, kind, dtype=np.int64) for kind, s in enumerate(stamps)]
    ev_idx_l = [np.arange(s.size) for s in stamps]
    ev_t = np.concatenate(ev_t_l)
    order = np.argsort(ev_t, kind="stable")
    ev_t = ev_t[order]
    ev_type = np.concatenate(ev_type_l)[order]
    ev_idx = np.concatenate(ev_idx_l)[order]
    # events stamped on an IMU sample up to float round-off are put exactly on it, so that a
    # measurement at a grid epoch is processed there without back-propagation
    if ev_t.size:
        j = nearest_index(t, ev_t)
        ev_t = np.where(np.abs(t[j] - ev_t) < 1e-6, t[j], ev_t)
    counts = np.diff(np.searchsorted(ev_t, t[grid_idx], side="right"))
    max_pending = int(counts.max()) + 1 if counts.size else 1
    return Events(ev_t, ev_type, ev_idx, max_pending)
