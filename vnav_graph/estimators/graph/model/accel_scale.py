"""The accelerometer scale factors of the graph smoothers: the variable ``AccelScale`` (A(0),
a random constant k_a per axis) and the interval mean specific force it multiplies."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ....types.streams import FloatArray


@dataclass(frozen=True)
class AccelScale:
    """The accelerometer scale-factor variable A(0) (3, random constant k_a, prior N(0, sd²)):
    ``f_mean`` (K, 3) is the mean measured specific force ā_k [m/s²] of interval k (body
    frame; the last keyframe's is its interval's, a gap interval's its predecessor's), so
    that B(k) is the effective accelerometer bias b_a + diag(ā_k)·k_a of interval k."""

    sd: float
    f_mean: FloatArray

    def true_bias(self, ba_eff: FloatArray, ka: FloatArray, k: np.ndarray) -> FloatArray:
        """b_a at intervals ``k`` from the effective biases ``ba_eff`` (len(k), 3)."""
        return ba_eff - self.f_mean[k] * ka


def interval_mean_force(t: FloatArray, accel: FloatArray, kf_idx: np.ndarray,
                        gap: np.ndarray) -> FloatArray:
    """ā_k (K, 3): the time average of the midpoint specific force the preintegration uses
    over each interval (``AccelScale``)."""
    dt = np.diff(t)
    fm = 0.5 * (accel[:-1] + accel[1:]) * dt[:, None]
    cs = np.vstack([np.zeros((1, 3)), np.cumsum(fm, axis=0)])
    ct = np.r_[0.0, np.cumsum(dt)]
    j0, j1 = kf_idx[:-1], kf_idx[1:]
    out = np.empty((kf_idx.size, 3))
    out[:-1] = (cs[j1] - cs[j0]) / np.maximum(ct[j1] - ct[j0], 1e-12)[:, None]
    for k in np.flatnonzero(gap):  # no inertial information across a logging gap
        out[k] = out[k - 1] if k > 0 else out[min(k + 1, out.shape[0] - 2)]
    out[-1] = out[-2] if kf_idx.size > 1 else 0.0
    return out
