"""The GNSS reference of the vertical estimators' AHRS (docs/vertical_loops.md §1, steps 3-5).

``gnss_reference`` gives the reference velocity at each fix, from the receiver or, without
one, from the positions (``velocity_from_positions``: a weighted quadratic fit over a
window), with its σ and whether its vertical component agrees with the baro climb rate
(``baro_rate``, rule R5). ``matching_inputs`` thins the fixes to the velocity-matching
interval and assembles everything the AHRS kernel reads from the GNSS (``Matching``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ...geo.earth import OMEGA_IE, gravity, radii
from ...types import Drive
from ...types.streams import FloatArray
from .ahrs import poly_velocity, trailing_slope

# the receiver's nominal fix interval (and usual velocity σ) is taken from its first this
# many fixes: a rate the system knows from the start, not a whole-drive statistic
NOMINAL_FIXES = 20


def nominal_interval(t: FloatArray) -> float:
    """Nominal interval [s] of the increasing stamps ``t``: the median of the first
    ``NOMINAL_FIXES`` intervals (1 s with fewer than two stamps)."""
    d = np.diff(np.asarray(t, float)[:NOMINAL_FIXES + 1])
    return float(np.median(d)) if d.size else 1.0


def thin(t: FloatArray, min_dt: float) -> FloatArray:
    """Indices of a greedy subset of the increasing times ``t`` spaced at least ``min_dt``
    (within 1 % to tolerate stamp jitter)."""
    keep = [0]
    for i in range(1, t.size):
        if t[i] - t[keep[-1]] >= 0.99 * min_dt:
            keep.append(i)
    return np.asarray(keep, dtype=np.int64)


def ned_offsets(lla: FloatArray) -> FloatArray:
    """Local NED metres of (lat, lon, h) rows about the first row (radii at each row)."""
    rn, re = radii(lla[:, 0])
    return np.column_stack([
        (lla[:, 0] - lla[0, 0]) * (rn + lla[:, 2]),
        (lla[:, 1] - lla[0, 1]) * (re + lla[:, 2]) * np.cos(lla[:, 0]),
        -(lla[:, 2] - lla[0, 2]),
    ])


def velocity_from_positions(t: FloatArray, lla: FloatArray, pos_sd: FloatArray,
                            window_s: float, gap_s: float) -> tuple[FloatArray, FloatArray]:
    """Reference velocity from GNSS positions alone (docs/vertical_loops.md §1, step 3b).

    Parameters
    ----------
    t : (M,) fix times [s]; lla : (M, 3) (lat rad, lon rad, h m); pos_sd : (M, 3) NED σ [m]
    window_s : fit window [s] (centred where the segment allows: the velocity at t_j is
        known at t_j + window_s/2, which is when the AHRS uses it)
    gap_s : a fix spacing above this starts a new segment (no fit across outages)

    Returns
    -------
    v : (M, 3) NED velocity [m/s], the slope at t_j of p(τ) = a + b τ + c τ² fitted with
        weights 1/σ² to the fixes of the same segment with |t_i − t_j| ≤ window_s/2 (NaN with
        fewer than 3 fixes); exact for a quadratic trajectory; a cubic term c3·τ³ biases it by
        c3·Στ⁴/Στ² (≈ 3c3W²/20 in a symmetric window of length W)
    sd : (M, 3) its σ [m/s], √[(XᵀWX)⁻¹]₁₁ (uncorrelated fix errors assumed); for N equally
        spaced fixes spanning W, ≈ σ_p·√(12/N)/W
    """
    seg = np.concatenate([[0], np.cumsum(np.diff(t) > gap_s)]).astype(np.int64)
    sd = np.where(np.isfinite(pos_sd) & (pos_sd > 0), pos_sd, 1e6)
    return poly_velocity(np.ascontiguousarray(t, dtype=float), ned_offsets(lla),
                          np.ascontiguousarray(sd, dtype=float), 0.5 * window_s, seg)


def baro_rate(t_q: FloatArray, t_b: FloatArray, alt_b: FloatArray,
              window_s: float = 2.0) -> tuple[FloatArray, FloatArray]:
    """Climb rate of the baro altitude at times ``t_q`` from the samples up to each of them:
    the slope at t_q of a quadratic fitted over the trailing [t_q − window_s, t_q] (at
    least 5 samples spanning half the window; exact for a constant vertical acceleration,
    no look-ahead), with its σ from that fit's own residual σ (floor 0.02 m). Returns
    (rate (Q,) [m/s, +up], σ (Q,)); NaN/inf where the window is too thin."""
    return trailing_slope(np.ascontiguousarray(t_q, dtype=float),
                          np.ascontiguousarray(t_b, dtype=float),
                          np.ascontiguousarray(alt_b, dtype=float), float(window_s), 0.02)


def gnss_reference(drive: Drive, cfg: Any) -> tuple:
    """Reference velocities, their σ and the vertical-trust flags at the fixes (``cfg``: the
    ``AhrsConfig``)."""
    gn = drive.gnss
    t_g, lla_g = gn.t, gn.lla
    dt_nom = nominal_interval(t_g)
    if gn.vel_n is not None:
        source = "receiver"
        v_g = np.asarray(gn.vel_n, float)
        if gn.vel_sd is not None:
            sd_v = np.where(np.isfinite(gn.vel_sd), gn.vel_sd, np.inf)
        else:
            sd_v = np.full((t_g.size, 3), cfg.sd_v_default)
        window = 0.0
    else:
        source = "positions"
        window = max(cfg.pos_vel_window_s, (cfg.pos_vel_min_fixes - 1) * dt_nom)
        v_g, sd_v = velocity_from_positions(t_g, lla_g, gn.pos_sd, window,
                                            cfg.gap_factor * dt_nom)
    sd_h = np.max(sd_v[:, :2], axis=1)
    use = np.isfinite(v_g).all(axis=1) & (sd_h <= cfg.sd_v_max)
    v_g = np.where(np.isfinite(v_g), v_g, 0.0)
    # R5: vertical component of the reference trusted only from a receiver velocity that
    # agrees with the baro climb rate (3σ + 0.3 m/s + 10 % for baro scale/latency)
    if source == "positions" and not cfg.pos_vel_vertical:
        vert = np.zeros(t_g.size, dtype=bool)
    elif cfg.baro_check and drive.baro is not None and len(drive.baro) > 5:
        rate, sd_r = baro_rate(t_g, drive.baro.t, drive.baro.altitude)
        tol = 3.0 * np.sqrt(sd_v[:, 2] ** 2 + sd_r**2) + 0.3 + 0.1 * np.abs(rate)
        vert = np.abs(-v_g[:, 2] - rate) <= tol  # NaN rate (no baro there) -> False
    else:
        vert = np.ones(t_g.size, dtype=bool)
    return source, dt_nom, v_g, sd_v, sd_h, use, vert, window


@dataclass(frozen=True)
class Matching:
    """What the AHRS kernel needs from the GNSS (docs/vertical_loops.md §1, steps
    3-5): at the thinned fixes ``t_g`` the reference velocity ``v_g``, the time ``t_av`` it
    is known (``t_g``, or half the fit window later for position-derived velocities), gravity
    ``g_g``, the
    Coriolis and transport term ``cor_g``, the interval flags ``ok`` (not across an outage),
    ``vert_iv`` (vertical component trusted) and ``use`` (velocity usable), the residual
    variance ``r_g``; at the IMU epochs the position ``lla_i``, velocity ``vel_i`` and
    horizontal velocity σ ``sdv_i`` of the last fix at or before the epoch (no velocity and
    σ = inf once ``gap_factor`` nominal intervals have passed without a fix); the usual σ
    ``sd_med``, the matching interval ``match`` [s] and the nominal residual variance
    ``r_nom``. Without GNSS the fix arrays are empty and the position is the origin."""

    t_g: FloatArray
    t_av: FloatArray
    v_g: FloatArray
    g_g: FloatArray
    cor_g: FloatArray
    ok: Any
    r_g: FloatArray
    vert_iv: Any
    use: Any
    lla_i: FloatArray
    vel_i: FloatArray
    sdv_i: FloatArray
    sd_med: float
    match: float
    r_nom: float


def matching_inputs(drive: Drive, cfg: Any, t: FloatArray, info: dict) -> Matching:
    """The kernel's GNSS inputs (``Matching``) for the IMU epochs ``t`` with the AHRS settings
    ``cfg`` (``AhrsConfig``); the velocity source and fit window go into ``info``."""
    n = t.size
    gn = drive.gnss
    if gn is not None and gn.t.size >= 3:
        source, dt_nom, v_g, sd_v, sd_h, use, vert, window = gnss_reference(drive, cfg)
        info["velocity_source"] = source
        if window:
            info["position_velocity_window_s"] = window
        t_g, lla_g = gn.t, gn.lla
        ok = np.concatenate([[False], np.diff(t_g) <= cfg.gap_factor * dt_nom])
        # when each fix's velocity is known: at the fix for a receiver's, half a window
        # later for the centred position fit (step 3b)
        t_av = t_g + 0.5 * window
        # at each IMU epoch the last fix at or before it and the last velocity known by
        # then, held (no interpolation toward the next fix); an outage is decided from the
        # time elapsed since the last fix: more than gap_factor nominal intervals ago, no
        # velocity (no course, no Coriolis from it)
        last = np.searchsorted(t_g, t, side="right") - 1
        have = last >= 0
        li = np.maximum(last, 0)
        lla_i = np.where(have[:, None], lla_g[li], np.asarray(drive.origin_lla, float)[None, :])
        lastv = np.searchsorted(t_av, t, side="right") - 1
        have_v = lastv >= 0
        lv = np.maximum(lastv, 0)
        vel_i = np.where(have_v[:, None], v_g[lv], 0.0)
        sdv_i = np.where(have_v & use[lv], sd_h[lv], 1e9)
        in_gap = ~have_v | (t - t_g[li] > cfg.gap_factor * dt_nom)
        vel_i[in_gap, :2] = 0.0
        sdv_i[in_gap] = np.inf
        # velocity matching over intervals of at least match_interval_s (fewer, longer Δv);
        # with position-derived velocities at least half the fit window
        match = cfg.match_interval_s if source == "receiver" else max(
            cfg.match_interval_s, 0.5 * window)
        keep = thin(t_g, match)
        t_g, t_av, lla_g, v_g = t_g[keep], t_av[keep], lla_g[keep], v_g[keep]
        sd_h, use, vert = sd_h[keep], use[keep], vert[keep]
        ok = np.concatenate(
            [[False], np.diff(t_g) <= cfg.gap_factor * max(dt_nom, match)])
        vert_iv = np.concatenate([[False], vert[1:] & vert[:-1]])
        dtg = np.concatenate([[np.inf], np.diff(t_g)])
        with np.errstate(invalid="ignore"):
            r_g = (sd_h**2 + np.concatenate([[np.inf], sd_h[:-1] ** 2])) / dtg**2
        r_g = np.where(np.isfinite(r_g), r_g, 1e12)
        r_nom = 2.0 * cfg.sd_v_nominal**2 / match**2
        g_g = gravity(lla_g[:, 0], lla_g[:, 2])
        w_ie = np.column_stack([OMEGA_IE * np.cos(lla_g[:, 0]), np.zeros(t_g.size),
                                -OMEGA_IE * np.sin(lla_g[:, 0])])
        rn, re = radii(lla_g[:, 0])
        w_en = np.column_stack([v_g[:, 1] / (re + lla_g[:, 2]), -v_g[:, 0] / (rn + lla_g[:, 2]),
                                -v_g[:, 1] * np.tan(lla_g[:, 0]) / (re + lla_g[:, 2])])
        cor_g = np.cross(2 * w_ie + w_en, v_g)
        # the receiver's usual velocity σ, from its first usable fixes (causal, like dt_nom)
        sd_med = float(np.median(sd_h[use][:NOMINAL_FIXES])) if np.any(use) \
            else cfg.sd_v_default
    else:
        t_g = np.empty(0)
        t_av = np.empty(0)
        v_g = np.zeros((0, 3))
        g_g = np.empty(0)
        cor_g = np.zeros((0, 3))
        ok = np.zeros(0, dtype=bool)
        r_g = np.empty(0)
        vert_iv = np.zeros(0, dtype=bool)
        use = np.zeros(0, dtype=bool)
        lla_i = np.tile(drive.origin_lla, (n, 1))
        vel_i = np.zeros((n, 3))
        sdv_i = np.full(n, np.inf)
        sd_med = 0.0
        match = cfg.match_interval_s
        r_nom = 1.0
    return Matching(t_g, t_av, v_g, g_g, cor_g, ok, r_g, vert_iv, use, lla_i, vel_i, sdv_i,
                    sd_med, match, r_nom)
