"""Inputs of the classical vertical-channel estimators: vertical specific force, gravity, C33.

The seed papers assume that "the INS" hands the vertical channel its specific force resolved
along the local vertical. Without reading truth, ``vertical_inputs`` provides it from a small
GNSS-aided attitude and heading reference (AHRS): coarse levelling, gyro integration with the
shared mechanisation, a Mahony-type PI tilt correction by velocity matching against GNSS
velocity increments, heading from the GNSS course, robustness rules for bad GNSS velocity,
an accelerometer-levelling fallback, IMU-gap re-levelling, and causal outputs. Its
specification, with the steps (1–9) and rules (R1–R5) the code names, its outputs and its
measured accuracy, is docs/vertical_loops.md, section 1.

Outputs at the IMU epochs (``VerticalInputs``): the AHRS attitude q_nb, the vertical specific
force f_D (NED down, m/s², ≈ −g at rest), C33, F_z, the latitude, the normal gravity at the
reference height and the vertical Coriolis/transport term: dv_D/dt = f_D + g(lat, h) + cor_D.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ...geo.earth import OMEGA_IE, gravity, radii
from ...nav.gaps import gap_threshold
from ...types import Drive
from ...types.streams import FloatArray
from .ahrs import AhrsFixes, AhrsGains, AhrsImu, ahrs_kernel
from .ahrs_cache import shared_call
from .gnss_reference import baro_rate, matching_inputs, velocity_from_positions


@dataclass(frozen=True)
class AhrsConfig:
    """Gains and robustness rules of the GNSS-aided attitude reference (steps and rules R1-R5:
    the module docstring).

    level_s : duration of the initial coarse-levelling average [s]
    tilt_omega : natural frequency ω_t of the tilt PI loop, k_p = 2ζω_t, k_i = ω_t² [rad/s]
    tilt_zeta : damping ζ of the tilt loop [-]
    yaw_gain : gain k_y of the course-over-ground heading correction [1/s]
    v_course_min : ground speed above which the GNSS course is trusted as heading [m/s]
    max_correction : clamp on each raw tilt observation |ψ̂| per update, gross errors only [rad]
    max_tilt_feedback : clamp on the low-passed tilt error ψ fed back as a rate (R4) [rad]
    gap_factor : fixes further apart than this × the nominal interval are an outage [-]
    a_static : before heading, tilt is corrected only below this horizontal acceleration [m/s²]
    match_interval_s : minimum length of a velocity-matching interval [s]
    tilt_filter_s : time constant T_f of the low-pass on the raw tilt observation ψ̂ [s]
    gate_prob : false-alarm probability p of the χ²₂ velocity-matching gate (R2; None: no gate)
    tilt_sd0 : σ of the tilt error of an aligned reference, used in the gate [rad]
    gyro_bias_sd : σ of the residual gyro bias; the gate's tilt σ grows by it per second [rad/s]
    heading_sd : σ of the heading error once initialised, used in the gate [rad]
    sd_v_default : σ of a receiver velocity without ``vel_sd`` [m/s]
    sd_v_nominal : velocity σ up to which an interval gets the full gain, else R_nom/R (R3) [m/s]
    sd_v_max : fixes with a horizontal velocity σ above this are not used (R1) [m/s]
    reinit_s : gate rejections spanning this long let the next usable interval through [s]
    baro_check : drop the vertical levelling residual where receiver and baro climb disagree (R5)
    pos_vel_window_s, pos_vel_min_fixes : without receiver velocity, the position-fit window [s]
    pos_vel_vertical : trust the vertical component of the position-fit velocity
    fallback_after_s : without a GNSS levelling update this long, the accelerometer fallback [s]
    accel_level_window_s : averaging window of the fallback [s]
    accel_level_tau_s : time constant of the fallback's tilt correction [s]
    static_rate : the fallback runs only when |mean(ω̃ − b̂_g)| is below this [rad/s]
    static_accel : ... and | |mean f̃_b| − g | is below this [m/s²]
    """

    level_s: float = 2.0
    tilt_omega: float = 0.05
    tilt_zeta: float = 1.0
    # the z-gyro bias integrator gain is k_y²/4 (critically damped heading loop)
    yaw_gain: float = 0.1
    # raised per fix to 5σ of that fix's horizontal velocity
    v_course_min: float = 5.0
    # a tight clamp would break the telescoping of the velocity noise
    max_correction: float = 1.0
    # step 5, rule R4: the feedback rate never exceeds k_p·max_tilt_feedback
    max_tilt_feedback: float = 0.2
    # no correction is made across an outage
    gap_factor: float = 2.5
    # plus 3σ of the differenced GNSS velocity noise, 3·√2·σ_v/match_interval_s
    a_static: float = 0.3
    # faster fixes are thinned: at 10 Hz with σ_v = 0.1 m/s, matching every fix gave 3-5×
    # larger tilt noise on the simulated hill-drive than matching every 0.5 s
    match_interval_s: float = 0.5
    tilt_filter_s: float = 2.0
    # rule R2: threshold −2 ln p (13.8 at 10⁻³)
    gate_prob: float | None = 1e-3
    # covers the consumer accelerometer-bias floor of ≈ 7 mrad with margin
    tilt_sd0: float = 0.03
    gyro_bias_sd: float = 0.002
    # couples ψ_z × a_h into the horizontal residual
    heading_sd: float = 0.05
    sd_v_default: float = 0.2
    sd_v_nominal: float = 1.0
    sd_v_max: float = 3.0
    # the gate cannot lock the GNSS out after a real drift
    reinit_s: float = 20.0
    baro_check: bool = True
    # step 3b: the reference velocity at each fix is the slope of a σ-weighted quadratic
    # least-squares fit of the GNSS positions over max(pos_vel_window_s,
    # (pos_vel_min_fixes − 1) × nominal fix interval)
    pos_vel_window_s: float = 4.0
    pos_vel_min_fixes: int = 7
    pos_vel_vertical: bool = False
    # step 6: the accelerometer levelling fallback
    fallback_after_s: float = 90.0
    accel_level_window_s: float = 10.0
    # slow: the fallback assumes no sustained horizontal acceleration
    accel_level_tau_s: float = 30.0
    # no turn: a turn carries a centripetal acceleration
    static_rate: float = 0.03
    static_accel: float = 0.3
    # IMU logging gaps (nav.gaps, step 7): attitude held across them, no velocity matching

    def __post_init__(self) -> None:
        for n in ("level_s", "tilt_omega", "tilt_zeta", "v_course_min", "max_correction",
                  "max_tilt_feedback", "gap_factor", "tilt_filter_s", "tilt_sd0",
                  "sd_v_default", "sd_v_nominal", "sd_v_max", "reinit_s", "pos_vel_window_s",
                  "fallback_after_s", "accel_level_window_s", "accel_level_tau_s",
                  "static_rate", "static_accel", "heading_sd"):
            if not getattr(self, n) > 0:
                raise ValueError(f"AhrsConfig.{n}: must be > 0")
        if self.yaw_gain < 0 or self.gyro_bias_sd < 0:
            raise ValueError("AhrsConfig.yaw_gain, gyro_bias_sd: must be >= 0")
        if self.gate_prob is not None and not 0.0 < self.gate_prob < 1.0:
            raise ValueError("AhrsConfig.gate_prob: in (0, 1) or None")
        if self.pos_vel_min_fixes < 3:
            raise ValueError("AhrsConfig.pos_vel_min_fixes: at least 3 (quadratic fit)")


@dataclass(frozen=True)
class VerticalInputs:
    """Vertical-channel inputs at the IMU epochs (see module docstring for the equations).

    Parameters
    ----------
    t : (N,) IMU epochs [s]
    f_down : (N,) vertical specific force f_D = [C_nb f̃_b]_3, NED down [m/s²] (≈ −g at rest)
    gravity : (N,) normal gravity g(lat, h_ref) at the reference (GNSS) height [m/s²], +down
    c33 : (N,) C_nb[2, 2] of the AHRS attitude [-]
    f_z_b : (N,) measured specific force along body z (down) [m/s²]
    coriolis_down : (N,) cor_D = −[(2ω_ie + ω_en) × v]_D [m/s²] with v the horizontal
        velocity propagated from the last usable GNSS velocity (step 8)
    lat : (N,) latitude used for gravity [rad] (the last GNSS fix at or before the epoch;
        the origin before the first fix and without GNSS)
    q_nb : (N, 4) AHRS attitude (w, x, y, z), b → n
    bias_gyro : (N, 3) AHRS gyro-bias estimate [rad/s]
    info : counters of the robustness rules (``velocity_source``, ``levelling_accepted``,
        ``levelling_rejected``, ``levelling_reinit``, ``levelling_unusable``,
        ``vertical_dropped``, ``accel_level_updates``, ``imu_gaps``)
    """

    t: FloatArray
    f_down: FloatArray
    gravity: FloatArray
    c33: FloatArray
    f_z_b: FloatArray
    coriolis_down: FloatArray
    lat: FloatArray
    q_nb: FloatArray
    bias_gyro: FloatArray
    runtime_s: float = 0.0
    info: dict = field(default_factory=dict)


def _coarse_level(accel_b: FloatArray) -> FloatArray:
    """Roll/pitch from a mean specific force at rest (Groves eq. 5.101), yaw 0; returns q_nb."""
    from ...geo.frames import rph_to_quat
    from ...nav.levelling import coarse_level

    roll, pitch = coarse_level(np.mean(accel_b, axis=0))
    return rph_to_quat(np.array([[roll, pitch, 0.0]]))[0]


def _relevel_after_gaps(t, gyro, accel, gap_dt, level_s, g_nom, tol_acc, tol_rate):
    """(N, 2) roll/pitch [rad] at the first epoch after each IMU gap longer than gap_dt,
    from the mean specific force over the following level_s (Groves eq. 5.101), when that
    window is static: | |f̄| − g | < 3·tol_acc and the RMS rate below 3·tol_rate (NaN else)."""
    out = np.full((t.size, 2), np.nan)
    for k in np.flatnonzero(np.diff(t) > gap_dt) + 1:
        w = (t >= t[k]) & (t <= t[k] + level_s)
        if np.sum(w) < 3:
            continue
        f = accel[w].mean(axis=0)
        rate = float(np.sqrt(np.mean(np.sum(gyro[w] ** 2, axis=1))))
        if abs(np.linalg.norm(f) - g_nom) < 3 * tol_acc and rate < 3 * tol_rate:
            out[k] = np.arctan2(-f[1], -f[2]), np.arctan2(f[0], np.hypot(f[1], f[2]))
    return out


def vertical_inputs(drive: Drive, config: AhrsConfig | None = None) -> VerticalInputs:
    """Vertical specific force, gravity, C33 and F_z at the IMU epochs from a GNSS-aided AHRS.

    Parameters
    ----------
    drive : the drive; uses ``imu``, ``gnss`` when present (positions, and velocities if
        given) and ``baro`` (only to check the GNSS vertical velocity, rule R5). Truth is
        never read.
    config : AHRS gains and robustness rules (``AhrsConfig()`` by default)

    Returns
    -------
    VerticalInputs
        arrays of shape (N,) (``q_nb`` (N, 4), ``bias_gyro`` (N, 3)) at ``drive.imu.t``.
        Inside ``runner.run_estimators`` it is computed once per drive and config and
        shared, read-only, by the vertical estimators (``vertical.ahrs_cache``).
    """
    cfg = config or AhrsConfig()
    # computed once per run for all vertical estimators, time charged to each (sharing.py)
    return shared_call("vertical_inputs", drive, cfg, lambda: compute_vertical_inputs(drive, cfg))


def compute_vertical_inputs(drive: Drive, cfg: AhrsConfig) -> VerticalInputs:
    t0 = time.perf_counter()
    imu = drive.imu
    t = imu.t
    lev = t <= t[0] + cfg.level_s
    q0 = _coarse_level(imu.accel_b[lev])
    info: dict = {"velocity_source": "none"}
    m = matching_inputs(drive, cfg, t, info)
    # "quasi-static" threshold raised by 3σ of the differenced velocity noise per interval
    a_static_eff = cfg.a_static + 3.0 * np.sqrt(2.0) * m.sd_med / m.match
    kp = 2.0 * cfg.tilt_zeta * cfg.tilt_omega
    ki = cfg.tilt_omega**2
    # χ²₂ quantile; no gate on position-derived velocities: their smoothing kernel differs
    # from the IMU increment's, the residual carries the manoeuvre (a skier's turns), and
    # only an ungated sequence of intervals telescopes that mismatch away (step 3b)
    gate2 = np.inf if (cfg.gate_prob is None or info["velocity_source"] == "positions") \
        else -2.0 * np.log(cfg.gate_prob)
    g_nom = float(gravity(drive.origin_lla[0], drive.origin_lla[2]))
    relevel = _relevel_after_gaps(t, imu.gyro_b, imu.accel_b, gap_threshold(t),
                                  cfg.level_s, g_nom, cfg.static_accel, cfg.static_rate)
    # a writable copy of the specific force: its rows reach the shared strapdown step, which
    # then keeps the EKF's compiled specialisation (a read-only row would compile a second)
    f64 = [np.ascontiguousarray(a, dtype=float) for a in (m.t_g, m.t_av, m.v_g, m.g_g, m.cor_g)]
    fixes = AhrsFixes(np.ascontiguousarray(m.lla_i), np.ascontiguousarray(m.vel_i),
                      np.ascontiguousarray(m.sdv_i), *f64, m.ok,
                      np.ascontiguousarray(m.r_g, dtype=float), m.vert_iv, m.use)
    gains = AhrsGains(*(float(x) for x in (
        kp, ki, cfg.yaw_gain, 0.25 * cfg.yaw_gain**2, cfg.v_course_min, cfg.max_correction,
        cfg.max_tilt_feedback, a_static_eff, cfg.tilt_filter_s, cfg.gap_factor, gate2,
        cfg.tilt_sd0, cfg.gyro_bias_sd, cfg.heading_sd, m.r_nom, cfg.reinit_s,
        cfg.fallback_after_s, cfg.accel_level_window_s, cfg.accel_level_tau_s,
        cfg.static_rate, cfg.static_accel, g_nom, gap_threshold(t))))
    q, f_n, bg, vp, cnt = ahrs_kernel(
        AhrsImu(t, imu.gyro_b, np.array(imu.accel_b), q0, relevel), fixes, gains)
    for key, val in zip(("levelling_accepted", "levelling_rejected", "levelling_reinit",
                         "levelling_unusable", "vertical_dropped", "accel_level_updates",
                         "imu_gaps"), cnt, strict=True):
        info[key] = int(val)
    lat = m.lla_i[:, 0]
    h_ref = m.lla_i[:, 2]
    x, y = q[:, 1], q[:, 2]
    c33 = 1.0 - 2.0 * (x * x + y * y)
    # cor_D = −[(2ω_ie + ω_en) × v]_D with the propagated horizontal velocity (step 8)
    rn_i, re_i = radii(lat)
    wx = 2 * OMEGA_IE * np.cos(lat) + vp[:, 1] / (re_i + h_ref)
    wy = -vp[:, 0] / (rn_i + h_ref)
    cor_d = -(wx * vp[:, 1] - wy * vp[:, 0])
    q = np.where(q[:, :1] < 0, -q, q)
    return VerticalInputs(
        t=t, f_down=f_n[:, 2].copy(), gravity=gravity(lat, h_ref), c33=c33,
        f_z_b=imu.accel_b[:, 2].copy(), coriolis_down=cor_d, lat=lat, q_nb=q, bias_gyro=bg,
        runtime_s=time.perf_counter() - t0, info=info,
    )


__all__ = ["AhrsConfig", "VerticalInputs", "baro_rate", "velocity_from_positions",
           "vertical_inputs"]
