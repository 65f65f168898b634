"""Seed 003: one-degree-of-freedom vertical inertial unit aided by GPS altitude (``observer1d``).

State (up form) x = [z, v, c]: altitude [m, +up], vertical velocity [m/s, +up] and an additive
acceleration correction c [m/s²] (c = −b_a,up: minus the accelerometer bias along the up axis),

    ż = v,   v̇ = a_up + c,   ċ = 0,    A = [[0, 1, 0], [0, 0, 1], [0, 0, 0]],

with the measured vertical acceleration a_up = −(f_D + g(lat, h) + cor_D) from
``vertical.inputs.vertical_inputs``. Between GPS fixes the state is propagated at the IMU rate;
at each fix (every T = 1 s in seed 003) the fixed-gain observer correction is applied:

    x̂⁺ = x̂⁻ + L (z̃_gps − ẑ⁻),   L = [0.4, 0.04, 0.002]ᵀ

(seed 003 writes it in error form, δx⁺ = δx⁻ − L·δy). The error dynamics at the GPS rate are
e⁺_{k+1} = (I − L H) (Φ e⁺_k + w_k) + L ν_k, Φ = exp(A T) = [[1, T, T²/2], [0, 1, T], [0, 0, 1]],
with closed-loop eigenvalues 0.671 and 0.9438 ± 0.0541j (|λ| = 0.9454, time constant
≈ 18 samples).

Discretisation (``ObserverConfig.discretisation``):

- ``"zoh"`` — analytic zero-order hold, exp(A h) with the input held over the step:
  z ← z + v h + u_k h²/2, v ← v + u_k h (u = a + c);
- ``"tustin"`` — bilinear (trapezoidal) discretisation of the double integrator 1/s²:
  v' = v + (u_k + u_{k+1}) h/2, z ← z + (v + v') h/2.

A is nilpotent, so the Tustin transition matrix (I − Ah/2)⁻¹(I + Ah/2) equals exp(A h)
exactly; the two differ only in how the input enters (held sample vs trapezoid: ZOH lags by
h/2). With the 100 Hz IMU of the seed003 scenario the INS-only altitudes differ by millimetres
and the steady-state σ by < 1 % (measured by
``vnav_graph.studies.seed003.compare_discretisations``).

Steady state. ``steady_state`` solves the discrete Lyapunov equation of the closed loop driven
by the GPS noise (R = σ_gps²) and the accelerometer noise (white, root PSD q_a, plus a bias
random walk q_b): P⁺ = A_cl P⁺ A_clᵀ + (I−LH) Q (I−LH)ᵀ + L R Lᵀ, A_cl = (I − LH) Φ,
Q = q_a² [[T³/3, T²/2, 0], [T²/2, T, 0], [0, 0, 0]] + q_b² [[T⁵/20, T⁴/8, T³/6], [.., T³/3,
T²/2], [.., .., T]]. With σ_gps = 2 m and the consumer accelerometer (300 µg/√Hz) it gives
σ⁺ = 1.06 m just after a fix, σ⁻ = 1.16 m just before one, and a time-averaged σ of the
continuous (IMU-rate) output of ≈ 1.11 m — the seed's "final value near 1.2 m" against the
2 m of GPS alone. The exact 1.2 m time average needs an accelerometer noise density of
≈ 0.095 m/s²/√Hz (≈ 9.7 mg/√Hz, ``seed003_noise_for_sigma``), 32× the MPU-9250 datasheet; the
seed's script (not available) presumably used such a noisy or a coarser INS. We report the
consumer-noise value and state the difference.

Settling (``seed003_monte_carlo``): t_s is the time from the first fix to the last fix at
which the ensemble-mean altitude error of runs started with a common accelerometer-bias
estimation error (all else zero-mean) exceeds 10 % of its peak absolute value. It measures
the decay of the slowest closed-loop mode as excited by the bias, the error the observer must
learn; analytically |[A_cl^k]_{0,2}| gives t_s = 49 samples (seed 003: "around 50 samples").
The 10 % level sits above the 4.6 % undershoot of the oscillatory mode (a 5 % level would be
decided by that undershoot and by Monte Carlo noise). The transient is linear in the initial
bias error, so the Monte Carlo uses a large one (2 m/s², peak ≈ 22 m) to keep the ensemble
mean's noise (σ/√n ≈ 0.08 m for 200 runs) far below the 10 % level.

GNSS gating (not in seed 003, which assumes clean GPS). A fix whose
innovation δy = z̃_gps − ẑ⁻ satisfies δy² > k²·S(τ) is rejected (not applied, counted in
``Estimate.info["gnss_rejected"]``), with k² = χ²₁(1 − p_fa) (``gate_prob`` = p_fa, default
10⁻³: k = 3.29) and S(τ) = [Φ(τ) P⁺ Φ(τ)ᵀ + Q(τ)]₀₀ + σ_gps² the innovation variance of the
fixed-gain loop τ seconds after its last *accepted* fix, P⁺ the post-fix Lyapunov solution
above (at the median of the first 10 fix intervals, σ_gps the median vertical ``pos_sd`` of
the fixes of the warm-up, consumer accelerometer noise by default: both known before the
gate opens, so the online answer never reads a later fix). At τ = T this is the
steady-state innovation variance S_ss = P⁻₀₀ + σ_gps² (seed 003: √S_ss = 2.31 m, gate
±7.6 m); it widens while fixes are rejected, as the INS-only prediction becomes uncertain.
Two rules keep the gate from locking the GNSS out: (1) no gating during the first
``warmup_s`` (default the analytic settling time, 49 s at 1 Hz) — S_ss holds only once the
loop has settled; (2) when consecutive rejections span ``reinit_s`` (default 20 s; ≥ 2
fixes), the observer re-initialises as at the start (ẑ = the current fix, v̂ = 0, ĉ kept)
and the warm-up restarts (``info["gnss_reinit"]``).
On clean seed-003 data (bias error 0) the gate rejects 0.106 % of the fixes (p_fa = 0.1 %)
and the steady σ moves by +0.3 %; ``seed003_monte_carlo`` (the reproduction) stays ungated
by default. Limitation: the observer has no baro, so during a sustained GNSS failure it can
only coast on the IMU; where the AHRS's in-flight vertical acceleration is m/s² wrong (a
vibrating multirotor), the coast diverges and the re-initialisation then follows the bad
GNSS (gate and rejection count work; the altitude is not usable there; docs/real_logs.md,
"Vertical attitude reference").

Causality: the answer is the online answer; the gate's period and σ_gps come from fixes seen
before the gate opens (above) and the vertical acceleration from the causal attitude
reference (step 9 of docs/vertical_loops.md §1). Altitude RMSE against truth, hill-drive seeds
0/1/2: 2.11/16.80/5.94 m; sortie seeds 0/1/2: 6.20/5.31/4.58 m (2.11/16.78/5.96 and
6.20/5.35/4.58 m with whole-drive medians and fixes interpolated toward the next one). Not
causal: the state starts at the first fix at or after the first IMU epoch (the observer has
no other altitude), 0.1-1 s ahead on the simulated drives.

References: seed 003 (1-DOF INS + GPS altitude observer); Franklin, Powell, Workman,
*Digital Control of Dynamic Systems*, 3rd ed., §6.3 (ZOH/bilinear equivalents).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numba import njit
from scipy.linalg import solve_discrete_lyapunov

from ...config import G0
from ...geo.earth import gravity, radii
from ...nav.gaps import gap_threshold
from ...sensors.model import sensor_model
from ...types import Drive, Estimate
from ...types.streams import FloatArray
from .base import VerticalEstimator, vertical_estimate
from .inputs import AhrsConfig, vertical_inputs

SEED003_GAIN = (0.4, 0.04, 0.002)


@dataclass(frozen=True)
class ObserverConfig:
    """Configuration of ``observer1d``.

    gain : L (3,) applied at each GPS fix [-, 1/s, 1/s²]
    discretisation : "zoh" | "tustin"
    gate_prob : false-alarm probability of the GNSS innovation gate (None: no gate)
    gnss_sd : σ of the GNSS altitude in S [m] (None: median vertical pos_sd of warm-up fixes)
    accel_noise_density : white accelerometer noise used in S [m/s²/√Hz]
    accel_bias_rw : accelerometer bias random walk used in S [m/s²/√s]
    warmup_s : fixes before t_first_fix + warmup_s are never gated [s] (None: the settling time)
    reinit_s : rejections spanning this long re-initialise the observer at the current fix [s]
    ahrs : attitude reference for the vertical specific force
    """

    gain: tuple[float, float, float] = SEED003_GAIN
    discretisation: str = "zoh"
    # the gate is δy² > χ²₁(1 − gate_prob) · S(τ) (module docstring, "GNSS gating")
    gate_prob: float | None = 1e-3
    gnss_sd: float | None = None
    # the consumer preset, 300 µg/√Hz
    accel_noise_density: float = 300e-6 * G0
    accel_bias_rw: float = 0.0
    # None: the analytic settling time of the loop at the fix period of the first fixes
    # (analytic_settling)
    warmup_s: float | None = None
    # so that the gate cannot lock the GNSS out forever
    reinit_s: float = 20.0
    ahrs: AhrsConfig = field(default_factory=AhrsConfig)

    def __post_init__(self) -> None:
        if self.discretisation not in ("zoh", "tustin"):
            raise ValueError("ObserverConfig.discretisation: 'zoh' or 'tustin'")
        if len(self.gain) != 3:
            raise ValueError("ObserverConfig.gain: three gains")
        if self.gate_prob is not None and not 0.0 < self.gate_prob < 1.0:
            raise ValueError("ObserverConfig.gate_prob: in (0, 1) or None")


# the gate's fix period is the median of the first this many fix intervals (all inside the
# warm-up: it is 49 intervals at the seed's gains)
PERIOD_FIXES = 10


def gate_threshold(gate_prob: float | None) -> float:
    """k² = χ²₁ quantile at 1 − gate_prob (∞ for None): reject δy² > k²·S."""
    if gate_prob is None:
        return float(np.inf)
    from scipy.stats import chi2

    return float(chi2.ppf(1.0 - gate_prob, 1))


@njit(cache=True)
def gate_var(p, tau, qa, qb, r):
    """Innovation variance of a fix τ seconds after the last accepted one, from the
    post-fix covariance p (3, 3): [Φ(τ) p Φ(τ)ᵀ + Q(τ)]₀₀ + r (``_phi_q``, module docstring)."""
    t2 = tau * tau
    return (p[0, 0] + 2.0 * tau * p[0, 1] + t2 * (p[0, 2] + p[1, 1]) + t2 * tau * p[1, 2]
            + 0.25 * t2 * t2 * p[2, 2] + qa * qa * t2 * tau / 3.0
            + qb * qb * t2 * t2 * tau / 20.0 + r)


@njit(cache=True)
def _fix_update(zf, tf, z, v, c, gain, gate2, p_gate, qa, qb, r_gate, t_warm, reinit_s, st):
    """One GNSS fix: gate, correct or re-initialise. st = [t_acc, t_gate_on, n_consec,
    t_first_rej] (float64 (4,), updated in place). Returns z, v, c, innovation, code
    (0 accepted, 1 rejected, 2 re-initialised)."""
    innov = zf - z
    if tf >= st[1] and innov * innov > gate2 * gate_var(p_gate, tf - st[0], qa, qb, r_gate):
        if st[2] == 0.0:
            st[3] = tf
        st[2] += 1.0
        if st[2] >= 2.0 and tf - st[3] >= reinit_s:
            # re-initialise as at the start: z at the fix, v = 0, c kept; gate off again for
            # t_warm so the loop can settle
            st[0] = tf
            st[1] = tf + t_warm
            st[2] = 0.0
            return zf, 0.0, c, innov, 2
        return z, v, c, innov, 1
    st[0] = tf
    st[2] = 0.0
    return z + gain[0] * innov, v + gain[1] * innov, c + gain[2] * innov, innov, 0


@njit(cache=True)
def observer_kernel_gated(t, a_up, t_fix, z_fix, gain, tustin, x0, grav_grad, h_ref, stride,
                          gate2, p_gate, qa, qb, r_gate, t_warm, reinit_s, gap_dt=np.inf):
    """Propagate/correct the 1-DOF observer for R runs at once, with the innovation gate.

    t (N,) IMU epochs [s]; a_up (R, N) measured up acceleration [m/s²] (gravity at h_ref
    removed); t_fix (M,), z_fix (R, M) GPS altitudes; gain (3,); tustin: bool; x0 (R, 3);
    grav_grad = 2g/R [1/s²]: the INS adds grav_grad·(ẑ − h_ref) to a_up (gravity decreases
    with height — the positive feedback of the vertical channel; 0 for the seed's model).
    Gate (module docstring, "GNSS gating"): a fix with innovation δy is rejected when
    δy² > gate2 · S(τ), S(τ) = ``gate_var(p_gate, τ, qa, qb, r_gate)``, τ the time since the
    last accepted fix; fixes earlier than t_fix[0] + t_warm are never gated (gate2 = inf: no
    gate); rejections spanning ≥ reinit_s [s] re-initialise the state (``_fix_update``).
    An IMU step longer than gap_dt [s] is a logging gap: the vertical acceleration is taken
    as zero across it (a = −c, so u = only the 2g/R feedback) instead of interpolating two
    samples over the whole gap. Any other step length is exact (ZOH/Tustin per step).
    Returns z, v, c at every ``stride``-th IMU epoch, shape (R, K), the altitude just after
    each fix (R, M) and just before it (R, M), the fix codes (R, M) int8 (0 accepted,
    1 rejected, 2 re-initialised; −1 not reached) and the innovations (R, M) [m].
    """
    r_n, n = a_up.shape
    m = t_fix.size
    kk = (n - 1) // stride + 1
    z_out = np.empty((r_n, kk))
    v_out = np.empty((r_n, kk))
    c_out = np.empty((r_n, kk))
    z_post = np.full((r_n, m), np.nan)
    z_prior = np.full((r_n, m), np.nan)
    code = np.full((r_n, m), -1, dtype=np.int8)
    st = np.empty(4)
    innov_out = np.full((r_n, m), np.nan)
    t_gate_on = (t_fix[0] + t_warm) if m > 0 else 0.0
    for r in range(r_n):
        z, v, c = x0[r, 0], x0[r, 1], x0[r, 2]
        st[0] = t_fix[0] if m > 0 else 0.0  # time of the last accepted fix
        st[1] = t_gate_on
        st[2] = 0.0  # consecutive rejections
        st[3] = 0.0  # time of the first of them
        j = 0
        while j < m and t_fix[j] < t[0]:
            j += 1
        for k in range(n):
            # fixes at t_k are applied before stepping on
            while j < m and t_fix[j] <= t[k] + 1e-9 and (k == n - 1 or t_fix[j] < t[k + 1]):
                if abs(t_fix[j] - t[k]) <= 1e-9:
                    z_prior[r, j] = z
                    z, v, c, innov_out[r, j], code[r, j] = _fix_update(
                        z_fix[r, j], t_fix[j], z, v, c, gain, gate2, p_gate, qa, qb, r_gate,
                        t_warm, reinit_s, st)
                    z_post[r, j] = z
                    j += 1
                else:
                    break
            if k % stride == 0:
                z_out[r, k // stride] = z
                v_out[r, k // stride] = v
                c_out[r, k // stride] = c
            if k == n - 1:
                break
            ts = t[k]
            a0 = a_up[r, k]
            a1 = a_up[r, k + 1]
            te = t[k + 1]
            if te - ts > gap_dt:
                a0 = -c
                a1 = -c
            # sub-steps at fixes strictly inside (t_k, t_{k+1})
            while True:
                t_end = te
                inside = j < m and t_fix[j] > ts + 1e-9 and t_fix[j] < te - 1e-9
                if inside:
                    t_end = t_fix[j]
                h = t_end - ts
                frac0 = (ts - t[k]) / (te - t[k])
                frac1 = (t_end - t[k]) / (te - t[k])
                u0 = a0 + frac0 * (a1 - a0) + c + grav_grad * (z - h_ref)
                if tustin:
                    # predictor for the end-point gravity feedback (one explicit step)
                    u1 = a0 + frac1 * (a1 - a0) + c + grav_grad * (z + v * h - h_ref)
                    v1 = v + 0.5 * (u0 + u1) * h
                    z = z + 0.5 * (v + v1) * h
                    v = v1
                else:
                    z = z + v * h + 0.5 * u0 * h * h
                    v = v + u0 * h
                ts = t_end
                if not inside:
                    break
                z_prior[r, j] = z
                z, v, c, innov_out[r, j], code[r, j] = _fix_update(
                    z_fix[r, j], t_fix[j], z, v, c, gain, gate2, p_gate, qa, qb, r_gate,
                    t_warm, reinit_s, st)
                z_post[r, j] = z
                j += 1
    return z_out, v_out, c_out, z_post, z_prior, code, innov_out


@njit(cache=True)
def observer_kernel(t, a_up, t_fix, z_fix, gain, tustin, x0, grav_grad, h_ref, stride):
    """The ungated seed-003 observer (``observer_kernel_gated`` with gate2 = ∞).

    Returns z, v, c at every ``stride``-th IMU epoch (R, K), the altitude just after each fix
    (R, M) and just before it (R, M).
    """
    z, v, c, zp, zm, _, _ = observer_kernel_gated(
        t, a_up, t_fix, z_fix, gain, tustin, x0, grav_grad, h_ref, stride, np.inf,
        np.zeros((3, 3)), 0.0, 0.0, 0.0, 0.0, np.inf)
    return z, v, c, zp, zm


def _gps_up(drive: Drive) -> tuple[FloatArray, FloatArray]:
    if drive.gnss is None or len(drive.gnss) == 0:
        raise ValueError("observer1d: the drive has no GNSS fixes")
    return drive.gnss.t, drive.gnss.lla[:, 2]


class Observer1D(VerticalEstimator):
    """Seed-003 observer as a registered estimator (``observer1d``). See module docstring."""

    name = "observer1d"
    config_class = ObserverConfig

    def solve(self, drive: Drive) -> Estimate:
        cfg = self.config
        vi = vertical_inputs(drive, cfg.ahrs)
        h0 = float(drive.origin_lla[2])
        # a_up with gravity at the reference height; the kernel adds the 2g/R feedback
        a_up = -(vi.f_down + gravity(vi.lat, h0) + vi.coriolis_down)
        rn, re = radii(drive.origin_lla[0])
        grav_grad = 2.0 * float(gravity(drive.origin_lla[0], h0)) / float(np.sqrt(rn * re))
        t_fix, z_fix = _gps_up(drive)
        # IMU logging gaps: the shared rule (nav.gaps)
        gap_dt = gap_threshold(vi.t)
        k0 = int(np.searchsorted(t_fix, vi.t[0]))
        z_init = z_fix[min(k0, z_fix.size - 1)]
        x0 = np.array([[z_init, 0.0, 0.0]])
        t_first = t_fix[min(k0, t_fix.size - 1)]
        # the gate's fix period and σ_gps come from fixes the observer has seen before its
        # gate opens (module docstring, "GNSS gating"): the period from the first
        # PERIOD_FIXES intervals, σ_gps from the fixes of the warm-up
        head = t_fix[k0:k0 + PERIOD_FIXES + 1]
        period = float(np.median(np.diff(head))) if head.size > 1 else 1.0
        warm = (analytic_settling(cfg.gain, period) if cfg.warmup_s is None
                else cfg.warmup_s)
        sd_g = cfg.gnss_sd
        if sd_g is None:  # the median of the shared model's GNSS σ_v (sensors.model)
            k1 = max(int(np.searchsorted(t_fix, t_first + warm, side="right")), k0 + 1)
            sd_g = float(np.median(sensor_model(drive).gnss_pos_sd[k0:k1, 2]))
        ss = steady_state(cfg.gain, period, sd_g, cfg.accel_noise_density, cfg.accel_bias_rw)
        gate2 = gate_threshold(cfg.gate_prob)
        z, v, c, _, _, code, innov = observer_kernel_gated(
            vi.t, a_up[None, :], t_fix, z_fix[None, :], np.asarray(cfg.gain, float),
            cfg.discretisation == "tustin", x0, grav_grad, h0, 1, gate2, ss.p_post,
            cfg.accel_noise_density, cfg.accel_bias_rw, sd_g**2,
            float(t_first - t_fix[0]) + warm, cfg.reinit_s, gap_dt,
        )
        s_ss = float(ss.p_prior[0, 0] + sd_g**2)
        ok = np.isfinite(innov[0])
        return vertical_estimate(
            self.name, vi.t, z[0], -v[0], cfg,
            innovations={"gnss_alt": innov[0][ok] / np.sqrt(s_ss)},
            info={"accel_bias_up_final": float(-c[0, -1]), "uses": "imu+gnss",
                  "gnss_rejected": int(np.sum(code[0] == 1)),
                  "gnss_reinit": int(np.sum(code[0] == 2)), "gnss_gate_sd_m": float(np.sqrt(s_ss)),
                  "gnss_gate_k": float(np.sqrt(gate2)), "gnss_gate_warmup_s": float(warm)},
        )


# --------------------------------------------------------------------------------------------
# Analysis: steady state, seed-003 Monte Carlo, discretisation comparison
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class SteadyState:
    """Analytic steady state of the closed loop at the GPS rate.

    p_post, p_prior : (3, 3) error covariance just after / just before a fix
    sd_post, sd_prior : their altitude σ [m]
    sd_mean : RMS over the fix interval of the altitude σ of the IMU-rate output [m]
    eigenvalues : (3,) closed-loop eigenvalues of (I − LH)Φ
    """

    p_post: FloatArray
    p_prior: FloatArray
    sd_post: float
    sd_prior: float
    sd_mean: float
    eigenvalues: FloatArray


def _phi_q(tau: float, qa: float, qb: float) -> tuple[FloatArray, FloatArray]:
    phi = np.array([[1.0, tau, tau**2 / 2], [0.0, 1.0, tau], [0.0, 0.0, 1.0]])
    q = qa**2 * np.array([[tau**3 / 3, tau**2 / 2, 0], [tau**2 / 2, tau, 0], [0, 0, 0]])
    q = q + qb**2 * np.array([
        [tau**5 / 20, tau**4 / 8, tau**3 / 6],
        [tau**4 / 8, tau**3 / 3, tau**2 / 2],
        [tau**3 / 6, tau**2 / 2, tau],
    ])
    return phi, q


def steady_state(
    gain=SEED003_GAIN, period_s: float = 1.0, gps_sd: float = 2.0,
    accel_noise_density: float = 300e-6 * G0, accel_bias_rw: float = 0.0, n_sub: int = 100,
) -> SteadyState:
    """Discrete Lyapunov solution of the closed loop (module docstring).

    accel_noise_density [m/s²/√Hz], accel_bias_rw [m/s²/√s]; ``n_sub`` sub-samples of the
    fix interval for ``sd_mean``.
    """
    L = np.asarray(gain, float)
    m = np.eye(3) - np.outer(L, [1.0, 0.0, 0.0])
    phi, q = _phi_q(period_s, accel_noise_density, accel_bias_rw)
    a_cl = m @ phi
    q_cl = m @ q @ m.T + np.outer(L, L) * gps_sd**2
    p_post = solve_discrete_lyapunov(a_cl, q_cl)
    p_prior = phi @ p_post @ phi.T + q
    var = []
    for i in range(n_sub):
        ph, qq = _phi_q(period_s * i / n_sub, accel_noise_density, accel_bias_rw)
        var.append((ph @ p_post @ ph.T + qq)[0, 0])
    return SteadyState(p_post, p_prior, float(np.sqrt(p_post[0, 0])),
                       float(np.sqrt(p_prior[0, 0])), float(np.sqrt(np.mean(var))),
                       np.linalg.eigvals(a_cl))


def analytic_settling(gain=SEED003_GAIN, period_s: float = 1.0, tol: float = 0.10) -> float:
    """Settling time [s] of the altitude response to an initial accel-correction error:
    last k with |[A_cl^k]_{0,2}| > tol · max_k |[A_cl^k]_{0,2}| (module docstring)."""
    L = np.asarray(gain, float)
    phi, _ = _phi_q(period_s, 0.0, 0.0)
    a_cl = (np.eye(3) - np.outer(L, [1.0, 0.0, 0.0])) @ phi
    p = np.eye(3)
    e = []
    for _ in range(2000):
        p = a_cl @ p
        e.append(abs(p[0, 2]))
    e = np.asarray(e)
    return float((np.flatnonzero(e > tol * e.max())[-1] + 1) * period_s)
