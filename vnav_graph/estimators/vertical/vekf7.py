"""Seed 001: 7-state vertical-channel EKF with barometer scale, latency and bias.

State (error state x = true − nominal, closed-loop: after every update the estimate is added
to the nominal and x is reset to zero)::

    x = [δh_i, δv_z, B_z^a, K_z^a, dSF, Td, δh_b]     (+ an auxiliary accumulator, below)

δh_i [m] and δv_z [m/s] are the errors of the INS height and vertical speed (+up), B_z^a
[m/s²] and K_z^a [-] the body-z accelerometer bias and scale factor, dSF [-] and Td [s] the
baro scale-factor error and latency, δh_b [m] the baro Gauss-Markov bias b(t). Seed 001
eq. 5 (z up)::

    δḣ_i = δv_z
    δv̇_z = (−ρ_E² − ρ_N² + 2g/(R0 + h_i))·δh_i + C33·B_z^a + C33·F_z·K_z^a + w

with ρ the transport rate, C33 = C_nb[2, 2], F_z the measured body-z specific force (FRD: ≈ −g
at rest). With x = true − nominal and the nominal specific force corrected as
f_z − B̂_z − K̂_z·f_z, the signs of eq. 5 hold exactly as printed. B_z^a is a first-order
Gauss-Markov process plus a random walk (absorbs the other-axis and attitude errors that also
enter the vertical specific force), K_z^a, dSF and Td are random constants, and δh_b is the
Gauss-Markov baro bias with the exact discrete transition of ``vnav_graph.sensors.noise``.

Nominal INS vertical channel (the "INS" of the seed; inputs from
``vertical.inputs.vertical_inputs``, a GNSS-aided attitude reference, never truth)::

    dv_D/dt = f_D − C33·(B̂_z + K̂_z·F_z) + g(lat, h) + cor_D,    dh/dt = −v_D

with WGS-84 normal gravity at the filter's own height (the 2g/R feedback of eq. 5).

Measurements (seed 001 eq. 6, through the package's one baro model)::

    baro:  h_b = baro_predict(h, v_up, dSF, Td, b, h0) + v,
           H = [∂h_b/∂h, ∂h_b/∂v_up, 0, 0, ∂h_b/∂s, ∂h_b/∂τ, ∂h_b/∂b]  (``baro_row``)
    GNSS height:  h_G = h + v_G,             H = [1 0 0 0 0 0 0]
    GNSS vertical velocity (if given):  −v_D,G = v_up + v_V,  H = [0 1 0 0 0 0 0]

Seed 001's H = [1 0 0 0 −h v −1] is the same row for z = h_i − h_b with the opposite sign
convention of the states. GNSS measurements are gated at ``gnss_gate_sigma`` (rejected fixes
are counted in ``info["gnss_rejected"]``); during GNSS outages only the baro updates.

Reported baro errors (``Estimate.baro``): the final dSF and Td with their posterior σ and
prior σ (``ParamEstimate.observable`` judges observability), and the time average of b(t)
over the drive. The latter uses an accumulator state I = ∫ b dt (İ = b; no effect on the seven
states' estimates because it is never measured): its final filtered value is conditioned on
all data, so Î(T)/T and √P_II/T are the smoothed time average and its σ.

The covariance is returned in the shared ``ERROR_STATE`` layout (estimated − true): pos_n[2]
(down), vel_n[2] (down), bias_accel[2] (B_z), baro_scale, baro_latency, baro_bias; every
other row/column NaN (K_z has no slot there).

Known limitations (measured): on the sortie (industrial IMU) the 2-dof NEES is ≈ 1.4-1.9 and
scale/latency/bias z-scores are within ±2; on the hill-drive with the consumer IMU the latency
is over-estimated by ≈ 2.2-2.9 σ on 4 of 4 seeds (with a noiseless IMU it is not: the
attitude-reference f_D errors correlate with grade changes). Without GNSS velocity the
attitude reference's f_D is wrong by ≈ 1 m/s² on the hill-drive and this filter diverges
(NEES in the hundreds): it needs a receiver that reports velocity.

Causality: the answer is the online answer; measurements are processed at the first IMU
epoch at or after their stamp, the inputs come from the causal attitude reference
(step 9 of docs/vertical_loops.md §1), the transport-rate term from the last fix's velocity, held
(``vekf7_setup.transport_rate2``), and the filter starts from the last fix at or before its
first epoch (``vekf7_setup.initial_fix``; else the baro there with the bias prior).
Altitude RMSE, hill-drive seeds 0/1/2: 0.493/0.222/0.178 m; sortie seeds 0/1/2:
0.384/0.455/0.438 m (0.492/0.217/0.190 and 0.367/0.461/0.423 m when the inputs are
interpolated toward the next fix and the filter starts from the first fix, 0.1-0.5 s after
the first epoch on these drives). ``benchmarks/reproduce_seeds.py --quick``: seed-001 RMSE
0.457 m against 0.389 m that way.

References: seed 001 §3.2 (eqs. 5-6); Groves 2nd ed. §14.2 (closed-loop error-state KF).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np
from numba import njit

from ...geo.earth import gravity_scalar, radii_scalar
from ...nav.arrays import outer, put
from ...nav.error_state import embed_error_state, selection
from ...nav.gaps import GAP_ACCEL_SD, cv_bridge_noise, gap_threshold
from ...nav.gnss_gate import NO_LIMIT, REFUSE, height_gate, new_gate_state
from ...sensors.baro import baro_predict, baro_row
from ...sensors.model import SensorModel, sensor_model
from ...types import BaroEstimate, Drive, Estimate, ParamEstimate
from ...types.streams import FloatArray
from ..checks import with_prior_conflict_notes
from .base import VerticalEstimator, vertical_estimate
from .inputs import AhrsConfig, VerticalInputs, vertical_inputs
from .vekf7_setup import (
    IB,
    IBB,
    IH,
    II,
    IK,
    IS,
    ITD,
    IV,
    NX,
    Noise,
    initial_state,
    lever_arm_dz,
    measurement_events,
    noise_densities,
    transport_rate2,
)


@dataclass(frozen=True)
class VEKF7Config:
    """Tuning of the 7-state vertical EKF. From ``accel_bias_sd`` on, ``None`` takes the drive's
    shared sensor model (``sensors.model``, the values ekf and the graphs use).

    accel_psd : vertical specific-force white-noise PSD [(m/s²)²/Hz] (None: from the IMU spec)
    input_error_psd : floor PSD of the attitude-reference error in f_D [(m/s²)²/Hz]
    tilt_sd, input_corr_s : AHRS tilt σ with GNSS [rad] and correlation time of its f_D error [s]
    accel_bias_sd, accel_bias_tau : Gauss-Markov σ [m/s²] and τ [s] of B_z
    accel_bias_rw : random walk floor of B_z [m/s²/√s]
    accel_scale_sd : prior σ of K_z [-]
    baro_scale_sd : prior σ of dSF [-]
    baro_latency_mean, baro_latency_sd : prior mean and σ of Td [s]
    baro_bias_sd, baro_bias_tau : σ [m] and τ [s] of the baro Gauss-Markov bias
    baro_noise_sd : white baro noise [m]
    use_gnss_velocity : use the GNSS vertical velocity when the receiver gives it
    gnss_gate_sigma : reject GNSS innovations beyond this many σ
    max_gnss_sd_v, gnss_probation_s : GNSS σ_v limit [m]; consistent span to reuse heights [s]
    cov_rate_hz : rate at which covariances are stored in the Estimate [Hz]
    ahrs : attitude-reference gains for ``vertical_inputs``
    """

    # keys of earlier versions: a --config file that uses one is told the new name
    RENAMED: ClassVar[dict[str, str]] = {
        "scale_prior_sd": "baro_scale_sd", "latency_prior": "baro_latency_mean",
        "latency_prior_sd": "baro_latency_sd", "bias_prior_sd": "baro_bias_sd",
        "bias_tau": "baro_bias_tau"}
    # None: the IMU spec's noise density² + input_error_psd
    accel_psd: float | None = None
    # measured on the sortie scenario (industrial IMU): with GNSS the AHRS makes f_D err by
    # ≈ 2 mm/s² rms with ≈ 10 s correlation, PSD ≈ 2σ²τ ≈ 1e-4; without it the
    # vertical-velocity NEES is ≈ 2.5× too large
    input_error_psd: float = 1e-4
    # the manoeuvre-dependent part of the f_D error (see input_error_psd)
    tilt_sd: float = 5e-4
    input_corr_s: float = 20.0
    accel_bias_sd: float | None = None
    accel_bias_tau: float | None = None
    # for other-axis, attitude and Coriolis errors of the vertical specific force (not in
    # eq. 5's state); the shared model's (vibration) walk when larger
    accel_bias_rw: float = 2e-4
    accel_scale_sd: float | None = None
    baro_scale_sd: float | None = None
    baro_latency_mean: float | None = None
    baro_latency_sd: float | None = None
    baro_bias_sd: float | None = None
    baro_bias_tau: float | None = None
    baro_noise_sd: float | None = None
    use_gnss_velocity: bool = True
    gnss_gate_sigma: float = 5.0
    # GNSS heights with σ_v above max_gnss_sd_v are not used; after two consecutive refusals a
    # height is used again only after gnss_probation_s of consistent fixes
    # (nav.gnss_gate.height_gate). IMU logging gaps (nav.gaps) are bridged at constant vertical
    # velocity with the shared unknown acceleration GAP_ACCEL_SD [m/s²/√s].
    max_gnss_sd_v: float = 15.0
    gnss_probation_s: float = 10.0
    cov_rate_hz: float = 1.0
    ahrs: AhrsConfig | None = None


@njit(cache=True)
def propagate(k0, k1, t, f_down, g_lat, c33, f_z, cor, rho2, phi_b, q_b, phi_ab, q_ab,
               q_acc, gap_dt, gap_q, nom, p, h_out, v_out):
    """Propagate nominal and covariance from IMU epoch k0 to k1 (trapezoid; Φ = I + F·dt).

    An IMU step longer than ``gap_dt`` (logging gap) is bridged at constant vertical velocity
    with the unknown vertical acceleration PSD ``gap_q`` [(m/s²)²/Hz] added (q·dt to v_z,
    q·dt³/3 to h, q·dt²/2 cross), not integrated from its end samples."""
    for k in range(k0, k1):
        dt = t[k + 1] - t[k]
        h, v = nom[IH], nom[IV]
        bz, kz = nom[IB], nom[IK]
        if dt > gap_dt:
            nom[IH] = h + v * dt
            b_old = nom[IBB]
            nom[IBB] = phi_b[k] * b_old
            nom[II] += 0.5 * (b_old + nom[IBB]) * dt
            nom[IB] = phi_ab[k] * bz
            f = np.eye(NX)
            f[IH, IV] = dt
            f[IB, IB] = phi_ab[k]
            f[IBB, IBB] = phi_b[k]
            f[II, IBB] = dt
            put(p[:, :], f @ p @ f.T)
            q_hh, q_hv, q_vv = cv_bridge_noise(gap_q, dt)
            p[IH, IH] += q_hh
            p[IH, IV] += q_hv
            p[IV, IH] += q_hv
            p[IV, IV] += q_vv
            p[IB, IB] += q_ab[k]
            p[IBB, IBB] += q_b[k]
            h_out[k + 1] = nom[IH]
            v_out[k + 1] = v
            continue
        a0 = -(f_down[k] - c33[k] * (bz + kz * f_z[k]) + gravity_scalar(g_lat[k], h) + cor[k])
        h_p = h + v * dt
        a1 = -(f_down[k + 1] - c33[k + 1] * (bz + kz * f_z[k + 1])
               + gravity_scalar(g_lat[k + 1], h_p) + cor[k + 1])
        v_new = v + 0.5 * (a0 + a1) * dt
        h_new = h + 0.5 * (v + v_new) * dt
        b_old = nom[IBB]
        nom[IBB] = phi_b[k] * b_old
        nom[II] += 0.5 * (b_old + nom[IBB]) * dt
        nom[IB] = phi_ab[k] * bz
        nom[IH], nom[IV] = h_new, v_new
        # error dynamics, seed 001 eq. 5
        g = gravity_scalar(g_lat[k], h)
        rn, re = radii_scalar(g_lat[k])  # R0 = √(R_N·R_E), Gaussian mean radius
        f = np.eye(NX)
        f[IH, IV] = dt
        f[IV, IH] = (-rho2[k] + 2.0 * g / (np.sqrt(rn * re) + h)) * dt
        f[IV, IB] = c33[k] * dt
        f[IV, IK] = c33[k] * f_z[k] * dt
        f[IB, IB] = phi_ab[k]
        f[IBB, IBB] = phi_b[k]
        f[II, IBB] = dt
        put(p[:, :], f @ p @ f.T)
        p[IV, IV] += q_acc[k] * dt
        p[IB, IB] += q_ab[k]
        p[IBB, IBB] += q_b[k]
        h_out[k + 1] = h_new
        v_out[k + 1] = v_new


@njit(cache=True)
def scalar_update(nom, p, hrow, r, var_r):
    """Scalar closed-loop update (Joseph form). Returns the normalised innovation."""
    ph = p @ hrow
    s = hrow @ ph + var_r
    k = ph / s
    nom += k * r
    a = np.eye(NX) - outer(k, hrow)
    put(p[:, :], a @ p @ a.T + var_r * outer(k, k))
    return r / np.sqrt(s)


def _innovation_var(p: FloatArray, hrow: FloatArray, var_r: float) -> float:
    return float(hrow @ p @ hrow + var_r)


@dataclass
class _Pass:
    """What the filter pass produces: heights / vertical speeds (+up) at every IMU epoch, the
    covariance samples, the normalised innovations and the count of refused GNSS heights."""

    h: FloatArray
    v: FloatArray
    t_cov: list[float]
    p_cov: list[FloatArray]
    innov: dict[str, list[float]]
    rejected: int


def _gnss_update(nom: FloatArray, p: FloatArray, gate: FloatArray, t_m: float, i: int,
                 h_m: float, lever_dz: float, drive: Drive, g_psd: FloatArray,
                 g_vsd: FloatArray | None, cfg: VEKF7Config, out: _Pass) -> None:
    """GNSS height through the shared probation gate, then (if used) its vertical velocity."""
    gn = drive.gnss
    assert gn is not None
    hz = np.zeros(NX)
    hz[IH] = 1.0
    var_r = float(g_psd[i, 2]) ** 2
    r = float(gn.lla[i, 2]) - (h_m + lever_dz)
    if height_gate(gate, t_m, float(g_psd[i, 2]) <= cfg.max_gnss_sd_v,
                   r * r, _innovation_var(p, hz, var_r), cfg.gnss_gate_sigma**2,
                   cfg.gnss_probation_s, NO_LIMIT, 0.0, False) == REFUSE:
        out.rejected += 1
        return
    out.innov["gnss_alt"].append(scalar_update(nom, p, hz.copy(), r, var_r))
    if cfg.use_gnss_velocity and gn.vel_n is not None and g_vsd is not None:
        hz[:] = 0.0
        hz[IV] = 1.0
        var_v = float(g_vsd[i, 2]) ** 2
        rv = -float(gn.vel_n[i, 2]) - nom[IV]
        if rv**2 <= cfg.gnss_gate_sigma**2 * _innovation_var(p, hz, var_v):
            out.innov["gnss_vel"].append(scalar_update(nom, p, hz.copy(), rv, var_v))


def _filter_pass(drive: Drive, vi: VerticalInputs, model: SensorModel, nz: Noise,
                 nom: FloatArray, p: FloatArray, cfg: VEKF7Config) -> _Pass:
    """Propagate through the IMU epochs and update at each event (module docstring); ``nom``
    and ``p`` end as the final state."""
    assert drive.baro is not None
    g_psd, g_vsd = model.gnss_pos_sd, model.gnss_vel_sd
    t = drive.imu.t
    n = t.size
    h0 = float(drive.origin_lla[2])
    baro_alt = drive.baro.altitude
    et, ek, ei, kk = measurement_events(drive)
    lever_dz = lever_arm_dz(drive, vi)
    out = _Pass(np.empty(n), np.empty(n), [], [],
                {"baro": [], "gnss_alt": [], "gnss_vel": []}, 0)
    h_out, v_out = out.h, out.v
    h_out[0], v_out[0] = nom[IH], nom[IV]
    cov_dt = 1.0 / cfg.cov_rate_hz
    k_cur = 0
    next_cov = t[0]
    hz = np.zeros(NX)
    args = (t, vi.f_down, vi.lat, vi.c33, vi.f_z_b, vi.coriolis_down,
            transport_rate2(drive, vi), nz.phi_b, nz.q_b, nz.phi_ab, nz.q_ab, nz.q_acc,
            gap_threshold(t), GAP_ACCEL_SD**2)
    gate = new_gate_state()
    for j in range(et.size):
        k = int(kk[j])
        if k > k_cur:
            propagate(k_cur, k, *args, nom, p, h_out, v_out)
            k_cur = k
        lag = t[k] - et[j]  # evaluate the model at the measurement stamp
        h_m = nom[IH] - nom[IV] * lag
        if ek[j] == 0:
            i = int(ei[j])
            z = float(baro_alt[i])
            zhat = baro_predict(h_m, nom[IV], nom[IS], nom[ITD], nom[IBB], h0)
            jac = baro_row(h_m, nom[IV], nom[IS], nom[ITD], h0)
            hz[:] = 0.0
            hz[IH], hz[IV], hz[IS], hz[ITD], hz[IBB] = jac
            out.innov["baro"].append(scalar_update(nom, p, hz.copy(), z - zhat, nz.r_baro))
        else:
            assert g_psd is not None
            _gnss_update(nom, p, gate, float(et[j]), int(ei[j]), h_m, float(lever_dz[k]),
                         drive, g_psd, g_vsd, cfg, out)
        h_out[k], v_out[k] = nom[IH], nom[IV]
        if t[k] >= next_cov:
            out.t_cov.append(float(t[k]))
            out.p_cov.append(p.copy())
            next_cov = t[k] + cov_dt
    if k_cur < n - 1:
        propagate(k_cur, n - 1, *args, nom, p, h_out, v_out)
    if out.t_cov and out.t_cov[-1] >= t[-1]:  # the last epoch holds the final covariance
        out.t_cov.pop()
        out.p_cov.pop()
    out.t_cov.append(float(t[-1]))
    out.p_cov.append(p.copy())
    return out


class VEKF7(VerticalEstimator):
    """Seed-001 7-state vertical EKF (see module docstring)."""

    name = "vekf7"
    config_class = VEKF7Config
    needs_baro = True

    def solve(self, drive: Drive) -> Estimate:
        """Run the filter over the drive. Needs IMU and baro; GNSS optional but expected."""
        cfg = self.config
        vi: VerticalInputs = vertical_inputs(drive, cfg.ahrs)
        model = sensor_model(drive)  # shared with ekf and the graphs (sensors.model)
        nz = noise_densities(drive, vi, model, cfg)
        nom, p = initial_state(drive, model.gnss_pos_sd, nz)
        res = _filter_pass(drive, vi, model, nz, nom, p, cfg)

        t = drive.imu.t
        dur = float(t[-1] - t[0])
        baro = BaroEstimate(
            scale=ParamEstimate(float(nom[IS]), float(np.sqrt(p[IS, IS])), nz.scale_sd, 0.0),
            latency_s=ParamEstimate(float(nom[ITD]), float(np.sqrt(p[ITD, ITD])), nz.latency_sd,
                                    nz.latency_mean),
            bias_m=ParamEstimate(float(nom[II] / dur), float(np.sqrt(p[II, II]) / dur),
                                 nz.b_sd),
        )
        info = {
            "gnss_rejected": res.rejected,
            "accel_bias_z": float(nom[IB]),
            "accel_bias_z_sd": float(np.sqrt(p[IB, IB])),
            "accel_scale_z": float(nom[IK]),
            "accel_scale_z_sd": float(np.sqrt(p[IK, IK])),
            "baro_bias_final": float(nom[IBB]),
        }
        return with_prior_conflict_notes(vertical_estimate(
            self.name, t, res.h, -res.v, cfg, frozenset({"alt", "vel_d", "baro", "cov"}),
            cov=_to_error_state(np.array(res.p_cov)), t_cov=np.array(res.t_cov), baro=baro,
            innovations={k: np.asarray(v) for k, v in res.innov.items()}, info=info))


# ERROR_STATE rows (estimated − true = −x): pos_n[2] down = −h → +δh_i; vel_n[2] = −v_up →
# +δv_z; bias_accel[2] = −B_z; baro_scale, baro_latency, baro_bias = −(dSF, Td, δh_b).
_TO_ERROR_STATE = selection((("pos_n", 2, IH, 1.0), ("vel_n", 2, IV, 1.0),
                             ("bias_accel", 2, IB, -1.0), ("baro_scale", 0, IS, -1.0),
                             ("baro_latency", 0, ITD, -1.0), ("baro_bias", 0, IBB, -1.0)), NX)


def _to_error_state(p: FloatArray) -> FloatArray:
    """(M, 8, 8) filter covariances -> (M, 18, 18) ERROR_STATE layout, NaN where absent."""
    return embed_error_state(p, _TO_ERROR_STATE)


__all__ = ["VEKF7", "VEKF7Config"]
