"""The graph smoothers' own sensors beyond the IMU, GNSS and baro core: each is a factor
built on the public extension point (``extend``) that chains its ``sensors/`` model through
the keyframe variables, and ``builtin_extensions`` lists the ones a drive switches on.

Magnetometer: heading factors with a hard-iron bias variable, switched on by
``GraphConfig.use_mag`` whenever the drive has a magnetometer. The measurement model is the
one the EKF uses (``sensors.magnetometer``): the azimuth of the bias-corrected field rotated
into the graph's frame by the keyframe attitude R_k (body → tangent frame),

    e_k = wrap(atan2(m̂_E, m̂_N) − D_k),   m̂ = R_k (z − b_m),

one scalar ``gtsam.CustomFactor`` on X(k) and the hard-iron bias H(0) (3-vector [µT], prior
N(0, ``mag_bias_sd``² I)) per keyframe that has a sample within half a sample spacing, at
most one per ``mag_interval_s`` (the errors are correlated over seconds). D_k is the
azimuth, in the tangent frame, of the World Magnetic Model's field at the start
(``geo.magfield``; it is the declination up to the tangent frame's convergence, < 0.05°
over a few km). The error and its Jacobians are the EKF's row ``mag_heading_row`` (module
``sensors.magnetometer``) at R_k: ∂e/∂b_m as it is, and ∂e/∂ω_k = (∂e/∂ψ) R_k for the Pose3
retraction R Exp(ω), since the row's attitude error ψ is in n (R̃ = (I + [ψ×]) R, so ψ = R ω).
σ = √((σ_m/H)² + floor²); a Huber loss at ``mag_loss_sd`` σ stands in for the EKF's gate
(motor-current and soft-iron bursts).

Key: H(0) (``gtsam.symbol_shorthand.H``), reported as ``info["extra_variables"]["h0"]``;
a user extension must not declare H(0) as well.
"""

from __future__ import annotations

from typing import Any

import gtsam
import numpy as np
from gtsam.symbol_shorthand import H

from ....nav.arrays import nearest_index
from ....sensors.magnetometer import (
    MIN_HORIZONTAL_UT,
    drive_field,
    field_and_info,
    heading_sd,
    mag_heading_row,
    usable,
)
from ....types.streams import FloatArray
from .extend import GraphView, Terms, Variable, X

MAG_KEY = H(0)
# graph-isam2's relinearisation threshold of H(0) [µT per component]: its heading factors are
# rebuilt (``isam2.py_factors``) once H(0) moved this far since they were built. Every heading
# factor holds H(0), so such a move rebuilds all of them and re-eliminates the whole Bayes
# tree. 1 µT is a fifth of a logged magnetometer's σ (5 µT per axis), so the factors stay
# linearised within a fraction of their noise, while 0.05 µT rebuilds them at almost every
# update early in a drive (docs/real_logs.md, "Magnetometer noise, field strength and
# spread"); never relinearising on H(0) left a final cost gap of 16.4 to the batch check
# (hill-drive-mag 300 s, against 0.41).
MAG_RELIN_THRESHOLD_UT = 1.0


def mag_heading_factor(k: int, z_b: FloatArray, d_ref: float, sd: float, loss_sd: float) -> Any:
    """Keyframe k's heading factor on X(k) and H(0): sample ``z_b`` (3,) [µT], reference
    azimuth ``d_ref`` [rad], σ ``sd`` [rad], Huber at ``loss_sd`` σ (module docstring)."""
    base = gtsam.noiseModel.Isotropic.Sigma(1, sd)
    noise = gtsam.noiseModel.Robust.Create(gtsam.noiseModel.mEstimator.Huber.Create(loss_sd),
                                           base)

    key_x = X(k)

    def error(this: Any, values: Any, jac: Any) -> FloatArray:
        # the shared model's row (the EKF's) at R_k: its attitude error ψ is in n
        # (R̃ = (I + [ψ×]) R_k), the Pose3 retraction's ω in body (R_k Exp(ω)), so ψ = R_k ω
        r_k = np.ascontiguousarray(values.atPose3(key_x).rotation().matrix())
        e, h_psi, h_bias, _ = mag_heading_row(z_b, np.ascontiguousarray(values.atVector(MAG_KEY)),
                                              r_k, d_ref)
        if jac is not None:
            row = np.zeros((1, 6))
            row[0, 0:3] = h_psi @ r_k
            jac[0] = row
            jac[1] = h_bias[None, :]
        return np.array([e])

    return gtsam.CustomFactor(noise, [key_x, MAG_KEY], error)


class MagnetometerExtension:
    """The built-in extension (module docstring); ``config`` is the ``GraphConfig``."""

    name = "magnetometer"

    def __init__(self, config: Any) -> None:
        self.config = config

    def __call__(self, view: GraphView) -> Terms:
        cfg, mag = self.config, view.drive.mag
        assert mag is not None
        fm = drive_field(view.drive)[0]  # the origin is view.origin_lla
        cos_incl = float(np.hypot(fm.ned_ut[0], fm.ned_ut[1]) / np.linalg.norm(fm.ned_ut))
        # field reference in the tangent frame at each keyframe (initial position)
        i = nearest_index(mag.t, view.t_kf)
        spacing = float(np.median(np.diff(mag.t))) if mag.t.size > 1 else np.inf
        near = np.abs(mag.t[i] - view.t_kf) <= 0.5 * spacing
        slot = np.floor((view.t_kf - view.t_kf[0]) / cfg.mag_interval_s).astype(np.int64)
        factors = []
        last = -1
        for k in np.flatnonzero(near):
            if slot[k] == last:
                continue
            z = np.asarray(mag.field_b[i[k]], float)
            # the sample's horizontal strength: its magnitude at the reference field's
            # inclination (attitude-free, so that a keyframe's σ does not depend on an
            # initial attitude drawn from later data: graph-isam2's online answer is causal)
            hor = float(np.linalg.norm(z)) * cos_incl
            if hor < MIN_HORIZONTAL_UT:
                continue
            last = slot[k]
            ref = fm.ned_ut  # tangent ≈ local level at the start (module docstring)
            sd = float(heading_sd(mag.sd_ut, hor, cfg.mag_heading_floor))
            factors.append(mag_heading_factor(int(k), z, float(np.arctan2(ref[1], ref[0])), sd,
                                           cfg.mag_loss_sd))
        return Terms(factors, [Variable(MAG_KEY, np.zeros(3), cfg.mag_bias_sd,
                                        relinearize_threshold=MAG_RELIN_THRESHOLD_UT)])


def builtin_extensions(drive: Any, config: Any) -> list[Any]:
    """The smoother's own extensions for this drive (the magnetometer when it has one)."""
    if config.use_mag and usable(drive.mag)[0]:
        return [MagnetometerExtension(config)]
    return []


def mag_info(drive: Any, config: Any) -> dict[str, Any]:
    """What the smoother reports about the magnetometer: the EKF's ``info`` keys
    (``sensors.magnetometer.field_and_info``: why it is left out, or that the drive has no
    date; declination and field model when used)."""
    return field_and_info(drive, config.use_mag)[1]

