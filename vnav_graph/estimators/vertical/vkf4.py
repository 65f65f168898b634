"""Seed 004: 4-state baro-inertial Kalman filter of the INS vertical channel.

States (seed 004 §6.2, errors = indicated − true)::

    x = [Δh_ins, Δv_d, Δh_baro, Δh_m]

Δh_ins [m] is the INS height error (+up), Δv_d [m/s] the INS down-velocity error, Δh_baro [m]
the slowly varying baro altitude error (bias plus the accumulated scale-factor error of the
flight level) and Δh_m [m] the second, faster "Markov baro state" (lag- and
manoeuvre-induced baro error). Both baro errors are first-order Gauss-Markov processes.
Seed 004 prints the transition with a δt coupling of the first two states and process noise

    Q = [[Aδt³/3, Aδt²/2, 0, 0], [Aδt²/2, Aδt, 0, 0], [0, 0, 2β₃σ₃²δt, 0], [0, 0, 0, 2β₄σ₄²δt]]

(A the PSD of the vertical specific-force error, β = 1/τ). Here h is +up and v_d +down, so
Δḣ_ins = −Δv_d and Φ[0, 1] = −δt with the matching sign in Q[0, 1]; the Markov states use the
exact discrete transition exp(−βδt) and variance σ²(1 − exp(−2βδt)) of
``vnav_graph.sensors.noise`` (= 2βσ²δt to first order). The seed's garbled text also carries
a second-order-Markov parameter α = √(β² + ω²); we read the fourth state as an independent
first-order Markov error (documented interpretation, not the paper's verbatim model).

Measurements (closed loop; the INS height and velocity are corrected after every update and
their error states reset to zero):

- baro (seed 004): Z = h_ins − h_baro = Δh_ins − Δh_baro − Δh_m − v,  H = [1, 0, −1, −1];
- GNSS height, when available (our addition, so the baro errors are calibrated in flight):
  Z = h_ins − h_GNSS = Δh_ins − v_G, H = [1, 0, 0, 0], gated at ``gnss_gate_sigma``.

In GNSS outages only the baro updates: the INS channel then follows the baro corrected by the
last baro-error estimate, so the altitude error stays bounded (it grows only with the change of
the true baro error, e.g. the scale error times the altitude change, over the outage).

INS vertical channel (inputs from ``vertical.inputs.vertical_inputs``, never truth)::

    dv_D/dt = f_D + g(lat, h) + cor_D,   dh/dt = −v_D     (WGS-84 gravity at the INS height)

The accelerometer bias is not a state (4-state filter): it is absorbed by the process noise A,
which by default is the accelerometer white-noise PSD plus σ_ba²·``bias_corr_s`` (a random
walk that lets the velocity error follow the bias) plus the attitude-reference input error.

Outputs: altitude and down velocity at the IMU epochs; covariance in the ``ERROR_STATE`` layout
(pos_n[2] down, vel_n[2] down, baro_bias ← Δh_baro, rest NaN); ``Estimate.baro.bias_m`` is the
time average of the Δh_baro estimate — it lumps the scale error in, so it is the "baro error"
of the seed, not b(t) of the package model — with σ the time average of its σ (an upper bound
of the σ of the average).

Limitation (measured, ``benchmarks/reproduce_seeds.py``): the 4-state model has no scale
state, so an outage with a level change costs |s|·Δh — on sortie seed 3 (s = −4.1 %, 350 m
level change inside the 60 s outage) the outage altitude RMSE is 9.4 m against 1.2 m for
``vekf7``.

Causality: the answer is the online answer; measurements are processed at the first IMU
epoch at or after their stamp, the inputs come from the causal attitude reference
(step 9 of docs/vertical_loops.md §1) and the filter starts from the last fix at or before its first
epoch (``vekf7_setup.initial_fix``; else the baro there with the slow baro error's σ).
Altitude RMSE, hill-drive seeds 0/1/2: 0.686/0.450/0.475 m; sortie seeds 0/1/2:
0.909/0.999/0.799 m (0.686/0.448/0.477 and 0.905/1.001/0.792 m when the inputs are
interpolated toward the next fix and the filter starts from the first fix, 0.1-0.5 s after
the first epoch on these drives).

Reference: seed 004 §6.2 (Reddy & Saraswat, four-state baro-inertial filter); Groves 2nd ed.
§16.3.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from ...geo.earth import gravity_scalar
from ...nav.arrays import outer, put
from ...nav.error_state import embed_error_state, selection
from ...nav.gaps import GAP_ACCEL_SD, cv_bridge_noise, gap_threshold
from ...nav.gnss_gate import NO_LIMIT, REFUSE, height_gate
from ...sensors.model import sensor_model
from ...sensors.noise import gm_process_var, gm_transition
from ...types import BaroEstimate, Drive, Estimate, ParamEstimate
from ...types.streams import FloatArray
from .base import VerticalEstimator, vertical_estimate
from .inputs import AhrsConfig, vertical_inputs
from .vekf7_setup import initial_fix, input_error_psd

NX = 4


@dataclass(frozen=True)
class VKF4Config:
    """Tuning of the 4-state baro-inertial filter (``None``: from the stream specs).

    accel_psd : A, PSD of the vertical specific-force error [(m/s²)²/Hz] (None: from the specs)
    bias_corr_s : time over which an unmodelled accelerometer bias is treated as white [s]
    input_error_psd, tilt_sd, input_corr_s : as in ``vekf7.VEKF7Config``
    baro_slow_sd, baro_slow_tau : σ₃ [m], τ₃ [s] of Δh_baro (None: from the shared baro prior)
    alt_span_m : altitude span over which the scale error accumulates into Δh_baro [m]
    baro_fast_sd, baro_fast_tau : σ₄ [m], τ₄ [s] of the fast Markov state Δh_m
    baro_noise_sd : white baro noise [m] (None: the shared baro prior's)
    use_gnss : use GNSS heights when available (False: the seed-004 baro-inertial loop alone)
    gnss_gate_sigma : reject GNSS innovations beyond this many σ
    max_gnss_sd_v, gnss_probation_s : as in ``VEKF7Config``
    cov_rate_hz : rate at which covariances are stored [Hz]
    ahrs : attitude-reference gains
    """

    # None: the IMU spec's noise density² + accel_bias_sd²·bias_corr_s + the attitude-reference
    # input error of vekf7.input_error_psd (time-varying: larger in manoeuvres and GNSS
    # outages). The IMU and baro noise come from the shared sensor model (sensors.model); on a
    # log without an IMU spec its inferred accelerometer bias walk q_rw is added to A as its
    # white equivalent over bias_corr_s, q_rw²·bias_corr_s²/3; IMU gaps follow nav.gaps.
    accel_psd: float | None = None
    bias_corr_s: float = 60.0
    input_error_psd: float = 1e-4
    tilt_sd: float = 5e-4
    input_corr_s: float = 20.0
    # None: √(bias_sd² + (scale_sd·alt_span_m)²) and bias_tau of the shared baro prior
    baro_slow_sd: float | None = None
    baro_slow_tau: float | None = None
    alt_span_m: float = 1000.0
    baro_fast_sd: float = 1.5
    baro_fast_tau: float = 20.0
    baro_noise_sd: float | None = None
    use_gnss: bool = True
    gnss_gate_sigma: float = 5.0
    max_gnss_sd_v: float = 15.0
    gnss_probation_s: float = 10.0
    cov_rate_hz: float = 1.0
    ahrs: AhrsConfig | None = None


@njit(cache=True)
def _run(t, a_in, lat, h_init, v_init, p0, phi3, q3, phi4, q4, a_psd,
         ev_k, ev_kind, ev_z, ev_var, ev_lag, gate2, cov_dt, ev_t, ev_sd,
         max_sd_v, probation_s, gap_dt, gap_q):
    """Numba kernel: INS propagation at the IMU epochs, events processed at the first IMU
    epoch at or after their stamp. a_in = f_D + cor_D (gravity added at the INS height).
    ev_kind 0 = baro (ev_z = h_baro), 1 = GNSS (ev_z = h_GNSS, reported σ_v ev_sd). GNSS
    heights pass ``nav.gnss_gate.height_gate``'s plain rule (σ_v limit, probation after two
    consecutive refusals); an IMU step longer than gap_dt is bridged at constant velocity with the
    unknown-acceleration PSD gap_q."""
    n = t.size
    h_out = np.empty(n)
    v_out = np.empty(n)
    x = np.zeros(NX)
    p = p0.copy()
    h, vd = h_init, v_init
    h_out[0], v_out[0] = h, vd
    m = ev_k.size
    ncov = int((t[-1] - t[0]) / cov_dt) + 2
    t_cov = np.empty(ncov)
    p_cov = np.empty((ncov, NX, NX))
    x3_cov = np.empty(ncov)
    nc = 0
    next_cov = t[0]
    nu = np.full(m, np.nan)
    rejected = 0
    gate_state = np.array([0.0, 0.0, np.nan])  # nav.gnss_gate state
    j = 0
    for k in range(n):
        if k > 0:
            dt = t[k] - t[k - 1]
            if dt > gap_dt:
                h = h - vd * dt
            else:
                a0 = a_in[k - 1] + gravity_scalar(lat[k - 1], h)
                h_p = h - vd * dt
                a1 = a_in[k] + gravity_scalar(lat[k], h_p)
                v_new = vd + 0.5 * (a0 + a1) * dt
                h = h - 0.5 * (vd + v_new) * dt
                vd = v_new
            # Φ: Δh ← Δh − δt·Δv_d; baro states exact Gauss-Markov
            f = np.eye(NX)
            f[0, 1] = -dt
            f[2, 2] = phi3[k - 1]
            f[3, 3] = phi4[k - 1]
            x = f @ x
            p = f @ p @ f.T
            q_hh, q_hv, q_vv = cv_bridge_noise(a_psd[k - 1] if dt <= gap_dt else gap_q, dt)
            p[0, 0] += q_hh
            p[0, 1] -= q_hv  # Δh (up) against Δv_d (down)
            p[1, 0] -= q_hv
            p[1, 1] += q_vv
            p[2, 2] += q3[k - 1]
            p[3, 3] += q4[k - 1]
        while j < m and ev_k[j] == k:
            hrow = np.zeros(NX)
            hrow[0] = 1.0
            if ev_kind[j] == 0:
                hrow[2] = -1.0
                hrow[3] = -1.0
            # INS height at the measurement stamp (ev_lag = t_k − t_meas ≥ 0)
            z = (h + vd * ev_lag[j]) - ev_z[j]
            r = z - hrow @ x
            ph = p @ hrow
            s = hrow @ ph + ev_var[j]
            if ev_kind[j] == 1:
                code = height_gate(gate_state, ev_t[j], ev_sd[j] <= max_sd_v, r * r, s, gate2,
                                   probation_s, NO_LIMIT, 0.0, False)
                if code == REFUSE:
                    rejected += 1
                    j += 1
                    continue
            kg = ph / s
            x = x + kg * r
            ikh = np.eye(NX) - outer(kg, hrow)
            p = ikh @ p @ ikh.T + ev_var[j] * outer(kg, kg)
            nu[j] = r / np.sqrt(s)
            # closed loop: correct the INS and reset its error states
            h -= x[0]
            vd -= x[1]
            x[0] = 0.0
            x[1] = 0.0
            j += 1
        h_out[k], v_out[k] = h, vd
        if t[k] >= next_cov and nc < ncov:
            t_cov[nc] = t[k]
            put(p_cov[nc], p)
            x3_cov[nc] = x[2]
            nc += 1
            next_cov = t[k] + cov_dt
    return h_out, v_out, t_cov[:nc], p_cov[:nc], x3_cov[:nc], nu, rejected


class VKF4(VerticalEstimator):
    """Seed-004 4-state baro-inertial Kalman filter (see module docstring)."""

    name = "vkf4"
    config_class = VKF4Config
    needs_baro = True

    def solve(self, drive: Drive) -> Estimate:
        """Run the filter. Needs IMU and baro; GNSS heights are used when present."""
        cfg = self.config
        vi = vertical_inputs(drive, cfg.ahrs)
        model = sensor_model(drive)  # shared noise model (sensors.model)
        ims, bp = model.imu, model.baro
        assert bp is not None
        t = drive.imu.t
        n = t.size
        dt = np.diff(t)
        if cfg.accel_psd is not None:
            a_psd = np.full(n, cfg.accel_psd)
        else:
            a_psd = input_error_psd(
                drive, vi, ims.accel_noise_density**2
                + ims.accel_bias_sd**2 * cfg.bias_corr_s
                + cfg.input_error_psd, cfg.tilt_sd, ims.gyro_bias_sd, cfg.input_corr_s)
            if model.imu_inferred:  # the inferred vibration bias walk, as white over bias_corr_s
                a_psd = a_psd + ims.accel_bias_rw**2 * cfg.bias_corr_s**2 / 3.0
        s3 = cfg.baro_slow_sd if cfg.baro_slow_sd is not None else float(np.hypot(
            bp.bias_sd, bp.scale_sd * cfg.alt_span_m))
        tau3 = cfg.baro_slow_tau if cfg.baro_slow_tau is not None else bp.bias_tau
        r_baro = (cfg.baro_noise_sd if cfg.baro_noise_sd is not None else bp.noise_sd) ** 2
        phi3, q3 = gm_transition(dt, tau3), gm_process_var(dt, tau3, s3)
        phi4 = gm_transition(dt, cfg.baro_fast_tau)
        q4 = gm_process_var(dt, cfg.baro_fast_tau, cfg.baro_fast_sd)

        # events
        gn = drive.gnss if cfg.use_gnss else None
        tb = drive.baro.t
        ev = [(tb, np.zeros(tb.size, np.int64), drive.baro.altitude, np.full(tb.size, r_baro))]
        if gn is not None:
            g_var = model.gnss_pos_sd[:, 2] ** 2
            ev.append((gn.t, np.ones(gn.t.size, np.int64), gn.lla[:, 2], g_var))
        et = np.concatenate([e[0] for e in ev])
        ek = np.concatenate([e[1] for e in ev])
        ez = np.concatenate([e[2] for e in ev])
        evar = np.concatenate([e[3] for e in ev])
        order = np.lexsort((ek, et))
        et, ek, ez, evar = et[order], ek[order], ez[order], evar[order]
        keep = (et >= t[0]) & (et <= t[-1])
        et, ek, ez, evar = et[keep], ek[keep], ez[keep], evar[keep]
        esd = np.sqrt(evar)
        kk = np.searchsorted(t, et, side="left").astype(np.int64)
        lag = t[kk] - et

        # initial state: the last GNSS fix at or before the first IMU epoch, within 5 s (else
        # the baro sample there with the slow baro error's σ, at rest): nothing later
        i0 = initial_fix(gn, t[0])
        if i0 is not None:
            h_init, var_h = float(gn.lla[i0, 2]), float(model.gnss_pos_sd[i0, 2]) ** 2
        else:
            kb = max(int(np.searchsorted(tb, t[0], side="right")) - 1, 0)
            h_init, var_h = float(drive.baro.altitude[kb]), s3**2
        v_init = float(gn.vel_n[i0, 2]) if i0 is not None and gn.vel_n is not None else 0.0
        p0 = np.diag([var_h, 0.5**2, s3**2, cfg.baro_fast_sd**2])
        h_out, v_out, t_cov, p_cov, x3, nu, rejected = _run(
            t, vi.f_down + vi.coriolis_down, vi.lat, h_init, v_init, p0, phi3, q3, phi4, q4,
            a_psd, kk, ek, ez, evar, lag, cfg.gnss_gate_sigma**2, 1.0 / cfg.cov_rate_hz,
            et, esd, cfg.max_gnss_sd_v, cfg.gnss_probation_s,
            gap_threshold(t), GAP_ACCEL_SD**2)

        sd3 = np.sqrt(p_cov[:, 2, 2])
        baro = BaroEstimate(bias_m=ParamEstimate(float(np.mean(x3)), float(np.mean(sd3)), s3))
        return vertical_estimate(
            self.name, t, h_out, v_out, cfg, frozenset({"alt", "vel_d", "baro", "cov"}),
            cov=_to_error_state(p_cov), t_cov=t_cov, baro=baro,
            innovations={"baro": nu[(ek == 0) & np.isfinite(nu)],
                         "gnss_alt": nu[(ek == 1) & np.isfinite(nu)]},
            info={"gnss_rejected": int(rejected), "accel_psd_mean": float(np.mean(a_psd)),
                  "baro_slow_sd": s3})


def _to_error_state(p: FloatArray) -> FloatArray:
    """(M, 4, 4) -> (M, 18, 18). ERROR_STATE is estimated − true: the corrected INS error is
    (x − x̂): pos_n[2] down = −(Δh − Δĥ) → −1; vel_n[2] = +(Δv_d − Δv̂_d) → +1; the baro-error
    estimate's error is −(x₃ − x̂₃) → −1."""
    return embed_error_state(p, _TO_ERROR_STATE)


_TO_ERROR_STATE = selection((("pos_n", 2, 0, -1.0), ("vel_n", 2, 1, 1.0),
                             ("baro_bias", 0, 2, -1.0)), NX)


__all__ = ["VKF4", "VKF4Config"]
