"""The acquired heading carried back to the start of the drive (``ekf-rts``,
``EkfConfig.carry_heading_back``).

A heading acquired in motion (GNSS track or acceleration matching, ``ekf.heading``) is a
state reset: the yaw row of the reset's Jacobian is zero (``model.reset_jacobian``), so the
RTS pass carries nothing back across it and the smoothed trajectory before the acquisition
keeps the arbitrary start heading (cold-start seed 7: 97° off in the first 2 s).

Before the acquisition the nominal yaw only integrates the gyros (its error state is
decoupled), so the whole pre-acquisition attitude history is the true one rotated about the
vertical by one angle, up to gyro drift. The reset at t_h rotates it by Δ (``reset_at``) and
the smoother then corrects the post-reset yaw by δ_s = ψ_s(t_h) − ψ_f(t_h). The forward pass
integrated the gyros with its own bias estimate b̂_f, which before the acquisition holds the
prior mean on the down axis (nothing observes it while the yaw is decoupled); the smoother
knows it from the motion after t_h (b̂_s, the bias is a Gauss-Markov state with τ of hours).
The heading at t0 is therefore

    ψ(t0) = ψ_f(t0) + Δ + δ_s + ∫_{t0}^{t_h} (C (b̂_s − b̂_f))_D dt,

with the variance of the smoothed yaw at t_h plus the drift of the smoothed bias's error,
(σ_bD (t_h − t0))², σ_bD² = c_Dᵀ P_bg c_D the largest over [t0, t_h] (c_D the down row of C,
P_bg the smoothed gyro-bias covariance). The smoothed bias's σ belongs there, not its prior's:
the motion after the acquisition pins the bias down, while the prior σ of a real log of
unknown make (0.5 °/s) grows to 7.5° over a 15 s standstill at the start, above
``CARRY_SD_MAX``, and nothing would be carried back (docs/real_logs.md, "Standstills and
course on the RTK drives"). The forward and RTS passes are then run again from t0 with that
heading given (``EkfConfig.initial_heading``): one smoothing over the whole drive, with no
reset in it.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ...geo.frames import quat_to_mat
from ...types import Estimate
from ...types.streams import FloatArray
from .settings import EkfConfig

# the largest σ of a heading carried back [rad]: 5°, the "heading known" bound of the
# metrics (evaluation.metrics.HEADING_KNOWN_SD_DEG). A multicopter hovering before its
# acquisition barely shows its heading, so even the smoother may know it only to about ten
# degrees, and the re-run would treat a yaw error that large as a linear state, far outside
# its linear regime (docs/real_logs.md, "Initial heading and tilt of a hovering
# multirotor"); cold-start and default carry 0.4° and 1.2°
CARRY_SD_MAX = np.radians(5.0)


@dataclass(frozen=True)
class CarriedHeading:
    """Heading at the drive's first epoch [rad], its σ [rad], and the acquisition time [s]."""

    yaw0: float
    sd: float
    t_acquired: float


def _yaw(q: FloatArray) -> FloatArray:
    q = np.asarray(q, dtype=float)
    return np.arctan2(2.0 * (q[..., 0] * q[..., 3] + q[..., 1] * q[..., 2]),
                      1.0 - 2.0 * (q[..., 2] ** 2 + q[..., 3] ** 2))


def _wrap(a: float) -> float:
    return float(np.arctan2(np.sin(a), np.cos(a)))


