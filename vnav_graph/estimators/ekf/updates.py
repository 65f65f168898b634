"""The filter's measurements: everything that is per measurement kind (GNSS, baro,
magnetometer, zero-velocity update) is here, and a kind is added to the filter here alone:
1. its kind number (the position of its record in :class:`Measurements`) and data record;
   the record and the event stamps built from the drive in :func:`measurements`;
2. its row function, the innovation ``y = h(x̃) − z`` (6,), the Jacobian rows ``H`` (6, NX)
   and the noise variances ``r`` (6,) at an event and how many rows it uses, and its gated
   update of those rows mapped to the grid epoch (``steps.delayed_rows``); a branch for
   each in the compiled dispatchers :func:`event_rows` and :func:`event_update`, which
   ``kernel.run_filter`` calls;
3. its innovation and refusal arrays in :class:`Innovations` (:func:`new_innovations`;
   the kernel fills them) and their ``innovations`` / ``info`` entries (:func:`report`).

The nominal state at an event (``lm``, ``vm``, ``cm`` = C_nb, the radii ``rn``, ``re``) is
interpolated by the kernel; the rows follow the shared sensor models
(``sensors.gnss_model``, ``sensors.baro``, ``sensors.magnetometer.mag_heading_row``), which
give the prediction and its Jacobian in physical errors, and place them into the filter's
columns (``model``'s ``I*`` indices). Every record field keeps one numba type (float64
arrays, C-contiguous; int64 counts; float scalars; bools) so that the kernel compiles once.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
from numba import njit
from scipy.stats import chi2

from ...nav.arrays import put
from ...nav.gnss_gate import REFUSE, USE_INFLATE, height_gate
from ...nav.standstill import ZUPT_SD_FLOOR, Standstill
from ...nav.strapdown import nav_rates
from ...sensors.baro import baro_predict, baro_row
from ...sensors.gnss_model import antenna_position, antenna_velocity
from ...sensors.magnetometer import MIN_HORIZONTAL_UT, mag_heading_row
from ...sensors.model import BaroPrior, SensorModel
from ...types import Drive
from ...types.streams import BoolArray, FloatArray, IntArray
from .alignment import Alignment, track_heading
from .heading import RESET_DELTA, RESET_SD
from .magnetometer import one_per_interval
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
    PGE,
    PMB,
    PSC,
    PTD,
    consider_update,
    huber_weight,
    scalar_update,
    unpack,
    vector_update,
)
from .settings import EkfConfig
from .steps import tilt_held, update_gated

# event kinds of ``kernel.Events.kind``: the field order of ``Measurements``
GNSS, BARO, MAG, ZUPT = 0, 1, 2, 3


class GnssData(NamedTuple):
    """Per-fix GNSS data (G fixes; zero rows without GNSS)."""

    lla: FloatArray  # (G, 3) antenna position [rad, rad, m]
    pos_sd: FloatArray  # (G, 3) NED position σ [m] (shared model, floored)
    vel: FloatArray  # (G, 3) velocity in n [m/s]
    vel_sd: FloatArray  # (G, 3) velocity σ [m/s]
    has_vel: bool  # the velocity is used
    lever: FloatArray  # (3,) antenna lever arm in b [m]
    track_yaw: FloatArray  # (G,) course over ground [rad]
    track_speed: FloatArray  # (G,) horizontal speed [m/s]
    track_sd: FloatArray  # (G,) σ of the course as a heading [rad]


class BaroData(NamedTuple):
    """Baro samples (B; zero without a barometer) and their gate."""

    alt: FloatArray  # (B,) baro altitude [m]
    sd: float  # white baro noise σ [m]
    h0: float  # reference height of the baro model [m]
    has_baro: bool
    gate: float  # χ²₁ gate
    max_consec: int  # refusals after which a sample is forced in
    huber: float  # Huber threshold [σ] (0: no loss)


class MagData(NamedTuple):
    """Magnetometer samples (M; zero rows without one), heading model ``sensors.magnetometer``."""

    field: FloatArray  # (M, 3) field in b [µT]
    sd_ut: float  # white noise per axis [µT]
    declination: float  # of the Earth's field at the origin [rad]
    floor_var: float  # heading variance floor (declination, soft iron) [rad²]
    gate: float  # χ²₁ gate of the heading innovation
    max_consec: int  # refusals after which a heading is forced in


class ZuptData(NamedTuple):
    """Zero-velocity updates (``nav.standstill``; Z of them, one per ``ZUPT`` event)."""

    sd: float  # σ per axis [m/s]
    gate: float  # χ²₃ gate


class Measurements(NamedTuple):
    """The kernel's measurement records, one per event kind, in the kinds' order."""

    gnss: GnssData
    baro: BaroData
    mag: MagData
    zupt: ZuptData


class Innovations(NamedTuple):
    """Normalised innovations (NaN until used) and refusal flags of every event, filled in
    place by the kernel, and the gates' state it carries from event to event."""

    pos: FloatArray  # (G, 3) GNSS position
    vel: FloatArray  # (G, 3) GNSS velocity
    baro: FloatArray  # (B,)
    mag: FloatArray  # (M,)
    zupt: FloatArray  # (Z, 3)
    rej_pos: BoolArray  # (G,) horizontal pair or height refused
    forced_pos: BoolArray  # (G,) horizontal pair forced in after refusals
    rej_vel: BoolArray  # (G,)
    rej_v: BoolArray  # (G,) height refused
    rej_baro: BoolArray  # (B,)
    rej_mag: BoolArray  # (M,)
    rej_zupt: BoolArray  # (Z,)
    counts: IntArray  # (3,) refusals in a row (``C_*``)
    v_gate: FloatArray  # (3,) ``nav.gnss_gate`` state


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


