"""The forward EKF kernel: one compiled pass over the whole drive (``run_filter``).

The error-state model is in ``ekf.model`` (the filter: docs/ekf.md), all
that is per measurement kind (records, rows, gated updates, innovations) in ``ekf.updates``,
the heading acquisition in ``ekf.heading`` and the prediction, heading reset and delayed-row
mapping in ``ekf.steps``; this module holds only the loop that strings them together. It
does not branch on the measurement kind, except for the heading acquisition from a GNSS fix:
an event's rows and update are ``updates.event_rows`` / ``updates.event_update``.

Its inputs are typed records (``NamedTuple``s of arrays and scalars, which numba passes as
tuples: a field read is resolved at compile time and costs nothing): :class:`Grids`,
:class:`Initial`, :class:`Noise`, :class:`Events`, ``updates.Measurements`` (one record per
kind) and :class:`Settings`, built by ``ekf.filter``, and ``updates.Innovations``, which it
fills in place. Every field keeps one numba type (float64 arrays, C-contiguous; int64 counts;
float scalars; bools) so that the kernel compiles once.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
from numba import njit

from ...geo.earth import radii_scalar
from ...nav.arrays import put
from ...nav.rotations import quat_to_dcm, rpy_quat, yaw_of
from ...nav.strapdown import strapdown_step
from ...types.streams import BoolArray, FloatArray, IntArray
from .heading import (
    RESET_COURSE,
    RESET_DELTA,
    RESET_SD,
    confirmed_course,
    match_acceleration,
    new_state,
    restart_matching,
    track_heading,
)
from .model import NING, NPACK, NPAR, NX, PBA, PBG, PKA, apply_correction, pack
from .steps import delayed_rows, grid_predict, heading_reset
from .updates import GNSS, event_rows, event_update


class Grids(NamedTuple):
    """The IMU samples (N) and where each lands: covariance grid, outputs, gaps."""

    t: FloatArray  # (N,) IMU stamps [s]
    gyro: FloatArray  # (N, 3) angular rate in b [rad/s]
    accel: FloatArray  # (N, 3) specific force in b [m/s²]
    grid_of: IntArray  # (N,) grid epoch of IMU sample i, −1 if none
    out_of: IntArray  # (N,) output-trajectory slot of IMU sample i, −1 if none
    n_grid: int  # number of grid epochs K
    n_out: int  # number of output-trajectory epochs
    cov_out_of: IntArray  # (K,) covariance-output slot of grid epoch k, −1 if none
    n_cov_out: int  # number of covariance-output epochs
    gap_step: BoolArray  # (N−1,) IMU interval i → i+1 is a gap (a grid interval of its own)
    gap_rp: FloatArray  # (N, 2) roll, pitch re-levelled at a gap's end sample [rad], else NaN


class Initial(NamedTuple):
    """The state at the first IMU sample (alignment)."""

    lla0: FloatArray  # (3,) latitude, longitude [rad], height [m]
    v0: FloatArray  # (3,) velocity in n [m/s]
    q0: FloatArray  # (4,) attitude q_nb
    par0: FloatArray  # (NPAR,) biases, baro, accel scale, mag hard iron (ekf.model P*)
    p0: FloatArray  # (NX, NX) error covariance
    heading_known: bool  # the heading is given (else acquired in flight)


class Noise(NamedTuple):
    """Process noise and Gauss-Markov time constants."""

    q_diag: FloatArray  # (K, NX) discrete process-noise variances per grid interval
    tau_g: float  # gyro bias correlation time [s]
    tau_a: float  # accel bias correlation time [s]
    tau_b: float  # baro bias correlation time [s]
    tau_h: float  # GNSS height error correlation time [s] (inf: the state is off)
    yaw_unknown_var: float  # yaw variance while the heading is unknown [rad²]
    tilt_rate_sd: float  # tilt growth while the heading is unknown [rad/s]
    b_prior_var: float  # baro-bias prior variance [m²] (GNSS-height gate widening)


class Events(NamedTuple):
    """The measurement events of every kind merged and sorted by time (``inputs.events``)."""

    t: FloatArray  # (E,) event stamps [s]
    kind: IntArray  # (E,) event kind (``updates.GNSS`` ...: a field of ``updates.Measurements``)
    idx: IntArray  # (E,) row of the kind's record (``updates.measurements``)
    max_pending: int  # most events inside one grid interval, + 1


class Settings(NamedTuple):
    """Gates, re-acceptance and heading-acquisition settings (``EkfConfig``)."""

    gate_pos: float  # χ²₂ gate of the horizontal position pair
    gate_vel: float  # χ²₂ gate of the horizontal velocity pair
    gate_v: float  # χ²₁ gate of the GNSS height and vertical velocity
    max_consec: int  # refusals after which a horizontal pair is forced in
    max_sd_v: float  # GNSS heights with a larger σ are not used [m]
    probation_s: float  # GNSS-height probation [s]
    heading_v_min: float  # speed above which the track gives the heading [m/s]
    heading_accel: bool  # acquire the heading by acceleration matching
    heading_course: bool  # and by the GNSS course it confirms (heading.confirmed_course)
    course_confirm_sd: float  # σ of the matching that can confirm a course [rad]
    align_chunk_s: float
    align_forget_s: float
    align_sd_max: float  # [rad]
    align_acc_sd: float  # specific-force error of a chunk [m/s²]
    gap_forget_s: float  # IMU gaps this long make the heading unknown [s]
    store_rts: bool  # keep what the RTS smoother needs
    huber_pos: float  # Huber threshold of GNSS positions [σ] (0: no loss)
    huber_vel: float  # Huber threshold of GNSS velocities [σ] (0: no loss)
    tilt_consider: bool  # horizontal GNSS rows hold the attitude while the heading is unknown


@njit(cache=True)
def _store(o, out_lla, out_v, out_q, out_par, lla, v, q, par):
    put(out_lla[o], lla)
    put(out_v[o], v)
    put(out_q[o], q)
    put(out_par[o], par)


class FilterOutput(NamedTuple):
    """What ``run_filter`` returns, by name (the compiled kernel returns the plain tuple in
    this order; ``FilterOutput(*res)`` names it): the outputs at the output epochs (``lla``,
    ``v``, ``q``, ``par``), the covariance at the covariance epochs (``cov``), the RTS
    records (``rts_p``, ``rts_ing``, ``rts_q``, ``corr``, ``reset_at``), the heading's
    acquisition time (``t_heading``) and whether the course gave it (``by_course``); the
    innovations and refusals are in the ``updates.Innovations`` handed to ``run_filter``."""

    lla: Any
    v: Any
    q: Any
    par: Any
    cov: Any
    rts_p: Any
    rts_ing: Any
    rts_q: Any
    corr: Any
    reset_at: Any
    t_heading: Any
    by_course: Any


@njit(cache=True)
def run_filter(grids, init, noise, events, meas, settings, inn):
    """Forward error-state EKF over the whole drive (see module docstring).

    The records are described by their classes (:class:`Grids` ... :class:`Settings`,
    ``updates.Measurements``); ``inn`` (``updates.Innovations``) is filled in place.
    Returns the output trajectory, packed covariances and, when ``settings.store_rts``, what
    the RTS smoother needs.
    """
    t, gyro, accel, gap_step = grids.t, grids.gyro, grids.accel, grids.gap_step
    n, gnss = t.size, meas.gnss
    store_rts, max_pending = settings.store_rts, events.max_pending
    out_lla = np.empty((grids.n_out, 3))
    out_v = np.empty((grids.n_out, 3))
    out_q = np.empty((grids.n_out, 4))
    out_par = np.empty((grids.n_out, NPAR))
    cov_out = np.empty((grids.n_cov_out, NPACK))
    ks = grids.n_grid if store_rts else 1
    rts_p = np.zeros((ks, NPACK))
    rts_ing = np.zeros((ks, NING))
    rts_q = np.zeros((ks, NX))
    corr = np.zeros((ks, NX))
    reset_at = np.full(grids.n_grid, np.nan)

    lla, v, q = init.lla0.copy(), init.v0.copy(), init.q0.copy()
    par, p = init.par0.copy(), init.p0.copy()
    heading_ok = init.heading_known
    t_heading = t[0] if heading_ok else np.nan
    by_course = False  # the last heading acquisition was the GNSS course's
    acq = new_state()  # heading acquisition (ekf.heading)
    sf_acc, s_i, ch_u, ch_w = np.zeros(2), np.zeros(2), np.zeros(2), np.zeros(2)
    # measurements of the current grid interval, updated at its end
    pend_type = np.zeros(max_pending, dtype=np.int64)
    pend_idx = np.zeros(max_pending, dtype=np.int64)
    pend_t = np.zeros(max_pending)
    pend_y = np.zeros((max_pending, 6))
    pend_h = np.zeros((max_pending, 6, NX))
    pend_r = np.zeros((max_pending, 6))
    pend_m = np.zeros(max_pending, dtype=np.int64)
    pend_ok = np.zeros(max_pending, dtype=np.bool_)  # heading known when the rows were made
    n_pend = 0
    acc_fn, acc_fb, acc_n = np.zeros(3), np.zeros(3), 0  # interval's mean specific force
    t_prev_grid = t[0]
    je = 0
    while je < events.t.size and events.t[je] <= t[0]:
        je += 1
    if grids.out_of[0] >= 0:
        _store(grids.out_of[0], out_lla, out_v, out_q, out_par, lla, v, q, par)
    if grids.grid_of[0] >= 0:
        if store_rts:
            pack(p, rts_p[0])
        if grids.cov_out_of[0] >= 0:
            pack(p, cov_out[grids.cov_out_of[0]])

    for i in range(n - 1):
        dt = t[i + 1] - t[i]
        sc = 1.0 / (1.0 + par[PKA:PKA + 3])
        w0 = gyro[i] - par[PBG:PBG + 3]
        w1 = gyro[i + 1] - par[PBG:PBG + 3]
        f0 = (accel[i] - par[PBA:PBA + 3]) * sc
        f1 = (accel[i + 1] - par[PBA:PBA + 3]) * sc
        lla_p, v_p, q_p = lla, v, q
        if gap_step[i]:
            # IMU gap: constant velocity, attitude re-levelled from the first samples after
            # it with the yaw kept (docs/ekf.md, "IMU gaps")
            rn0, re0 = radii_scalar(lla_p[0])
            lla = lla_p.copy()
            lla[0] += v_p[0] * dt / (rn0 + lla_p[2])
            lla[1] += v_p[1] * dt / ((re0 + lla_p[2]) * np.cos(lla_p[0]))
            lla[2] -= v_p[2] * dt
            v = v_p.copy()
            q = rpy_quat(grids.gap_rp[i + 1, 0], grids.gap_rp[i + 1, 1], yaw_of(q_p))
            if dt >= settings.gap_forget_s:
                # long gap: the vehicle may have turned (a crash that flips it over); the
                # heading is re-acquired afterwards
                heading_ok = False
                acq[RESET_DELTA] = np.nan
            restart_matching(acq, sf_acc, s_i, ch_u, ch_w)
        else:
            lla, v, q = strapdown_step(lla_p, v_p, q_p, w0, w1, f0, f1, dt)
            fm = 0.5 * (f0 + f1)
            acc_fb += fm
            fnm = quat_to_dcm(q) @ fm
            acc_fn += fnm
            acc_n += 1
            s_i[0] = fnm[0] * dt
            s_i[1] = fnm[1] * dt
            sf_acc += s_i

        # measurements with time in (t_i, t_{i+1}]: rows from the interpolated nominal
        while je < events.t.size and events.t[je] <= t[i + 1]:
            tm = events.t[je]
            al = (tm - t[i]) / dt
            lm = (1.0 - al) * lla_p + al * lla
            vm = (1.0 - al) * v_p + al * v
            qm = q if al > 0.5 else q_p
            cm = quat_to_dcm(qm)
            rn, re = radii_scalar(lm[0])
            idx = events.idx[je]
            kind = events.kind[je]
            y, hm, r, mm = event_rows(kind, idx, lm, vm, cm, rn, re, par, w0, w1, meas,
                                      heading_ok, p, acq)
            if kind == GNSS:  # heading acquisition from the fix (``ekf.heading``)
                if not heading_ok and settings.heading_accel and gnss.has_vel:
                    match_acceleration(acq, sf_acc, s_i, ch_u, ch_w, al, tm, idx, gnss.vel,
                                       gnss.vel_sd, settings.align_chunk_s,
                                       settings.align_forget_s, settings.align_sd_max,
                                       settings.align_acc_sd)
                    if settings.heading_course:
                        confirmed_course(acq, gnss.track_speed[idx], gnss.track_yaw[idx],
                                         gnss.track_sd[idx], qm, settings.heading_v_min,
                                         settings.align_sd_max, settings.course_confirm_sd)
                elif not heading_ok:
                    track_heading(acq, gnss.track_speed[idx], gnss.track_yaw[idx],
                                  gnss.track_sd[idx], qm, settings.heading_v_min,
                                  settings.align_sd_max)
            if mm > 0 and n_pend < max_pending:
                pend_type[n_pend] = kind
                pend_idx[n_pend] = idx
                pend_t[n_pend] = tm
                put(pend_y[n_pend], y)
                put(pend_h[n_pend], hm)
                put(pend_r[n_pend], r)
                pend_m[n_pend] = mm
                pend_ok[n_pend] = heading_ok
                n_pend += 1
            je += 1

        k = grids.grid_of[i + 1]
        if k >= 0:
            dtg = t[i + 1] - t_prev_grid
            p, ing, fmat, qd = grid_predict(p, q, lla, v, par, acc_fn, acc_fb, acc_n,
                                            heading_ok, gap_step[i], dtg, t[i + 1] - t[0],
                                            noise.q_diag[k], noise)
            if not heading_ok and not np.isnan(acq[RESET_DELTA]):
                # heading acquired: reset yaw, rotate the tilt covariance
                p, q = heading_reset(p, q, qd, acq[RESET_DELTA], acq[RESET_SD])
                reset_at[k] = acq[RESET_DELTA]
                heading_ok = True
                t_heading = t[i + 1]
                by_course = acq[RESET_COURSE] > 0.5
                acq[RESET_COURSE] = 0.0
                acq[RESET_DELTA] = np.nan
            if store_rts:
                put(rts_ing[k], ing)
                put(rts_q[k], qd)
            dx = np.zeros(NX)
            for e in range(n_pend):
                mm, idx = pend_m[e], pend_idx[e]
                heff = delayed_rows(pend_h[e], pend_r[e], mm, fmat, qd, t[i + 1] - pend_t[e],
                                    dtg)
                event_update(pend_type[e], idx, p, dx, heff, pend_y[e], pend_r[e], mm,
                             pend_t[e], k, meas, settings, noise.b_prior_var, rts_q, inn,
                             pend_ok[e])
            n_pend = 0
            apply_correction(lla, v, q, par, dx)
            if store_rts:
                put(corr[k], dx)
                pack(p, rts_p[k])
            if grids.cov_out_of[k] >= 0:
                pack(p, cov_out[grids.cov_out_of[k]])
            acc_fn[:] = 0.0
            acc_fb[:] = 0.0
            acc_n = 0
            t_prev_grid = t[i + 1]

        if grids.out_of[i + 1] >= 0:
            _store(grids.out_of[i + 1], out_lla, out_v, out_q, out_par, lla, v, q, par)

    return (out_lla, out_v, out_q, out_par, cov_out, rts_p, rts_ing, rts_q, corr, reset_at,
            t_heading, by_course)
