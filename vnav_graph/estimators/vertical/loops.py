"""Classical baro-inertial damping loops of the INS vertical channel (``loop2``, ``loop3``).

Seed 001 figs. 2-3; Widnall & Sinha (1980), "Optimizing the gains of the baro-inertial
vertical channel", AIAA J. Guidance & Control 3(2). Up form: h altitude [m], v vertical speed
[m/s, +up], c acceleration-error estimate [m/s²]; e = h − h_baro is the loop error.

    3rd order:  ḣ = v − k1·e,   v̇ = a_up + ω_s²·(h − h0) − k2·e − c,   ċ = k3·e
    2nd order:  the same without c,

with a_up = −(f_D + g(lat, h0) + cor_D) from ``vertical.inputs.vertical_inputs`` and
ω_s² = 2g/R the gravity-gradient positive feedback of the free-inertial channel (g decreases
with height, so a height error feeds a growing acceleration error; time constant
1/ω_s ≈ 570 s).

Error dynamics (δh = h − h_true, δv, baro error-free, constant accel bias b along up):
δḣ = δv − k1 δh, δv̇ = b + (ω_s² − k2) δh − c, ċ = k3 δh; characteristic polynomial
s³ + k1 s² + (k2 − ω_s²) s + k3 (3rd order), s² + k1 s + (k2 − ω_s²) (2nd order).

Gains (pole placement):
- 3rd order, triple pole at −1/τ: k1 = 3/τ, k2 = 3/τ² + ω_s², k3 = 1/τ³ (default τ = 20 s);
- 2nd order, natural frequency ω_n and damping ζ: k1 = 2ζω_n, k2 = ω_n² + ω_s²
  (default ω_n = 0.05 rad/s, ζ = 1/√2).

Steady state under a constant accelerometer bias b (final-value theorem on the error
transfer function b/s → δh):
- 2nd order: δH(s) = b / (s (s² + k1 s + k2 − ω_s²)) ⇒ δh(∞) = b / (k2 − ω_s²) = b / ω_n²
  (b/k2 if the 2g/R compensation is left out of k2 and the feedback neglected);
  δv(∞) = k1·δh(∞).
- 3rd order: δH(s) = b·s / (s (s³ + k1 s² + (k2 − ω_s²) s + k3)) ⇒ δh(∞) = 0, c(∞) = b.
A baro bias β passes to the altitude in both loops (δh(∞) = β): the loops damp the INS,
they do not calibrate the barometer.

The loops are baro-inertial: they use the IMU and the baro stream (``drive.baro.altitude``)
only. GNSS enters only through the attitude reference that stands for "the INS attitude"
(``vertical.inputs``), never the vertical channel.

Discrete implementation at the IMU rate (step Δt_k, any spacing — real logs jitter by ±10 %):
x_{k+1} = Φ(Δt_k) x_k + Γ(Δt_k) a_k − Δt_k·g·e_k with
Φ = exp(A Δt), Γ = ∫₀^Δt exp(A s) ds·B the zero-order hold of the free channel
(A = [[0, 1], [ω_s², 0]] plus the c column [0, −1, 0]ᵀ for the 3rd order), g = [k1, k2, −k3],
and in e_k = h_k − h_baro,k the last baro altitude at or before each IMU epoch, held (linear
interpolation to the epoch would read the next baro sample; the hold delays the baro by half a
baro interval on average, 12.5 ms at 40 Hz). This is exactly the
structure of a steady-state Kalman filter's predict step (x_{k+1} = Φ x⁺_k + Γ a_k with
x⁺ = x − K e): with Δt·g = Φ K the loop *is* that filter (``Loop2.from_kalman`` and the
equivalence test). Logging gaps (steps > 5 × the median) are bridged at the median step
with zero vertical acceleration and the baro interpolated across the gap (``bridge_gaps``).

Causality: the loops' answer is their online answer; at each IMU epoch it uses the baro
samples and the attitude reference (step 9 of docs/vertical_loops.md §1) up to that epoch. Altitude
RMSE against truth, hill-drive seeds 0/1/2 and sortie seeds 0/1/2: loop2 23.52/52.35/31.58
and 5.27/3.23/3.51 m; loop3 3.67/7.58/3.16 and 2.52/8.79/5.62 m. With the baro and the fixes
interpolated to the epoch (reading the next sample): loop2 23.51/52.36/31.57 and
5.26/3.23/3.47 m; loop3 3.67/7.58/3.16 and 2.47/8.79/5.60 m (the sortie's fast climbs pay
for the baro's half-sample delay).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numba import njit
from scipy.linalg import solve_discrete_are

from ...geo.earth import gravity, radii
from ...nav.arrays import put
from ...nav.gaps import imu_gaps
from ...types import Drive, Estimate
from ...types.streams import FloatArray
from ...util.failures import MissingStream
from .base import VerticalEstimator, vertical_estimate
from .inputs import AhrsConfig, vertical_inputs


def schuler_vertical(lat: float, h: float) -> float:
    """ω_s² = 2g/R [1/s²] at (lat, h), R the Gaussian mean radius."""
    rn, re = radii(lat)
    return float(2.0 * gravity(lat, h) / (np.sqrt(rn * re) + h))


def gains3(tau: float, ws2: float) -> tuple[float, float, float]:
    """Triple pole at −1/τ: (k1, k2, k3) = (3/τ, 3/τ² + ω_s², 1/τ³)."""
    return 3.0 / tau, 3.0 / tau**2 + ws2, 1.0 / tau**3


def gains2(omega_n: float, zeta: float, ws2: float) -> tuple[float, float]:
    """(k1, k2) = (2ζω_n, ω_n² + ω_s²)."""
    return 2.0 * zeta * omega_n, omega_n**2 + ws2


@njit(cache=True)
def zoh_nb(dt, ws2, order):
    """ZOH (Φ, Γ) of the free channel, state [h − h0, v] (order 2) or [h − h0, v, c]
    (order 3): the blocks of exp([[A, B], [0, 0]]·Δt) by the Taylor series (A's nilpotent part
    ends after 3 terms and ω_s²Δt² ≲ 1e-6 at IMU steps, so 40 terms are exact to round-off
    for any Δt below a few minutes)."""
    n = order
    m = np.zeros((n + 1, n + 1))
    m[0, 1] = dt
    m[1, 0] = ws2 * dt
    if order == 3:
        m[1, 2] = -dt
    m[1, n] = dt
    e = np.eye(n + 1)
    term = np.eye(n + 1)
    for k in range(1, 40):
        term = term @ m / k
        e += term
        if np.max(np.abs(term)) < 1e-18:
            break
    return e[:n, :n].copy(), e[:n, n].copy()


def discrete_model(dt: float, ws2: float, order: int) -> tuple[FloatArray, FloatArray]:
    """``zoh_nb`` called from Python (gain design, tests): (Φ, Γ) of the free channel."""
    return zoh_nb(float(dt), float(ws2), np.int64(order))


@njit(cache=True)
def loop_kernel(t, a_up, z_baro, ws2, gains, x0, scale):
    """x_{k+1} = Φ(Δt_k) x_k + Γ(Δt_k) a_k − Δt_k · s_k ⊙ g · e_k, e_k = x_k[0] − z_k.

    t (N,) epochs [s] (any spacing: Φ, Γ recomputed when Δt_k changes), a_up (N,) (NaN: no
    IMU sample — a bridged logging gap, see ``bridge_gaps``: the input is then the loop's own
    bias estimate c (3rd order) or 0, i.e. zero vertical acceleration), z_baro (N,) baro
    altitude − h0 at the epochs, ws2 [1/s²], gains (n,) = [k1, k2(, −k3)], x0 (n,), scale
    (N, n) per-step gain multipliers (all ones for the fixed-gain loops). Returns states
    (N, n) and the loop error (N,).
    """
    n_s = x0.size
    n = a_up.size
    x = np.empty((n, n_s))
    err = np.empty(n)
    put(x[0], x0)
    dt_prev = -1.0
    phi = np.eye(n_s)
    gam = np.zeros(n_s)
    for k in range(n):
        e = x[k, 0] - z_baro[k]
        err[k] = e
        if k == n - 1:
            break
        dt = t[k + 1] - t[k]
        if abs(dt - dt_prev) > 1e-12 * dt:
            phi, gam = zoh_nb(dt, ws2, n_s)
            dt_prev = dt
        a = a_up[k]
        if np.isnan(a):
            a = x[k, 2] if n_s == 3 else 0.0
        for i in range(n_s):
            acc = gam[i] * a - scale[k, i] * (gains[i] * dt) * e
            for j in range(n_s):
                acc += phi[i, j] * x[k, j]
            x[k + 1, i] = acc
    return x, err


def bridge_gaps(inp: LoopInputs) -> tuple[LoopInputs, FloatArray]:
    """Fill IMU logging gaps (the shared rule, ``nav.gaps.imu_gaps``) with epochs at
    the median step: a_up = NaN there (the kernels then assume zero vertical acceleration:
    input = the loop's accelerometer-bias estimate c, or 0 for the 2nd order — a held
    acceleration sample would integrate one noisy value over the whole gap, ½aT²), z_baro
    linearly interpolated between the gap ends (the baro has the same gap in real logs), so
    the loop keeps its time constant instead of taking one Euler step of length T (k1·T > 1
    for T > τ/3). Returns the bridged inputs and the (N_bridged,) mask of original epochs.
    Jitter below the factor is handled by the per-step Φ(Δt), Γ(Δt)."""
    t = inp.t
    if t.size < 3:
        return inp, np.ones(t.size, dtype=bool)
    dt = np.diff(t)
    dt_nom = float(np.median(dt))
    big = imu_gaps(t)
    if big.size == 0:
        return inp, np.ones(t.size, dtype=bool)
    ins = [np.arange(t[i] + dt_nom, t[i + 1] - 0.5 * dt_nom, dt_nom) for i in big]
    t_new = np.concatenate([t] + ins)
    orig = np.concatenate([np.ones(t.size, dtype=bool)] + [np.zeros(a.size, dtype=bool)
                                                           for a in ins])
    order = np.argsort(t_new, kind="stable")
    t_new, orig = t_new[order], orig[order]
    a_new = np.full(t_new.size, np.nan)
    a_new[orig] = inp.a_up
    z_new = np.interp(t_new, t, inp.z_baro)
    return LoopInputs(t_new, a_new, z_new, inp.h0, inp.ws2), orig


@dataclass(frozen=True)
class LoopInputs:
    """What a loop consumes, at the IMU epochs: t (N,), a_up (N,) [m/s²] with gravity at h0,
    z_baro (N,) baro altitude − h0 [m], h0 [m], ω_s² [1/s²]."""

    t: FloatArray
    a_up: FloatArray
    z_baro: FloatArray
    h0: float
    ws2: float


def loop_inputs(drive: Drive, ahrs: AhrsConfig | None = None) -> LoopInputs:
    """Vertical acceleration from the AHRS and the last baro altitude at each IMU epoch."""
    if drive.baro is None or len(drive.baro) == 0:
        raise MissingStream("barometer", "loops: the drive has no barometer stream")
    vi = vertical_inputs(drive, ahrs)
    h0 = float(drive.origin_lla[2])
    a_up = -(vi.f_down + gravity(vi.lat, h0) + vi.coriolis_down)
    # the last baro sample at or before each IMU epoch (the first one before it starts)
    k = np.maximum(np.searchsorted(drive.baro.t, vi.t, side="right") - 1, 0)
    z = np.asarray(drive.baro.altitude, float)[k] - h0
    return LoopInputs(vi.t, a_up, z, h0, schuler_vertical(drive.origin_lla[0], h0))


@dataclass(frozen=True)
class Loop2Config:
    """Settings of ``loop2``.

    omega_n: natural frequency of the loop [rad/s].
    zeta: damping ratio [-].
    gains: explicit (k1, k2) [1/s, 1/s²], used as given (None: from omega_n and zeta).
    ahrs: attitude-reference gains.
    """

    omega_n: float = 0.05
    zeta: float = float(1 / np.sqrt(2))
    gains: tuple[float, float] | None = None
    ahrs: AhrsConfig = field(default_factory=AhrsConfig)


@dataclass(frozen=True)
class Loop3Config:
    """Settings of ``loop3``.

    tau: time constant of the triple pole at −1/τ [s].
    gains: explicit (k1, k2, k3) [1/s, 1/s², 1/s³], used as given (None: from tau).
    ahrs: attitude-reference gains.
    """

    tau: float = 20.0
    gains: tuple[float, float, float] | None = None
    ahrs: AhrsConfig = field(default_factory=AhrsConfig)


def run_loop(inp: LoopInputs, gains: tuple[float, ...], scale: FloatArray | None = None,
             x0: FloatArray | None = None) -> tuple[FloatArray, FloatArray]:
    """Run a 2nd (2 gains) or 3rd (3 gains) order loop on ``inp``; returns states (N, n) with
    x[:, 0] = h − h0, x[:, 1] = v_up (, x[:, 2] = c) and the loop error e (N,), at the epochs
    of ``inp`` (any sampling: per-step discretisation; logging gaps bridged by
    ``bridge_gaps``). ``scale`` (N, n) multiplies the gains per step."""
    order = len(gains)
    g = np.array(gains, float)
    if order == 3:
        g[2] = -g[2]
    if x0 is None:
        x0 = np.zeros(order)
        x0[0] = inp.z_baro[0]
    if scale is None:
        scale = np.ones((inp.t.size, order))
    br, orig = bridge_gaps(inp)
    sc = np.ones((br.t.size, order))
    sc[orig] = scale
    x, err = loop_kernel(br.t, br.a_up, br.z_baro, inp.ws2, g, np.asarray(x0, float), sc)
    return x[orig], err[orig]


class FixedGainLoop(VerticalEstimator):
    """``solve`` shared by the fixed-gain loops: inputs, gains, ``run_loop``, Estimate."""

    needs_baro = True

    def gains(self, ws2: float) -> tuple[float, ...]:
        raise NotImplementedError

    def extra_info(self, x: FloatArray) -> dict[str, Any]:
        return {}

    def solve(self, drive: Drive) -> Estimate:
        inp = loop_inputs(drive, self.config.ahrs)
        g = self.gains(inp.ws2)
        x, err = run_loop(inp, g)
        info = {"gains": g, "uses": "imu+baro", **self.extra_info(x),
                "loop_error_rms_m": float(np.sqrt(np.mean(err**2)))}
        return vertical_estimate(self.name, inp.t, x[:, 0] + inp.h0, -x[:, 1], self.config,
                                 info=info)


class Loop2(FixedGainLoop):
    """Fixed-gain 2nd-order baro-inertial loop (``loop2``)."""

    name = "loop2"
    config_class = Loop2Config

    def gains(self, ws2: float) -> tuple[float, float]:
        c = self.config
        return c.gains if c.gains is not None else gains2(c.omega_n, c.zeta, ws2)

    @staticmethod
    def from_kalman(q_accel: float, r_baro: float, dt: float, ws2: float) -> Loop2Config:
        """Gains equal to the steady-state Kalman gain of the 2-state filter
        x = [h − h0, v], Φ, Γ = ZOH (above), Q = q_accel²·Δt·ΓΓᵀ/Δt² (white accel noise of
        root PSD q_accel [m/s²/√Hz] held over the step), measurement h_baro with variance
        r_baro [m²]. With K the steady-state (a posteriori) gain, Δt·[k1, k2] = Φ K."""
        phi, gam = discrete_model(dt, ws2, 2)
        q = np.outer(gam, gam) * q_accel**2 / dt
        h = np.array([[1.0, 0.0]])
        p = solve_discrete_are(phi.T, h.T, q, np.array([[r_baro]]))  # a priori P
        k = p @ h.T / (h @ p @ h.T + r_baro)
        g = phi @ k[:, 0] / dt
        return Loop2Config(gains=(float(g[0]), float(g[1])))



class Loop3(FixedGainLoop):
    """Fixed-gain 3rd-order baro-inertial loop (``loop3``)."""

    name = "loop3"
    config_class = Loop3Config

    def gains(self, ws2: float) -> tuple[float, float, float]:
        c = self.config
        return c.gains if c.gains is not None else gains3(c.tau, ws2)

    def extra_info(self, x: FloatArray) -> dict[str, Any]:
        return {"accel_bias_up_final": float(x[-1, 2])}