# the gates' refusal counters (``Innovations.counts``)
C_POS, C_BARO, C_MAG = 0, 1, 2


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
def update_zupt(p, dx, heff, y, r, gate, inn, rej, idx):
    """A zero-velocity pseudo-measurement (``zupt_rows``) behind a χ²₃ gate, never
    forced: a standstill the filter's velocity contradicts is refused (``rej``)."""
    no_force = gate < 0.0  # False as a typed bool: a literal compiles vector_update again
    ok, nis, nrm, w = vector_update(p, dx, heff[:3].copy(), y[:3].copy(), r[:3].copy(), gate,
                                    no_force, 0.0, 0, 0)
    put(inn[idx], nrm)
    rej[idx] = not ok


@njit(cache=True)
def event_rows(kind, idx, lm, vm, cm, rn, re, par, w0, w1, meas, heading_ok, p, acq):
    """The rows ``(y, hm, r, mm)`` of event ``idx`` of ``kind`` at the nominal state
    (``lm``, ``vm``, ``cm``, radii ``rn``, ``re``; parameters ``par``; the IMU step's rates
    ``w0``, ``w1``); ``p`` and ``acq``: the magnetometer's heading proposal (``mag_rows``)."""
    if kind == GNSS:
        g = meas.gnss
        return gnss_rows(lm, vm, cm, rn, re, par[PGE:PGE + 3], g.lever, g.lla[idx],
                         g.pos_sd[idx], g.vel[idx], g.vel_sd[idx], g.has_vel, heading_ok, w0,
                         w1)
    if kind == BARO:
        return baro_rows(lm, vm, par, meas.baro.h0, meas.baro.alt[idx], meas.baro.sd)
    if kind == ZUPT:
        return zupt_rows(vm, meas.zupt.sd)
    m = meas.mag
    return mag_rows(m.field[idx], par, cm, m.declination, m.sd_ut, m.floor_var, heading_ok, p,
                    acq)


@njit(cache=True)
def event_update(kind, idx, p, dx, heff, y, r, mm, te, k, meas, settings, b_prior_var, rts_q,
                 inn, heading_ok):
    """The gated update of event ``idx`` of ``kind`` with its rows mapped to grid epoch ``k``
    (``heff``), made at time ``te`` with the heading known or not (``heading_ok``); fills
    ``inn``; ``rts_q``: the RTS record of the process noise (a forced GNSS pair adds to it)."""
    if kind == GNSS:
        update_gnss(p, dx, heff, y, r, mm, idx, te, k, settings, meas.gnss.pos_sd[idx, 2],
                    meas.baro.has_baro, b_prior_var, inn.v_gate, inn.counts, rts_q, inn.pos,
                    inn.vel, inn.rej_pos, inn.rej_vel, inn.rej_v, heading_ok, inn.forced_pos)
    elif kind == BARO:
        b = meas.baro
        update_gated(p, dx, heff, y, r, b.gate, b.max_consec, inn.counts, C_BARO, inn.baro,
                     inn.rej_baro, idx, b.huber, tilt_held(p, settings, heading_ok))
    elif kind == ZUPT:
        update_zupt(p, dx, heff, y, r, meas.zupt.gate, inn.zupt, inn.rej_zupt, idx)
    else:
        update_gated(p, dx, heff, y, r, meas.mag.gate, meas.mag.max_consec, inn.counts, C_MAG,
                     inn.mag, inn.rej_mag, idx, 0.0, False)


