"""GNSS velocity against the IMU: a screen that needs no attitude.

Between two fixes a and b the accelerometer's specific force integrates to the velocity
change the receiver should report (Groves, 2nd ed., §5.4, in a local-level frame):

    v_b − v_a − g_n·Δt = C_a · U_ab,    U_ab = ∫_a^b (C_aᵀ C_t) f_t dt,

with C_t the body attitude, f the measured specific force, g_n = [0, 0, γ] (down) and
Coriolis 2Ω×v neglected (≤ 1.5e-4 m/s² per m/s: 3 mm/s over 1 s at 20 m/s). U_ab needs only
the *relative* attitude over the span, which the gyro gives; the attitude C_a itself is
unknown, but a rotation keeps the norm, so

    ν_ab = |v_b − v_a − g_n·Δt| − |U_ab|

is noise for a correct fix, whatever the heading and tilt. Its variance is
σ²_v,a + σ²_v,b (reported, mean per axis) + (σ_ba·Δt)² (accelerometer bias)
+ (σ_ka·|U_ab|)² (scale factor) + n_a²·Δt (accelerometer white noise) + ``FLOOR_MPS``².
Gravity dominates both norms, so a horizontal error δ against a reference fix Δt earlier
shows as ν ≈ δ²/(2gΔt) when δ ≪ gΔt (a vertical one fully): the screen catches steps at
their onset and gross faults (3 m/s within 0.3 s, 15 m/s within 5 s), not slow drifts or
small offsets that persist.

A fix whose ν against the last accepted fix exceeds the χ²₁ quantile of ``prob`` is
refused, position and velocity alike (one receiver solution). A step in the reported
velocity that the IMU did not feel is refused for as long as it lasts, up to
``HORIZON_S``: after that long without an accepted fix (or across an IMU logging gap, or at
the first fix) the reference is the previous fix instead, and a pair that agrees starts a
new chain (a fault longer than the horizon cannot be told from a correct level by this
test; re-anchoring after three refusals let a constant 3 m/s fault through). The screen is
causal: a fix is judged by earlier fixes only, so graph-isam2's online estimate stays a
filter's.

A receiver that reports a large σ_v over its own fault keeps its fixes (ν is normalised
by it); clean fixes are refused at the rate of the χ² tail (docs/real_logs.md, "GNSS
screens"; simulated hill-drive 0–1 of 5 400). The graph
smoothers apply it in their GNSS pre-gate (``graph.problem.setup``), before any solve:
a fault the solution would follow cannot be fitted first and gated after (``urban``,
6 seeds: graph-batch horizontal RMSE 3.80 → 3.58 m, better on every seed).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ..types.streams import FloatArray

HORIZON_S = 5.0  # s: longest span compared against one anchor fix
FLOOR_MPS = 0.05  # m/s: velocity time-tag and interpolation error floor
GAP_FACTOR = 5.0  # an IMU interval longer than this × the median one is a logging gap


@njit(cache=True)
def specific_force_integral(t_imu, gyro, accel, t_q, max_dt):
    """S(t) = ∫ C(t') f(t') dt' from the first IMU sample, in the frame of the first sample's
    body (gyro-propagated), at the sorted times ``t_q`` (rectangle rule, as the samples
    hold), and the IMU segment each query lies in (a new segment after every interval
    longer than ``max_dt``: a logging gap, across which S is not comparable). Queries
    outside the IMU span get NaN and segment −1. The attitude step is ``so3_exp``'s
    Rodrigues formula written out on preallocated arrays: with a 3×3 allocated per sample
    the pass took 0.5 s on a 1-hour 200 Hz drive, as long as the rest of the graph's
    set-up."""
    n, m = t_imu.size, t_q.size
    out = np.full((m, 3), np.nan)
    seg = np.full(m, -1, dtype=np.int64)
    c = np.eye(3)
    c_new = np.empty((3, 3))
    e = np.empty((3, 3))
    s = np.zeros(3)
    cf = np.empty(3)
    q = 0
    while q < m and t_q[q] < t_imu[0]:
        q += 1
    k = 0
    for j in range(n - 1):
        dt = t_imu[j + 1] - t_imu[j]
        for r in range(3):
            cf[r] = c[r, 0] * accel[j, 0] + c[r, 1] * accel[j, 1] + c[r, 2] * accel[j, 2]
        while q < m and t_q[q] <= t_imu[j + 1]:
            if dt <= max_dt:
                for r in range(3):
                    out[q, r] = s[r] + cf[r] * (t_q[q] - t_imu[j])
                seg[q] = k
            q += 1
        if dt > max_dt:
            k += 1
            continue
        for r in range(3):
            s[r] += cf[r] * dt
        # e = exp([φ×]) = I + α[φ×] + β[φ×]², [φ×]² = φφᵀ − |φ|²I (``so3_exp``)
        x, y, z = gyro[j, 0] * dt, gyro[j, 1] * dt, gyro[j, 2] * dt
        a2 = x * x + y * y + z * z
        ang = np.sqrt(a2)
        if ang < 1e-9:
            al, be = 1.0, 0.5
        else:
            al, be = np.sin(ang) / ang, (1.0 - np.cos(ang)) / a2
        e[0, 0] = 1.0 + be * (x * x - a2)
        e[1, 1] = 1.0 + be * (y * y - a2)
        e[2, 2] = 1.0 + be * (z * z - a2)
        e[0, 1] = -al * z + be * x * y
        e[1, 0] = al * z + be * x * y
        e[0, 2] = al * y + be * x * z
        e[2, 0] = -al * y + be * x * z
        e[1, 2] = -al * x + be * y * z
        e[2, 1] = al * x + be * y * z
        for r in range(3):
            for cc in range(3):
                c_new[r, cc] = c[r, 0] * e[0, cc] + c[r, 1] * e[1, cc] + c[r, 2] * e[2, cc]
        for r in range(3):
            for cc in range(3):
                c[r, cc] = c_new[r, cc]
    return out, seg


def velocity_screen(t: FloatArray, vel_n: FloatArray, vel_sd: FloatArray,
                    t_imu: FloatArray, gyro: FloatArray, accel: FloatArray, gravity: float,
                    accel_bias_sd: float, accel_scale_sd: float, accel_noise_density: float,
                    prob: float) -> np.ndarray:
    """Mask (N,) of the fixes that pass (module docstring). Fixes without a finite velocity
    or outside the IMU span are not judged (True)."""
    from scipy.stats import chi2

    keep = np.ones(t.size, dtype=bool)
    if t.size < 2 or t_imu.size < 2 or prob <= 0:
        return keep
    max_dt = GAP_FACTOR * float(np.median(np.diff(t_imu)))
    s_at, seg = specific_force_integral(np.ascontiguousarray(t_imu, float),
                                        np.ascontiguousarray(gyro, float),
                                        np.ascontiguousarray(accel, float),
                                        np.ascontiguousarray(t, float), max_dt)
    ok = np.all(np.isfinite(vel_n), axis=1) & np.all(np.isfinite(vel_sd), axis=1) & (seg >= 0)
    var_v = np.mean(vel_sd**2, axis=1)
    thr = float(chi2.ppf(prob, 1))
    return _anchor_pass(np.ascontiguousarray(t, float), np.ascontiguousarray(vel_n, float),
                        var_v, s_at, seg, ok, thr, gravity, accel_bias_sd, accel_scale_sd,
                        accel_noise_density)


@njit(cache=True)
def _anchor_pass(t, vel_n, var_v, s_at, seg, ok, thr, gravity, accel_bias_sd,
                 accel_scale_sd, accel_noise_density):
    """The causal pass of ``velocity_screen`` over the judged fixes ``ok``: each against the
    last accepted fix within ``HORIZON_S`` in its IMU segment, else against the previous
    one (module docstring). Returns the mask of kept fixes."""
    keep = np.ones(t.size, dtype=np.bool_)
    anchor, prev = -1, -1
    for i in range(t.size):
        if not ok[i]:
            continue
        ref = -1
        if anchor >= 0 and seg[anchor] == seg[i] and t[i] - t[anchor] <= HORIZON_S:
            ref = anchor
        elif prev >= 0 and seg[prev] == seg[i] and t[i] - t[prev] <= HORIZON_S:
            ref = prev
        if ref >= 0:
            dt = t[i] - t[ref]
            u = np.sqrt((s_at[i, 0] - s_at[ref, 0]) ** 2 + (s_at[i, 1] - s_at[ref, 1]) ** 2
                        + (s_at[i, 2] - s_at[ref, 2]) ** 2)
            w0 = vel_n[i, 0] - vel_n[ref, 0]
            w1 = vel_n[i, 1] - vel_n[ref, 1]
            w2 = vel_n[i, 2] - vel_n[ref, 2] - gravity * dt
            nu = np.sqrt(w0 * w0 + w1 * w1 + w2 * w2) - u
            var = (var_v[ref] + var_v[i] + (accel_bias_sd * dt) ** 2
                   + (accel_scale_sd * u) ** 2 + accel_noise_density**2 * dt + FLOOR_MPS**2)
            if nu * nu > thr * var:
                keep[i] = False
                prev = i
                continue
        anchor = i
        prev = i
    return keep
