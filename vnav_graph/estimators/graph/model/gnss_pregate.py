"""The graph smoothers' GNSS height pre-gate against the barometer (``pregate_gnss``):
a causal χ² gate that refuses GNSS heights (and vertical velocities) the baro contradicts,
before any solve. Used by ``problem.setup``."""

from __future__ import annotations

import numpy as np

from ....types import Drive
from ....types.streams import FloatArray


def pregate_gnss(drive: Drive, t: FloatArray, h: FloatArray, sd_h: FloatArray,
                  pri: dict[str, float], prob: float, vel_d: FloatArray | None = None,
                  vel_d_sd: FloatArray | None = None,
                  t_avail: FloatArray | None = None) -> np.ndarray:
    """Causal χ² gate of GNSS heights against the barometer; returns the mask of kept fixes.

    By the shared baro model, d = h_gnss(t) − h_baro(t + τ0) = −s·(h − h0) − b + noise: a
    2-state Kalman filter on x = [c, s] with d = c + s·(h_baro − h0) + v, c a random walk of
    PSD 2σ_b²/τ_b (the Gauss-Markov bias, Groves §14.2 / ``sensors.noise``), s ~ N(0, σ_s²),
    var v = σ_h,gnss² + σ_baro² + (v_up·σ_τ)². A fix whose innovation ν has ν²/S above the
    1-dof χ² quantile ``prob`` is rejected (not used to update), like the EKF's innovation
    gate; the prediction variance grows while fixes are refused, so the gate re-opens.
    When the log has GNSS velocity, a fix is also refused when −v_down disagrees with the
    baro climb rate (central difference over ±1 s): variance σ_vd² + (σ_baro/√2 /1 s)²
    + (σ_s·v)² + (0.5 m/s)² (vertical acceleration over the ±1 s difference window).

    ``t_avail`` (per fix, the time up to which data may be read for it) makes the gate causal:
    the baro at t + τ0 is read at most at ``t_avail`` and carried on by the climb rate, the
    climb rate is the backward difference over the 2 s before that epoch (its lag, ½·a·2 s,
    is inside the 0.5 m/s term for a vertical acceleration up to 0.5 m/s²), and each of the
    first ``n0`` fixes is judged against the median and MAD of the fixes up to it (the seed
    of the filter, otherwise the median of the first ``n0``).
    """
    use = np.isfinite(h) & np.isfinite(sd_h)
    baro = drive.baro
    if baro is None or prob <= 0 or baro.t.size < 2:
        return use
    from scipy.stats import chi2

    thr = float(chi2.ppf(prob, 1))
    bt, bz = baro.t, baro.altitude
    inside = use & (t + pri["tau0"] >= bt[0]) & (t + pri["tau0"] <= bt[-1])
    idx = np.flatnonzero(inside)
    if idx.size == 0:
        return use
    tt = t[idx] + pri["tau0"]
    if t_avail is None:
        hb = np.interp(tt, bt, bz)
        v_up = (np.interp(tt + 1.0, bt, bz) - np.interp(tt - 1.0, bt, bz)) / 2.0
    else:
        te = np.minimum(tt, t_avail[idx])
        v_up = (np.interp(te, bt, bz) - np.interp(te - 2.0, bt, bz)) / 2.0
        hb = np.interp(te, bt, bz) + v_up * (tt - te)
    d = h[idx] - hb
    r = sd_h[idx] ** 2 + pri["noise"] ** 2 + (v_up * pri["tau_sd"]) ** 2
    hrel = hb - drive.origin_lla[2]
    q_rate = 2.0 * pri["b_sd"] ** 2 / pri["b_tau"]
    n0 = min(10, idx.size)
    c0 = float(np.median(d[:n0]))
    mad = float(np.median(np.abs(d[:n0] - c0))) * 1.4826
    keep = np.ones(idx.size, bool)
    start = 0  # the first fix the filter below judges
    if t_avail is not None:
        # the first n0 fixes: each against the median and MAD of those up to it
        for i in range(n0):
            med = float(np.median(d[:i + 1]))
            sc = float(np.median(np.abs(d[:i + 1] - med))) * 1.4826
            keep[i] = (d[i] - med) ** 2 <= thr * (sc**2 + r[i])
        start = n0
    if vel_d is not None and vel_d_sd is not None:
        var_v = (vel_d_sd[idx] ** 2 + 0.5 * pri["noise"] ** 2 + (pri["s_sd"] * v_up) ** 2
                 + 0.5**2)
        nu_v = -vel_d[idx] - v_up
        keep &= ~(nu_v**2 > thr * var_v) & np.isfinite(nu_v)
    # the filter in Python floats (x = [c, s], P = [[p00, p01], [p01, p11]]): numpy's
    # 2-vector operations cost ~7 µs per fix (0.12 s on a 30-min drive of 10 Hz fixes)
    c, s = c0, 0.0
    p00, p01, p11 = mad**2 + float(np.median(r[:n0])), 0.0, float(pri["s_sd"]) ** 2
    q_dt = (q_rate * np.maximum(np.diff(tt, prepend=tt[0]), 0.0)).tolist()
    kept = keep.tolist()
    for i, (di, hh, ri) in enumerate(zip(d.tolist(), hrel.tolist(), r.tolist(), strict=True)):
        p00 += q_dt[i]
        if not kept[i] or i < start:
            continue
        nu = di - (c + hh * s)
        ph0, ph1 = p00 + p01 * hh, p01 + p11 * hh
        s_inn = ph0 + hh * ph1 + ri
        if nu * nu > thr * s_inn:
            kept[i] = False
            continue
        k0, k1 = ph0 / s_inn, ph1 / s_inn
        c, s = c + k0 * nu, s + k1 * nu
        p00, p01, p11 = p00 - k0 * ph0, p01 - k0 * ph1, p11 - k1 * ph1
    use[idx[~np.asarray(kept, dtype=bool)]] = False
    return use