def carried_heading(t_grid: FloatArray, reset_at: FloatArray, t_out: FloatArray,
                    q_fwd: FloatArray, bg_fwd: FloatArray, smoothed: Estimate
                    ) -> CarriedHeading | None:
    """The heading at t0 from the first heading acquisition (module docstring), or None when
    the drive has none (heading given, from the compass, or never acquired).

    ``t_grid`` / ``reset_at``: the covariance grid and the yaw reset Δ at each of its epochs
    (NaN: none); ``t_out`` / ``q_fwd`` / ``bg_fwd``: the forward pass's output epochs,
    attitudes and gyro biases [rad/s]; ``smoothed``: the RTS estimate of the same pass
    (trajectory with its gyro biases on ``t_out``, ``cov``)."""
    k = np.flatnonzero(~np.isnan(reset_at))
    tr = smoothed.trajectory
    if (k.size == 0 or smoothed.cov is None or smoothed.t_cov is None or tr.q_nb is None
            or tr.bias_gyro is None):
        return None
    t_h = float(t_grid[k[0]])
    j = int(np.searchsorted(t_out, t_h))
    if j >= t_out.size or not np.isclose(t_out[j], t_h, rtol=0.0, atol=1e-9):
        return None
    delta_s = _wrap(float(_yaw(tr.q_nb[j]) - _yaw(q_fwd[j])))
    # the down component of the gyro-bias correction, integrated over [t0, t_h]
    c_d = quat_to_mat(tr.q_nb[:j + 1])[:, 2, :]  # (n, 3): the down row of C_nb
    rate = np.einsum("ni,ni->n", c_d, tr.bias_gyro[:j + 1] - bg_fwd[:j + 1])
    drift = float(np.sum(0.5 * (rate[1:] + rate[:-1]) * np.diff(t_out[:j + 1])))
    yaw0 = _wrap(float(_yaw(q_fwd[0])) + float(reset_at[k[0]]) + delta_s + drift)
    # the first covariance epoch at or after the acquisition (before it the yaw is unknown)
    jc = int(np.searchsorted(smoothed.t_cov, t_h - 1e-9))
    if jc >= smoothed.t_cov.size:
        return None
    # σ of the smoothed bias on the down axis, the largest over [t0, t_h]
    jq = np.clip(np.searchsorted(t_out, smoothed.t_cov[:jc + 1]), 0, j)
    p_bg = smoothed.cov[:jc + 1, 9:12, 9:12]
    var_bd = float(np.max(np.einsum("ni,nij,nj->n", c_d[jq], p_bg, c_d[jq])))
    var = float(smoothed.cov[jc, 8, 8]) + var_bd * (t_h - float(t_out[0])) ** 2
    return CarriedHeading(yaw0, float(np.sqrt(max(var, 0.0))), t_h)


def rerun_config(cfg: EkfConfig, info: dict[str, Any], t_grid: FloatArray,
                 reset_at: FloatArray, t_out: FloatArray, q_fwd: FloatArray,
                 bg_fwd: FloatArray, smoothed: Estimate
                 ) -> tuple[EkfConfig, dict[str, Any]] | None:
    """The settings of the re-run from t0 (the carried heading given) and the ``info``
    entries that report it, or None when there is nothing to carry back: the heading was
    given or from the compass, never acquired, or an IMU gap of at least
    ``gap_heading_forget_s`` lies before the acquisition (the vehicle may have turned in
    it). Shorter gaps before it add their heading random walk (``gap_yaw_rw``) to the σ.
    Nor when the carried σ exceeds ``CARRY_SD_MAX``."""
    if info["heading_source"] not in ("accel-matching", "gnss-course", "gnss-track"):
        return None
    ch = carried_heading(t_grid, reset_at, t_out, q_fwd, bg_fwd, smoothed)
    if ch is None:
        return None
    gaps = [g for g in info["imu_gaps"] if g[0] < ch.t_acquired]
    if any(g[1] >= cfg.gap_heading_forget_s for g in gaps):
        return None
    sd = float(np.hypot(ch.sd, cfg.gap_yaw_rw * np.sqrt(sum(g[1] for g in gaps))))
    if sd > CARRY_SD_MAX:
        return None
    report = {"heading_source": f"{info['heading_source']}, carried back",
              "heading_time_s": info["heading_time_s"],
              "heading_carried_back": {"yaw0_deg": float(np.degrees(ch.yaw0)),
                                       "sd_deg": float(np.degrees(sd)),
                                       "acquired_s": ch.t_acquired}}
    return replace(cfg, initial_heading=ch.yaw0, initial_heading_sd=sd), report