@dataclass(frozen=True)
class Context:
    """What the forward pass's set-up hands to the measurements' records and reports: the
    drive, its shared sensor model, the configuration, the alignment (lever arm, GNSS
    latency), the baro prior, the magnetometer's field reference (None: not used) and the
    standstill of the zero-velocity updates (None: off)."""

    drive: Drive
    model: SensorModel
    cfg: EkfConfig
    ini: Alignment
    bp: BaroPrior
    fm: Any
    still: Standstill | None


def measurements(c: Context) -> tuple[Measurements, list[FloatArray]]:
    """The kernel's records and each kind's event stamps [s] (in the kinds' order; event
    ``i`` of a kind is row ``i`` of its record)."""
    drive, cfg = c.drive, c.cfg
    gnss, baro, mag = drive.gnss, drive.baro, drive.mag
    gate1 = float(chi2.ppf(cfg.gate_prob, 1))
    if gnss is not None:
        tr = track_heading(gnss, cfg.sideslip_sd, drive.imu)
        g_lla, g_psd = gnss.lla, c.model.gnss_pos_sd
        has_vel = gnss.vel_n is not None and c.model.gnss_vel_sd is not None
        g_vel = gnss.vel_n if has_vel else np.zeros((gnss.t.size, 3))
        g_vsd = c.model.gnss_vel_sd if has_vel else np.ones((gnss.t.size, 3))
        tr_yaw, tr_speed, tr_sd = tr.yaw, tr.speed, tr.yaw_sd
        t_g = gnss.t - c.ini.g_latency
    else:
        g_lla = g_psd = g_vel = g_vsd = np.zeros((0, 3))
        has_vel = False
        tr_yaw = tr_speed = tr_sd = t_g = np.zeros(0)
    g_data = GnssData(np.ascontiguousarray(g_lla), np.ascontiguousarray(g_psd),
                      np.ascontiguousarray(g_vel), np.ascontiguousarray(g_vsd), bool(has_vel),
                      c.ini.lever, tr_yaw, tr_speed, tr_sd)
    max_consec_baro = 1
    if baro is not None and baro.t.size > 1:
        max_consec_baro = max(3, round(cfg.baro_reaccept_s / float(np.median(np.diff(baro.t)))))
    b_alt = np.asarray(baro.altitude, dtype=float) if baro is not None else np.zeros(0)
    b_data = BaroData(b_alt, float(c.bp.noise_sd), float(drive.origin_lla[2]),
                      baro is not None, gate1, int(max_consec_baro), cfg.huber_k()[2])
    if c.fm is not None:
        assert mag is not None
        im = one_per_interval(mag.t, cfg.mag_interval_s)
        m_data = MagData(np.ascontiguousarray(mag.field_b[im]), float(mag.sd_ut),
                         float(c.fm.declination_rad), float(cfg.mag_heading_floor**2), gate1,
                         int(max(3, round(cfg.mag_reaccept_s / cfg.mag_interval_s))))
        t_m = mag.t[im]
    else:
        m_data, t_m = MagData(np.zeros((0, 3)), 1.0, 0.0, 0.0, 1.0, 1), np.zeros(0)
    still = c.still
    t_z = np.zeros(0) if still is None else np.asarray(still.update_times(), dtype=float)
    z_data = ZuptData(float(still.vel_sd) if still is not None else float(ZUPT_SD_FLOOR),
                      float(chi2.ppf(cfg.gate_prob, 3)))
    return (Measurements(g_data, b_data, m_data, z_data),
            [t_g, np.zeros(0) if baro is None else baro.t, t_m, t_z])


