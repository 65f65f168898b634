"""The filter's measurement rows: one compiled function per sensor, each returning the
innovation ``y = h(x̃) − z`` (6,), the Jacobian rows ``H`` (6, NX) and the noise variances
``r`` (6,) of the measurement at an event, and how many rows it uses.

The nominal state at the event (``lm``, ``vm``, ``cm`` = C_nb and the radii ``rn``, ``re``) is
interpolated by ``kernel.run_filter``; the rows follow the shared sensor models
(``sensors.gnss_model``, ``sensors.baro.baro_predict`` / ``baro_row``,
``sensors.magnetometer.mag_heading_row``). Adding a sensor to the filter means a row function
here, an event kind in ``kernel`` and its gated update in ``steps``.
"""

from __future__ import annotations

import numpy as np
from numba import njit

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
