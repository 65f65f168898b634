"""Seed 000 (Sokolović, Dikić, Stančić 2014): 3rd-order baro-inertial loop with adaptive
gain/damping coefficients (``loop3-adaptive``).

The seed text stops before its equations; the law below is designed from its abstract and
the loop literature and written out in ``docs/adaptive_loop.md``. The fixed loop (``loops``)
places a triple pole at −1/τ: k1 = 3/τ, k2 = 3/τ² + ω_s², k3 = 1/τ³. The adaptive loop keeps
that structure (so the frozen-gain loop is stable for every value) and shortens the time
constant when the loop is far from equilibrium:

    τ_eff(t) = τ / s(t),   s = 1 + (s_max − 1)·φ(x),   φ: [0, ∞) → [0, 1), φ(0) = 0,
    k1 = 3s/τ,  k2 = 3s²/τ² + ω_s²,  k3 = s³/τ³,

with x = ē/e0 (``signal="error"``: ē the low-passed loop error magnitude, time constant
T_a, ē̇ = (|e| − ē)/T_a) or x = |v̂|/v0 (``signal="vz"``: the estimated vertical speed —
vertical dynamics, where baro lag and INS errors grow). Adaptation functions φ:

- ``"linear"``: min(x, 1) (linear-saturated)
- ``"exp"``: 1 − exp(−x)
- ``"tanh"``: tanh(x)
- ``"sigmoid"``: (σ(a(x − 1)) − σ(−a)) / (1 − σ(−a)), σ the logistic, a = 4 (soft threshold
  at x = 1)
- ``"none"``: 0 (the loop is then exactly ``loop3``; tested)

Measured benefit (benchmarks/bench_adaptive.py): 1.7-3× faster settling after a baro
step; no gain in fast climbs/descents or with baro latency.

EKF with control signals (``AdaptiveConfig(ekf_control=True)``; seed 000 abstract: "the
integration is done with an EKF with control signals"; design ours, docs/adaptive_loop.md).
State x = [h − h0, v_up, c, s, b] (baro scale and bias of ``sensors.baro``, latency not
modelled). The baro stays inside the loop: the loop error is taken against the
scale/bias-corrected baro, e = ĥ − (z_b − b̂)/(1 + ŝ), and the loop correction
u = −Δt·[k1, k2, −k3]·e (adaptive gains as above) is the EKF's control input,

    x_L,k+1 = Φ x_L,k + Γ a_k + u_k,   s_{k+1} = s_k,   b_{k+1} = e^(−Δt/τ_b) b_k,
    F = [[Φ − Δt g [1,0,0],  −Δt g ∂e/∂s,  −Δt g ∂e/∂b], [0, 1, 0], [0, 0, e^(−Δt/τ_b)]],
    ∂e/∂s = (z_b − b̂)/(1+ŝ)²,  ∂e/∂b = 1/(1+ŝ),
    Q = q_a ΓΓᵀ/Δt + q_c Δt e_c e_cᵀ + σ_n² T_b Δt g gᵀ (∂e/∂b)² + σ_b²(1 − e^(−2Δt/τ_b)) e_b e_bᵀ

(the baro noise enters through the control; T_b the baro sample interval over which one
noise sample is held). GNSS altitude is the measurement, H = [1, δt, 0, 0, 0] at the fix
time t_k + δt, gated by ν² > χ²₁(1 − p_fa)·S (``info["gnss_rejected"]``); consecutive
rejections spanning ``reinit_s`` reset P to its prior (``info["gnss_cov_resets"]``). The
adaptive gains are treated as known (frozen) in F. Covariance in the ERROR_STATE layout
(pos_n[2], vel_n[2], bias_accel[2], baro_scale, baro_bias). The default stays the
baro-inertial loop (``ekf_control=False``): see docs/adaptive_loop.md for the numbers.

Causality: as ``loops`` (held baro, causal attitude reference; the EKF variant's baro
interval from the first baro samples). Altitude RMSE, hill-drive seeds 0/1/2
2.52/4.84/1.54 m, sortie seeds 0/1/2 2.71/8.86/5.57 m (2.53/4.84/1.54 and 2.67/8.85/5.55 m
with baro and fixes interpolated to the epoch, reading the next sample).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numba import njit

from ...config import REAL_LOG_BARO
from ...nav.arrays import outer, put
from ...nav.error_state import embed_error_state, selection
from ...sensors.model import sensor_model
from ...types import BaroEstimate, Drive, Estimate, ParamEstimate
from ...types.streams import FloatArray
from .base import VerticalEstimator, vertical_estimate
from .gnss_reference import nominal_interval
from .inputs import AhrsConfig
from .loops import LoopInputs, bridge_gaps, loop_inputs, zoh_nb
from .observer1d import gate_threshold

_FUNCS = {"none": 0, "linear": 1, "exp": 2, "tanh": 3, "sigmoid": 4}
_SIGNALS = {"error": 0, "vz": 1}


@dataclass(frozen=True)
class AdaptiveConfig:
    """Settings of ``loop3-adaptive`` (seed 000).

    tau : nominal triple-pole time constant [s]
    s_max : largest speed-up of the loop [-]
    function : adaptation function (module docstring)
    signal : what drives the adaptation, "error" or "vz"
    e0 : normalisation of the loop error [m]
    v0 : normalisation of the vertical speed [m/s]
    t_avg : time constant T_a of the error-magnitude low-pass [s]
    ahrs : attitude-reference gains
    ekf_control : run the EKF-with-control-signals variant (docs/adaptive_loop.md)
    gains : base gains (k1, k2, k3) [1/s, 1/s², 1/s³] (None: the triple pole at −1/τ)
    gate_prob : false-alarm probability of the χ²₁ innovation gate on GNSS (None: no gate)
    reinit_s : consecutive rejections spanning this long reset the covariance to its prior [s]
    accel_psd : vertical acceleration input noise PSD [m²/s³] (None: from the IMU spec)
    accel_bias_rw : random walk of the acceleration correction c [m/s²/√s]
    baro_noise_sd, baro_bias_sd : baro white noise and bias σ [m] (None: the stream's spec)
    baro_bias_tau, baro_scale_sd : baro bias τ [s] and scale σ [-] (None: the stream's spec)
    cov_rate_hz : rate of the stored covariances [Hz]

    The fields from ``gains`` on act in the EKF-with-control-signals variant only."""

    tau: float = 20.0
    s_max: float = 4.0
    function: str = "tanh"
    signal: str = "error"
    e0: float = 3.0
    v0: float = 5.0
    t_avg: float = 2.0
    ahrs: AhrsConfig = field(default_factory=AhrsConfig)
    ekf_control: bool = False
    # the adaptation scales the gains as k1·s, (k2 − ω_s²)·s² + ω_s², k3·s³; (0, 0, 0) removes
    # the loop (the filter is then a plain GNSS-aided vertical KF)
    gains: tuple[float, float, float] | None = None
    gate_prob: float | None = 1e-3
    # so that the gate cannot lock GNSS out forever
    reinit_s: float = 30.0
    # None: the IMU spec's accel_noise_density² (fallback 3e-3²) + 1e-4 for the
    # attitude-reference input error
    accel_psd: float | None = None
    accel_bias_rw: float = 1e-4
    # the baro model of sensors.baro; None: the baro stream's spec, else 0.5 m, 10 m, 3600 s, 0.02
    baro_noise_sd: float | None = None
    baro_bias_sd: float | None = None
    baro_bias_tau: float | None = None
    baro_scale_sd: float | None = None
    cov_rate_hz: float = 1.0

    def __post_init__(self) -> None:
        if self.function not in _FUNCS:
            raise ValueError(f"AdaptiveConfig.function: one of {sorted(_FUNCS)}")
        if self.signal not in _SIGNALS:
            raise ValueError(f"AdaptiveConfig.signal: one of {sorted(_SIGNALS)}")
        if not (self.tau > 0 and self.s_max >= 1 and self.e0 > 0 and self.v0 > 0
                and self.t_avg > 0):
            raise ValueError("AdaptiveConfig: tau, e0, v0, t_avg > 0 and s_max >= 1 required")
        if self.gate_prob is not None and not 0.0 < self.gate_prob < 1.0:
            raise ValueError("AdaptiveConfig.gate_prob: in (0, 1) or None")
        if self.gains is not None and len(self.gains) != 3:
            raise ValueError("AdaptiveConfig.gains: three gains (k1, k2, k3)")


@njit(cache=True)
def _phi(x, func):
    if func == 0:
        return 0.0
    if func == 1:
        return x if x < 1.0 else 1.0
    if func == 2:
        return 1.0 - np.exp(-x)
    if func == 3:
        return np.tanh(x)
    a = 4.0
    s0 = 1.0 / (1.0 + np.exp(a))
    return (1.0 / (1.0 + np.exp(-a * (x - 1.0))) - s0) / (1.0 - s0)


@njit(cache=True)
def adaptive_kernel(t, a_up, z_baro, tau, ws2, s_max, func, signal, e0, v0, t_avg, x0):
    """Loop-3 recursion of ``loops.loop_kernel`` (per-step Φ(Δt_k), Γ(Δt_k); NaN a_up = bridged
    gap, input c) with per-step gains Δt_k·[3s/τ, 3s²/τ² + ω_s², −s³/τ³]. Returns states
    (N, 3), loop error (N,), s (N,)."""
    n = a_up.size
    x = np.empty((n, 3))
    err = np.empty(n)
    s_out = np.empty(n)
    put(x[0], x0)
    ebar = 0.0
    dt = t[1] - t[0] if n > 1 else 1.0
    dt_prev = -1.0
    phi = np.eye(3)
    gam = np.zeros(3)
    gain_dt = np.empty(3)
    scale = 1.0  # kept for the same expression order as loop_kernel
    for k in range(n):
        e = x[k, 0] - z_baro[k]
        err[k] = e
        if k < n - 1:
            dt = t[k + 1] - t[k]
        alpha = dt / t_avg if dt < t_avg else 1.0
        ebar += alpha * (abs(e) - ebar)
        if signal == 0:
            xi = ebar / e0
        else:
            xi = abs(x[k, 1]) / v0
        s = 1.0 + (s_max - 1.0) * _phi(xi, func)
        s_out[k] = s
        if k == n - 1:
            break
        if abs(dt - dt_prev) > 1e-12 * dt:
            phi, gam = zoh_nb(dt, ws2, np.int64(3))  # int64: the loops' specialisation
            dt_prev = dt
        a = a_up[k]
        if np.isnan(a):
            a = x[k, 2]
        gain_dt[0] = 3.0 * s / tau * dt
        gain_dt[1] = (3.0 * s**2 / tau**2 + ws2) * dt
        gain_dt[2] = -(s**3 / tau**3) * dt
        for i in range(3):
            acc = gam[i] * a - scale * gain_dt[i] * e
            for j in range(3):
                acc += phi[i, j] * x[k, j]
            x[k + 1, i] = acc
    return x, err, s_out


def run_adaptive(inp: LoopInputs, cfg: AdaptiveConfig, x0=None):
    """Run the adaptive loop on prepared inputs; returns (states (N, 3), error (N,), s (N,))
    at the epochs of ``inp`` (any sampling; logging gaps bridged by ``loops.bridge_gaps``)."""
    if x0 is None:
        x0 = np.array([inp.z_baro[0], 0.0, 0.0])
    br, orig = bridge_gaps(inp)
    x, err, s = adaptive_kernel(br.t, br.a_up, br.z_baro, cfg.tau, inp.ws2, cfg.s_max,
                                _FUNCS[cfg.function], _SIGNALS[cfg.signal], cfg.e0, cfg.v0,
                                cfg.t_avg, np.asarray(x0, float))
    return x[orig], err[orig], s[orig]


# State indices of the EKF-with-control variant: h − h0, v_up, c, baro scale s, baro bias b
IH, IV, IC, IS, IB = 0, 1, 2, 3, 4
NX = 5


@njit(cache=True)
def ekf_kernel(a_up, z_baro, base_gains, ws2, s_max, func, signal, e0, v0,
               t_avg, x0, p0, q_a, q_c, r_baro_dt, q_s, tau_b, sd_b, t, t_fix, z_fix, r_fix,
               gate2, reinit_s, cov_dt):
    """Adaptive loop-3 corrections as control signals of a 5-state EKF, GNSS as measurement.

    a_up (N,) up acceleration with gravity at h0 [m/s²] (NaN: bridged gap, input c);
    z_baro (N,) baro altitude − h0 at the epochs t (N,) [m] (any spacing: the ZOH Φ(Δt_k),
    Γ(Δt_k) of the free channel and the Markov/noise terms are per step); base_gains (3,)
    (k1, k2 − ω_s², k3); x0 (5,), p0 (5, 5); q_a [m²/s³] input noise PSD; q_c [m²/s⁵] c random
    walk PSD; r_baro_dt [m²·s] = σ_baro²·T_baro (baro noise entering through the control);
    q_s [1/s] scale-state PSD; tau_b [s], sd_b [m] Markov baro bias; t (N,); t_fix, z_fix,
    r_fix (M,) GNSS times, altitudes − h0, variances; gate2 = χ²₁ threshold (inf: off).
    Returns h (N,), v (N,), s_adapt (N,), loop error (N,), cov times (K,), covs (K, 5, 5),
    x at the cov times (K, 5), GNSS codes (M,) (0 used, 1 rejected, 2 used after a
    covariance reset, −1 not reached), normalised innovations (M,).
    """
    n = a_up.size
    m = t_fix.size
    x = x0.copy()
    p = p0.copy()
    h_out = np.empty(n)
    v_out = np.empty(n)
    s_out = np.empty(n)
    e_out = np.empty(n)
    kmax = int((t[-1] - t[0]) / cov_dt) + 2
    t_cov = np.empty(kmax)
    p_cov = np.empty((kmax, NX, NX))
    x_cov = np.empty((kmax, NX))
    nc = 0
    t_next = t[0]
    code = np.full(m, -1, dtype=np.int8)
    nu = np.full(m, np.nan)
    ebar = 0.0
    dt = t[1] - t[0] if n > 1 else 1.0
    dt_prev = -1.0
    phi = np.eye(3)
    gam = np.zeros(3)
    fb = 1.0
    qb = 0.0
    j = 0
    while j < m and t_fix[j] < t[0]:
        j += 1
    n_rej = 0
    t_rej0 = 0.0
    f = np.eye(NX)
    q = np.zeros((NX, NX))
    g = np.empty(3)
    for k in range(n):
        # GNSS fixes in [t_k, t_{k+1}): predicted height at the fix h + v·δt, H = [1, δt, 0..]
        while j < m and (k == n - 1 or t_fix[j] < t[k + 1]):
            if t_fix[j] > t[k] + 1.0:  # beyond the data (should not happen) — stop
                break
            d = t_fix[j] - t[k]
            hrow = np.zeros(NX)
            hrow[IH] = 1.0
            hrow[IV] = d
            ph = p @ hrow
            sv = hrow @ ph + r_fix[j]
            innov = z_fix[j] - (x[IH] + d * x[IV])
            nu[j] = innov / np.sqrt(sv)
            if innov * innov > gate2 * sv:
                if n_rej == 0:
                    t_rej0 = t_fix[j]
                n_rej += 1
                code[j] = 1
                if n_rej >= 2 and t_fix[j] - t_rej0 >= reinit_s:
                    # persistent disagreement: forget (covariance back to the prior) and let
                    # the next fix in
                    p = p0.copy()
                    n_rej = 0
                    code[j] = 2
                j += 1
                continue
            n_rej = 0
            code[j] = 0
            kg = ph / sv
            x += kg * innov
            ikh = np.eye(NX) - outer(kg, hrow)
            p = ikh @ p @ ikh.T + r_fix[j] * outer(kg, kg)  # Joseph form
            j += 1
        if k < n - 1:
            dt = t[k + 1] - t[k]
        if abs(dt - dt_prev) > 1e-12 * dt:
            phi, gam = zoh_nb(dt, ws2, np.int64(3))  # int64: the loops' specialisation
            fb = np.exp(-dt / tau_b)
            qb = sd_b * sd_b * (1.0 - fb * fb)
            dt_prev = dt
        alpha = dt / t_avg if dt < t_avg else 1.0
        # loop error against the bias/scale-corrected baro, adaptation as adaptive_kernel
        denom = 1.0 + x[IS]
        zc = (z_baro[k] - x[IB]) / denom
        e = x[IH] - zc
        e_out[k] = e
        ebar += alpha * (abs(e) - ebar)
        xi = ebar / e0 if signal == 0 else abs(x[IV]) / v0
        sa = 1.0 + (s_max - 1.0) * _phi(xi, func)
        s_out[k] = sa
        h_out[k] = x[IH]
        v_out[k] = x[IV]
        if t[k] >= t_next - 1e-9:
            t_cov[nc] = t[k]
            p_cov[nc] = p
            x_cov[nc] = x
            nc += 1
            t_next += cov_dt
        if k == n - 1:
            break
        g[0] = base_gains[0] * sa
        g[1] = base_gains[1] * sa * sa + ws2
        g[2] = -base_gains[2] * sa * sa * sa
        # nominal: x_L ← Φ x_L + Γ a − Δt·g·e (the control signal), b Markov, s constant
        a_k = a_up[k]
        if np.isnan(a_k):
            a_k = x[IC]
        xl = phi @ x[:3] + gam * a_k - dt * g * e
        x[0] = xl[0]
        x[1] = xl[1]
        x[2] = xl[2]
        x[IB] *= fb
        # error transition: δx_L ← (Φ − Δt g [1,0,0]) δx_L − Δt g (∂e/∂s δs + ∂e/∂b δb)
        f[:] = 0.0
        f[:3, :3] = phi
        dedh = 1.0
        deds = zc / denom
        dedb = 1.0 / denom
        for i in range(3):
            f[i, IH] -= dt * g[i] * dedh
            f[i, IS] = -dt * g[i] * deds
            f[i, IB] = -dt * g[i] * dedb
        f[IS, IS] = 1.0
        f[IB, IB] = fb
        q[:] = 0.0
        # input noise through Γ (white, PSD q_a), c random walk, baro noise via the control
        for i in range(3):
            for ii in range(3):
                q[i, ii] = (q_a * gam[i] * gam[ii] / dt
                            + r_baro_dt * dt * g[i] * g[ii] * dedb * dedb)
        q[IC, IC] += q_c * dt
        q[IS, IS] = q_s * dt
        q[IB, IB] = qb
        p = f @ p @ f.T + q
    return (h_out, v_out, s_out, e_out, t_cov[:nc], p_cov[:nc], x_cov[:nc], code, nu)


def _spec(obj, name: str, default: float) -> float:
    v = getattr(obj, name, None) if obj is not None else None
    return float(v) if v is not None else default


def run_adaptive_ekf(inp: LoopInputs, cfg: AdaptiveConfig, t_fix, z_fix, r_fix, *,
                     imu_spec=None, baro_spec=None, baro_dt: float = 0.04):
    """Run the EKF-with-control variant on prepared inputs. t_fix, z_fix (altitude − h0),
    r_fix (variances) (M,) GNSS. Returns the tuple of ``ekf_kernel`` with the per-epoch
    arrays at the epochs of ``inp`` (any sampling; gaps bridged by ``loops.bridge_gaps``)."""
    br, orig = bridge_gaps(inp)
    if cfg.gains is None:
        base = np.array([3.0 / cfg.tau, 3.0 / cfg.tau**2, 1.0 / cfg.tau**3])
    else:
        base = np.array([cfg.gains[0], cfg.gains[1] - inp.ws2, cfg.gains[2]])
    q_a = (cfg.accel_psd if cfg.accel_psd is not None
           else _spec(imu_spec, "accel_noise_density", 3e-3) ** 2 + 1e-4)
    sd_n = cfg.baro_noise_sd if cfg.baro_noise_sd is not None else _spec(
        baro_spec, "noise_sd", REAL_LOG_BARO.noise_sd)
    sd_b = cfg.baro_bias_sd if cfg.baro_bias_sd is not None else _spec(
        baro_spec, "bias_sd", REAL_LOG_BARO.bias_sd)
    tau_b = cfg.baro_bias_tau if cfg.baro_bias_tau is not None else _spec(
        baro_spec, "bias_tau", REAL_LOG_BARO.bias_tau)
    sd_s = cfg.baro_scale_sd if cfg.baro_scale_sd is not None else _spec(
        baro_spec, "scale_sd", REAL_LOG_BARO.scale_sd)
    x0 = np.array([inp.z_baro[0], 0.0, 0.0, 0.0, 0.0])
    # prior: height from the (biased) baro, v at rest ±1 m/s, c ±0.1 m/s², s, b from the spec
    p0 = np.diag([sd_b**2 + sd_n**2, 1.0, 0.1**2, sd_s**2, sd_b**2])
    p0[IH, IB] = p0[IB, IH] = -sd_b**2  # h0 = z_baro = h + b: δh = −δb initially
    p0[IH, IH] = sd_b**2 + sd_n**2
    out = ekf_kernel(
        br.a_up, br.z_baro, base, inp.ws2, cfg.s_max, _FUNCS[cfg.function],
        _SIGNALS[cfg.signal], cfg.e0, cfg.v0, cfg.t_avg, x0, p0, q_a, cfg.accel_bias_rw**2,
        sd_n**2 * baro_dt, 0.0, tau_b, sd_b, br.t, np.asarray(t_fix, float),
        np.asarray(z_fix, float), np.asarray(r_fix, float), gate_threshold(cfg.gate_prob),
        cfg.reinit_s, 1.0 / cfg.cov_rate_hz)
    h, v, s, e = (a[orig] for a in out[:4])
    return (h, v, s, e) + tuple(out[4:])


# ERROR_STATE rows (estimated − true = +δx): pos_n[2] down = −δh, vel_n[2] down = −δv,
# bias_accel[2] (body z ≈ down for a near-level IMU) = −δc, baro_scale = +δs, baro_bias = +δb
_TO_ERROR_STATE = selection((("pos_n", 2, IH, -1.0), ("vel_n", 2, IV, -1.0),
                             ("bias_accel", 2, IC, -1.0), ("baro_scale", 0, IS, 1.0),
                             ("baro_bias", 0, IB, 1.0)), NX)


def to_error_state(p: FloatArray) -> FloatArray:
    """(M, 5, 5) filter covariances -> (M, 18, 18) ERROR_STATE layout, NaN where absent."""
    return embed_error_state(p, _TO_ERROR_STATE)


class AdaptiveLoop3(VerticalEstimator):
    """3rd-order baro-inertial loop with adaptive coefficients (``loop3-adaptive``)."""

    name = "loop3-adaptive"
    config_class = AdaptiveConfig
    needs_baro = True

    def solve(self, drive: Drive) -> Estimate:
        cfg = self.config
        inp = loop_inputs(drive, cfg.ahrs)
        if cfg.ekf_control:
            return self._run_ekf(drive, inp)
        x, err, s = run_adaptive(inp, cfg)
        # baro-inertial: GNSS only reaches the attitude reference (vertical.inputs), never the
        # height channel, so no GNSS is gated and no gnss_rejected is claimed
        return vertical_estimate(self.name, inp.t, x[:, 0] + inp.h0, -x[:, 1], cfg,
                                 info={"uses": "imu+baro", "speedup_mean": float(np.mean(s)),
                                       "speedup_max": float(np.max(s)),
                                       "accel_bias_up_final": float(x[-1, 2])})

    def _run_ekf(self, drive: Drive, inp: LoopInputs) -> Estimate:
        cfg = self.config
        model = sensor_model(drive)
        gn = drive.gnss
        if gn is None or len(gn) == 0:
            t_fix, z_fix, r_fix = np.empty(0), np.empty(0), np.empty(0)
        else:
            t_fix, z_fix = gn.t, gn.lla[:, 2] - inp.h0
            r_fix = model.gnss_pos_sd[:, 2] ** 2
        # the baro's nominal interval from its first samples (causal)
        bdt = nominal_interval(drive.baro.t) if len(drive.baro) > 1 else 0.04
        # the shared sensor model (sensors.model): IMU noise, baro noise/bias/scale priors
        # (this loop has no latency state, by the seed paper's design)
        h, v, s, err, t_cov, p_cov, x_cov, code, nu = run_adaptive_ekf(
            inp, cfg, t_fix, z_fix, r_fix, imu_spec=model.imu, baro_spec=model.baro,
            baro_dt=bdt)
        xs = x_cov[-1] if len(x_cov) else np.full(NX, np.nan)
        ps = p_cov[-1] if len(p_cov) else np.full((NX, NX), np.nan)
        p0 = p_cov[0] if len(p_cov) else ps
        baro = BaroEstimate(
            scale=ParamEstimate(float(xs[IS]), float(np.sqrt(ps[IS, IS])),
                                float(np.sqrt(p0[IS, IS]))),
            bias_m=ParamEstimate(float(xs[IB]), float(np.sqrt(ps[IB, IB])),
                                 float(np.sqrt(p0[IB, IB]))))
        return vertical_estimate(
            self.name, inp.t, h + inp.h0, -v, cfg, frozenset({"alt", "vel_d", "baro", "cov"}),
            cov=to_error_state(p_cov), t_cov=t_cov, baro=baro,
            innovations={"gnss_alt": nu[np.isfinite(nu)]},
            info={"uses": "imu+baro+gnss", "variant": "ekf_control",
                  "gnss_rejected": int(np.sum(code >= 1)),
                  "gnss_cov_resets": int(np.sum(code == 2)),
                  "speedup_mean": float(np.mean(s)), "speedup_max": float(np.max(s)),
                  "accel_bias_up_final": float(xs[IC])})
