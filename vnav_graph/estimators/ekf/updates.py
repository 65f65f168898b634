"""The filter's measurement updates, one pair of compiled functions per measurement model.

A row function returns the innovation ``y = h(x̃) − z`` (6,), the Jacobian rows ``H``
(6, NX) and the noise variances ``r`` (6,) of the measurement at an event, and how many rows
it uses; its update applies those rows, mapped to the grid epoch (``steps.delayed_rows``),
behind the measurement's gate.

The nominal state at the event (``lm``, ``vm``, ``cm`` = C_nb and the radii ``rn``, ``re``) is
interpolated by ``kernel.run_filter``; the rows follow the shared sensor models
(``sensors.gnss_model``, ``sensors.baro.baro_predict`` / ``baro_row``,
``sensors.magnetometer.mag_heading_row``), which give the prediction and its Jacobian in
physical errors; the row functions place them into the filter's columns (``model``'s
``I*`` indices). Adding a sensor to the filter means its row function and update here, and
its event kind in ``kernel.run_filter`` and ``inputs.events``.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ...nav.arrays import put
from ...nav.gnss_gate import REFUSE, USE_INFLATE, height_gate
from ...nav.strapdown import nav_rates
from ...sensors.baro import baro_predict, baro_row
from ...sensors.gnss_model import antenna_position, antenna_velocity
from ...sensors.magnetometer import MIN_HORIZONTAL_UT, mag_heading_row
from .heading import RESET_DELTA, RESET_SD
from .model import (
    IATT,
    IBB,
    IBG,
    IGE,
    IMB,
    IPOS,
    ISC,
    ITD,
    IVEL,
    NX,
    PBB,
    PMB,
    PSC,
    PTD,
    consider_update,
    huber_weight,
    scalar_update,
    vector_update,
)

# event kinds of ``kernel.Events.kind``
GNSS, BARO, MAG, ZUPT = 0, 1, 2, 3


@njit(cache=True)
def gnss_rows(lm, vm, cm, rn, re, ge, lever, lla_g, pos_sd, vel_g, vel_sd, has_vel,
              heading_ok, w0, w1):
    """GNSS antenna position (rows 0-2, NED metres) and, with ``has_vel``, velocity (3-5):
    r + C l + e and v + C (ω_nb × l), the shared model ``sensors.gnss_model``; ``ge`` (3,)
    is the GNSS error state (zero, of zero variance, on the axes not carried).
    While the heading is unknown the yaw column is zeroed and the lever arm's length is
    added to the position variance."""
    d, h_att = antenna_position(cm, lever)
    y = np.zeros(6)
    hm = np.zeros((6, NX))
    r = np.zeros(6)
    # the fix's NED offset from the nominal IMU position (north, east, down)
    y[0] = -(lla_g[0] - lm[0]) * (rn + lm[2]) + d[0] + ge[0]
    y[1] = -(lla_g[1] - lm[1]) * (re + lm[2]) * np.cos(lm[0]) + d[1] + ge[1]
    y[2] = (lla_g[2] - lm[2]) + d[2] + ge[2]
    lev2 = 0.0 if heading_ok else lever @ lever
    for a in range(3):
        hm[a, IPOS + a] = 1.0
        for b in range(3):
            hm[a, IATT + b] = h_att[a, b]
        hm[a, IGE + a] = 1.0
        r[a] = pos_sd[a] ** 2 + lev2
    mm = 3
    if has_vel:
        w_ie, w_en = nav_rates(lm[0], lm[2], vm)
        # (w_ie + w_en) @ cm is cm.T @ (...) and cross3 np.cross: the same numbers without
        # two more compiled specialisations (~4 s of a first run)
        wnb = 0.5 * (w0 + w1) - (w_ie + w_en) @ cm
        u, hv_att, hv_bg = antenna_velocity(cm, lever, wnb)
        for a in range(3):
            y[3 + a] = vm[a] + u[a] - vel_g[a]
            hm[3 + a, IVEL + a] = 1.0
            for b in range(3):
                hm[3 + a, IATT + b] = hv_att[a, b]
                hm[3 + a, IBG + b] = hv_bg[a, b]
            r[3 + a] = vel_sd[a] ** 2
        mm = 6
    if not heading_ok:
        for a in range(6):
            hm[a, IATT + 2] = 0.0
    return y, hm, r, mm


@njit(cache=True)
def baro_rows(lm, vm, par, h0, alt, sd):
    """Baro altitude (row 0): h0 + (1+s)(h − h0 − v_up τ) + b (docs/design.md's model)."""
    hb = lm[2]
    vup = -vm[2]
    y = np.zeros(6)
    hm = np.zeros((6, NX))
    r = np.zeros(6)
    y[0] = baro_predict(hb, vup, par[PSC], par[PTD], par[PBB], h0) - alt
    jb = baro_row(hb, vup, par[PSC], par[PTD], h0)
    hm[0, IPOS + 2] = -jb[0]
    hm[0, IVEL + 2] = -jb[1]
    hm[0, ISC] = jb[2]
    hm[0, ITD] = jb[3]
    hm[0, IBB] = jb[4]
    r[0] = sd * sd
    return y, hm, r, 1


@njit(cache=True)
def mag_rows(field, par, cm, decl, sd_ut, floor_var, heading_ok, p, acq):
    """Magnetometer heading (row 0): azimuth of the bias-corrected field in n minus the
    declination. With an unknown heading it proposes a heading reset instead (``acq``'s
    ``RESET_DELTA`` / ``RESET_SD``, see ``heading``), with the σ of the acquired heading from
    the noise, the hard-iron prior and the tilt; no rows then (0)."""
    y = np.zeros(6)
    hm = np.zeros((6, NX))
    r = np.zeros(6)
    mm = 0
    res_m, h_psi, h_bias, hor = mag_heading_row(field, par[PMB:PMB + 3].copy(), cm, decl)
    if hor >= MIN_HORIZONTAL_UT:
        r[0] = (sd_ut / hor) ** 2 + floor_var
        if heading_ok:
            y[0] = res_m
            for a in range(3):
                hm[0, IATT + a] = h_psi[a]
                hm[0, IMB + a] = h_bias[a]
            mm = 1
        elif np.isnan(acq[RESET_DELTA]):
            var = r[0]
            for a in range(3):
                var += h_bias[a] ** 2 * p[IMB + a, IMB + a]
            for a in range(2):
                for b in range(2):
                    var += h_psi[a] * p[IATT + a, IATT + b] * h_psi[b]
            acq[RESET_DELTA] = -res_m
            acq[RESET_SD] = np.sqrt(var)
    return y, hm, r, mm


@njit(cache=True)
def zupt_rows(vm, sd):
    """Zero velocity (rows 0-2): the IMU's velocity in n against 0, each of σ ``sd`` [m/s]
    (``nav.standstill``: a detected standstill)."""
    y = np.zeros(6)
    hm = np.zeros((6, NX))
    r = np.zeros(6)
    for a in range(3):
        y[a] = vm[a]
        hm[a, IVEL + a] = 1.0
        r[a] = sd * sd
    return y, hm, r, 3


# the gates' refusal counters (an int array carried by the loop)
C_POS, C_BARO, C_MAG = 0, 1, 2
# ``tilt_held``: the attitude is held as a consider state only while the heading is unknown
# and the tilt σ exceeds this (a levelling in motion leaves 15–20°, far outside the linear
# regime; a static levelling leaves < 1°, and holding that tilt for a whole drive whose
# heading never becomes known cost ekf-rts 0.33 → 0.72 m altitude RMSE on seed003)
TILT_HELD_VAR = np.radians(5.0) ** 2


@njit(cache=True)
def tilt_held(p, settings, heading_ok):
    """Whether the GNSS and baro updates hold the attitude as Schmidt consider states
    (``EkfConfig.tilt_consider``; ``model`` docstring, "Heading before it is known")."""
    if not settings.tilt_consider or heading_ok:
        return False
    return max(p[IATT, IATT], p[IATT + 1, IATT + 1]) > TILT_HELD_VAR


@njit(cache=True)
def update_gnss(p, dx, heff, y, r, mm, idx, te, k, settings, sd_v, has_baro, b_prior_var,
                v_gate, counts, rts_q, inn_pos, inn_vel, rej_pos, rej_vel, rej_v, heading_ok,
                forced_pos):
    """A GNSS fix: the horizontal position pair (χ²₂ gate; after ``max_consec`` refusals a
    jump of the observed size is added to P and forced in, flagged in ``forced_pos``), the
    height through the fault
    detection of ``nav.gnss_gate.height_gate``, then the velocity (pair, then down, which
    follows the height's verdict). Huber re-weighting per ``settings.huber_*`` (pair, height
    and vertical velocity each on its own NIS). While the heading is unknown the horizontal
    pairs hold the attitude as consider states while its tilt σ is large (``tilt_held``)."""
    no_force = mm < 0  # False as a typed bool: a literal compiles vector_update again
    c0 = IATT if tilt_held(p, settings, heading_ok) else 0
    c1 = IATT + 3 if c0 > 0 else 0
    force_h = counts[C_POS] >= settings.max_consec
    forced_pos[idx] = force_h
    if force_h:
        for a in range(2):
            nu_a = y[a] - heff[a] @ dx
            p[IPOS + a, IPOS + a] += nu_a * nu_a
            if settings.store_rts:
                rts_q[k, IPOS + a] += nu_a * nu_a
    ok, nis, nrm, w = vector_update(p, dx, heff[:2].copy(), y[:2].copy(), r[:2].copy(),
                                    settings.gate_pos, force_h, settings.huber_pos, c0, c1)
    put(inn_pos[idx, :2], nrm)
    rej_pos[idx] = not ok
    counts[C_POS] = 0 if nis <= settings.gate_pos else counts[C_POS] + 1
    hv = heff[2].copy()
    rv = r[2]
    nu_v = y[2] - hv @ dx
    s_v = hv @ p @ hv + rv
    inn_pos[idx, 2] = -nu_v / np.sqrt(s_v)
    usable = sd_v <= settings.max_sd_v
    code = height_gate(v_gate, te, usable, nu_v * nu_v, s_v, settings.gate_v,
                       settings.probation_s, settings.max_consec, b_prior_var, not has_baro)
    use_v = code != REFUSE
    if use_v:
        if code == USE_INFLATE:
            p[IBB, IBB] += b_prior_var
        w = huber_weight(np.sqrt(nu_v * nu_v / s_v), settings.huber_pos)
        if c1 > c0:
            consider_update(p, dx, hv, y[2], rv if w >= 1.0 else rv / w, c0, c1)
        else:
            scalar_update(p, dx, hv, y[2], rv if w >= 1.0 else rv / w)
    else:
        rej_v[idx] = True
        rej_pos[idx] = True
    if mm == 6:
        ok, nis, nrm, w = vector_update(p, dx, heff[3:5].copy(), y[3:5].copy(),
                                        r[3:5].copy(), settings.gate_vel, no_force,
                                        settings.huber_vel, c0, c1)
        put(inn_vel[idx, :2], nrm)
        rej_vel[idx] = not ok
        if use_v:
            ok, nis, nrm, w = vector_update(p, dx, heff[5:6].copy(), y[5:6].copy(),
                                            r[5:6].copy(), settings.gate_v, no_force,
                                            settings.huber_vel, c0, c1)
            inn_vel[idx, 2] = nrm[0]
            rej_vel[idx] = rej_vel[idx] or not ok
        else:
            rej_vel[idx] = True


@njit(cache=True)
def update_gated(p, dx, heff, y, r, gate, max_consec, counts, c, inn, rej, idx, huber_k,
                 hold_tilt):
    """A one-row measurement (baro, magnetometer heading) behind a χ²₁ gate, forced in after
    ``max_consec`` refusals in a row (counter ``counts[c]``); Huber re-weighting with
    threshold ``huber_k`` (0: none); ``hold_tilt``: the attitude as consider states."""
    c0 = IATT if hold_tilt else 0
    c1 = IATT + 3 if hold_tilt else 0
    ok, nis, nrm, w = vector_update(p, dx, heff[:1].copy(), y[:1].copy(), r[:1].copy(), gate,
                                    counts[c] >= max_consec, huber_k, c0, c1)
    inn[idx] = nrm[0]
    rej[idx] = not ok
    counts[c] = 0 if nis <= gate else counts[c] + 1


@njit(cache=True)
def update_zupt(p, dx, heff, y, r, gate, inn, rej, idx):
    """A zero-velocity pseudo-measurement (``rows.zupt_rows``) behind a χ²₃ gate, never
    forced: a standstill the filter's velocity contradicts is refused (``rej``)."""
    no_force = gate < 0.0  # False as a typed bool: a literal compiles vector_update again
    ok, nis, nrm, w = vector_update(p, dx, heff[:3].copy(), y[:3].copy(), r[:3].copy(), gate,
                                    no_force, 0.0, 0, 0)
    put(inn[idx], nrm)
    rej[idx] = not ok
