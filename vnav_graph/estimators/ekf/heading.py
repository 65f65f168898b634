"""Heading acquisition of the forward EKF (docs/ekf.md describes the method):
acceleration matching against GNSS velocity changes, the GNSS course when moving, or the
magnetometer (``updates.mag_rows``). Each proposes a yaw reset (``RESET_DELTA`` ± ``RESET_SD``)
that ``steps.heading_reset`` applies at the next grid epoch.

The acquisition state is one float array (``new_state``; layout below) and four (2,)
vectors (specific-force integral since the last velocity fix ``sf_acc``, this IMU step's
``s_i``, the current chunk's ``ch_u`` / ``ch_w``), so that the compiled loop carries it
without a dozen loose scalars.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from ...nav.arrays import put
from ...nav.rotations import yaw_of

# layout of the acquisition state
# (RESET_COURSE: 1 when the proposed reset is the GNSS course's)
(CH_T, AL_DOT, AL_CROSS, AL_UU, AL_N, PREV_VFIX, PEND_TV, RESET_DELTA, RESET_SD,
 RESET_COURSE) = range(10)
N_STATE = 10


@njit(cache=True)
def new_state():
    """No chunk, no sums, no previous velocity fix, no proposed reset."""
    s = np.zeros(N_STATE)
    s[PREV_VFIX] = -1.0
    s[RESET_DELTA] = np.nan
    return s


@njit(cache=True)
def restart_matching(acq, sf_acc, s_i, ch_u, ch_w):
    """After an IMU gap: no specific force over it, so matching starts again (the sums
    already gathered are kept)."""
    s_i[:] = 0.0
    sf_acc[:] = 0.0
    ch_u[:] = 0.0
    ch_w[:] = 0.0
    acq[CH_T] = 0.0
    acq[PREV_VFIX] = -1.0


@njit(cache=True)
def match_acceleration(acq, sf_acc, s_i, ch_u, ch_w, al, tm, idx, vel, vel_sd, chunk_s,
                       forget_s, sd_max, acc_sd):
    """One GNSS velocity fix of acceleration matching, W = R_z(δ) U per chunk of at least
    ``chunk_s``: U the specific-force integral in the nominal frame, W the GNSS velocity
    change; a reset is proposed once three chunks give σ(δ) ≤ ``sd_max``. ``al`` is the
    fix's fraction of the current IMU step."""
    u_part = sf_acc - (1.0 - al) * s_i
    put(sf_acc, (1.0 - al) * s_i)
    prev = int(acq[PREV_VFIX])
    if prev >= 0:
        dtf = tm - acq[PEND_TV]
        ch_u += u_part
        for a in range(2):
            ch_w[a] += vel[idx, a] - vel[prev, a]
        acq[CH_T] += dtf
        ch_t = acq[CH_T]
        if ch_t >= chunk_s:
            sv2 = 0.5 * (vel_sd[idx, 0] ** 2 + vel_sd[idx, 1] ** 2
                         + vel_sd[prev, 0] ** 2 + vel_sd[prev, 1] ** 2)
            var = sv2 + (acc_sd * ch_t) ** 2
            uu = ch_u[0] ** 2 + ch_u[1] ** 2
            ww = ch_w[0] ** 2 + ch_w[1] ** 2
            # rotation keeps the norm: a chunk whose |W| and |U| disagree by > 4σ is a GNSS
            # velocity fault, not information
            if abs(np.sqrt(ww) - np.sqrt(uu)) <= 4.0 * np.sqrt(var):
                fg = np.exp(-ch_t / forget_s)
                acq[AL_DOT] = fg * acq[AL_DOT] + (ch_u[0] * ch_w[0] + ch_u[1] * ch_w[1]) / var
                acq[AL_CROSS] = fg * acq[AL_CROSS] + (ch_u[0] * ch_w[1]
                                                      - ch_u[1] * ch_w[0]) / var
                acq[AL_UU] = fg * acq[AL_UU] + uu / var
                acq[AL_N] += 1.0
            ch_u[:] = 0.0
            ch_w[:] = 0.0
            acq[CH_T] = 0.0
            sd_al = 1.0 / np.sqrt(max(acq[AL_UU], 1e-12))
            if acq[AL_N] >= 3 and sd_al <= sd_max and np.isnan(acq[RESET_DELTA]):
                acq[RESET_DELTA] = np.arctan2(acq[AL_CROSS], acq[AL_DOT])
                acq[RESET_SD] = 2.0 * sd_al
    acq[PREV_VFIX] = idx
    acq[PEND_TV] = tm


@njit(cache=True)
def track_heading(acq, speed, course, course_sd, q, v_min, sd_max):
    """The GNSS course as the heading, when moving faster than ``v_min`` and its σ as a
    heading is at most ``sd_max``."""
    if speed > v_min and course_sd <= sd_max and np.isnan(acq[RESET_DELTA]):
        dlt = course - yaw_of(q)
        acq[RESET_DELTA] = np.arctan2(np.sin(dlt), np.cos(dlt))
        acq[RESET_SD] = course_sd


@njit(cache=True)
def confirmed_course(acq, speed, course, course_sd, q, v_min, sd_max, confirm_sd):
    """The GNSS course as the heading while acceleration matching runs (``heading_source``
    "auto" with GNSS velocity): proposed when ``track_heading`` would take it and the
    matching's running estimate δ̂ (at least one chunk, σ_δ ≤ ``confirm_sd``) agrees with it
    within 3 σ of both, so that a body that does not move along its x axis (a sideways
    mount, a multicopter, a hand-held device turned against its path) keeps the matching's
    heading."""
    if not (speed > v_min and course_sd <= sd_max and np.isnan(acq[RESET_DELTA])
            and acq[AL_N] >= 1.0):
        return
    sd_al = 1.0 / np.sqrt(max(acq[AL_UU], 1e-12))
    if sd_al > confirm_sd:
        return
    dlt = course - yaw_of(q)
    dlt = np.arctan2(np.sin(dlt), np.cos(dlt))
    d_al = np.arctan2(acq[AL_CROSS], acq[AL_DOT])
    dd = dlt - d_al
    dd = np.arctan2(np.sin(dd), np.cos(dd))
    if abs(dd) <= 3.0 * np.sqrt(course_sd**2 + sd_al**2):
        acq[RESET_DELTA] = dlt
        acq[RESET_SD] = course_sd
        acq[RESET_COURSE] = 1.0