def new_innovations(stamps: list[FloatArray]) -> Innovations:
    """Each kind's innovations (NaN) and refusal flags (False) for its events, and the
    gates' initial state."""
    ng, nb, nm, nz = (s.size for s in stamps)
    return Innovations(
        np.full((ng, 3), np.nan), np.full((ng, 3), np.nan), np.full(nb, np.nan),
        np.full(nm, np.nan), np.full((nz, 3), np.nan), np.zeros(ng, dtype=np.bool_),
        np.zeros(ng, dtype=np.bool_), np.zeros(ng, dtype=np.bool_),
        np.zeros(ng, dtype=np.bool_), np.zeros(nb, dtype=np.bool_),
        np.zeros(nm, dtype=np.bool_), np.zeros(nz, dtype=np.bool_),
        np.zeros(3, dtype=np.int64), np.array([0.0, 0.0, np.nan]))


def report(c: Context, meas: Measurements, inn: Innovations, par: FloatArray,
           cov_last: FloatArray) -> tuple[dict[str, FloatArray], dict[str, Any]]:
    """The ``innovations`` (normalised (z − h(x̃))/√S of the accepted measurements) and
    ``info`` entries of every kind (``filter`` module docstring); ``par``: the parameters
    at the output epochs, ``cov_last``: the last packed covariance."""
    gnss = c.drive.gnss
    has_vel = meas.gnss.has_vel
    innov: dict[str, FloatArray] = {}
    if gnss is not None:
        innov["gnss_pos"] = inn.pos[np.isfinite(inn.pos[:, 0]) & ~inn.rej_pos]
        if has_vel:
            innov["gnss_vel"] = inn.vel[np.isfinite(inn.vel[:, 0]) & ~inn.rej_vel]
    if c.drive.baro is not None:
        innov["baro"] = inn.baro[np.isfinite(inn.baro) & ~inn.rej_baro]
    rej_pos, rej_vel = inn.rej_pos, inn.rej_vel
    info: dict[str, Any] = {
        "gnss_rejected": int(rej_pos.sum()),
        "gnss_rejected_t": (gnss.t[rej_pos] if gnss is not None else np.zeros(0)),
        # fixes of which nothing was used (position refused, and velocity refused or absent)
        "gnss_unused_t": (gnss.t[rej_pos & (rej_vel | (not has_vel))] if gnss is not None
                          else np.zeros(0)),
        "gnss_alt_rejected": int(inn.rej_v.sum()),
        "gnss_vel_rejected": int(rej_vel.sum()),
        "baro_rejected": int(inn.rej_baro.sum()),
    }
    if meas.mag.field.shape[0]:
        innov["mag"] = inn.mag[np.isfinite(inn.mag) & ~inn.rej_mag]
        sd_mb = np.sqrt(np.clip(np.diag(unpack(cov_last))[IMB:IMB + 3], 0, None))
        info.update(mag_used=int(np.isfinite(inn.mag).sum() - inn.rej_mag.sum()),
                    mag_rejected=int(inn.rej_mag.sum()),
                    # the hard iron [µT] under the graph's name for it (H(0) → "h0"), so that
                    # summary.json shows both families' estimates side by side
                    extra_variables={"h0": {"est": par[-1, PMB:PMB + 3].tolist(),
                                            "sd": sd_mb.tolist()}})
    info.update(zupt_info(c.still, inn.zupt, inn.rej_zupt))
    if info["zupt_used"]:
        innov["zupt"] = inn.zupt[np.isfinite(inn.zupt[:, 0]) & ~inn.rej_zupt]
    return innov, info


def zupt_info(still: Standstill | None, inn: FloatArray, rej: BoolArray) -> dict[str, Any]:
    """``info["zupt_intervals"]`` ([t_start, t_end] [s] of the detected standstills, empty
    with ``EkfConfig.zupt`` off), ``zupt_used`` / ``zupt_rejected`` (updates applied and
    refused by their χ²₃ gate) and ``zupt`` (the detector's threshold and σ)."""
    if still is None:
        return {"zupt_intervals": [], "zupt_used": 0, "zupt_rejected": 0}
    return {"zupt_intervals": still.interval_list(),
            "zupt_used": int(np.isfinite(inn[:, 0]).sum() - rej.sum()),
            "zupt_rejected": int(rej.sum()),
            "zupt": still.summary()}
