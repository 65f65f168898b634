"""Standstill detection for zero-velocity updates (ZUPT), shared by both estimator families.

Test statistic: the generalised likelihood-ratio detector of Skog et al. ("Zero-velocity
detection — an algorithm evaluation", IEEE T-BME 57(11), 2010) with the specific force and
the angular rate at rest both unknown constants over the window (the sensors' biases, the
gravity's direction and magnitude: nuisance parameters), i.e. the moving variance of both
sensors (their MV and ARE detectors together), over the trailing W IMU samples ending at k:

    T_k = (1/W) Σ_{j=k−W+1..k} [ ||f_j − f̄||² / σ_a² + ||ω_j − ω̄||² / σ_g² ],

f the specific force in b [m/s²], ω the angular rate in b [rad/s], f̄ and ω̄ the window's
means, σ_a and σ_g the per-sample white-noise σ. At rest W·T_k is χ² with 6W − 6 degrees of
freedom whatever the biases, and the IMU test is

    T_k ≤ γ = χ²⁻¹_{6W−6}(1 − α) / W,   α = ``CUT_ALPHA`` (1e-5: the test is made at every
    sample, and one refusal ends a standstill).

(Skog's SHOE form with ||f − g f̄/||f̄|| ||² and ||ω||² reads the turn-on biases as motion: on
simulated hill-drive seed 1, a consumer IMU's 1–2σ biases put T at 11.4 at rest against
γ = 7.1 (p = 0.999), and no stop was found.)

Noise. σ_a, σ_g come from the shared sensor model (``estimators.zupt``: density·√rate). A
real log's inferred model holds the vibration in motion, so each is capped at
``QUIET_MARGIN`` times the per-axis rms of the drive's quietest ``QUIET_QUANTILE`` % windows
(``quiet_sd``): the vibration of a running engine or a walker's steps then no longer hides
a stop (docs/real_logs.md, "Standstills and course on the RTK drives"; a phone held by a
standing walker moves more than one lying still, so such standstills are found in part).
White noise at the model's σ (a simulated drive) is not
changed.

GNSS agreement. An IMU cannot tell a constant-velocity straight motion from rest, so a
sample is still only if the GNSS velocities of the trailing ``GNSS_WINDOW_S`` (at least 1.5
fix spacings) agree with zero: their inverse-variance mean per NED axis passes
Σ_axes v̄_a²·Σ_i σ_{i,a}⁻² ≤ χ²⁻¹₃(p) (a 0.2 m/s creep over ten 10 Hz fixes of σ 0.1 m/s
gives 40 against 16.3), and so does the latest fix alone. Without a fix in that window (an
outage) no sample is still: the IMU alone would take a smooth cruise for a stop. A drive with
GNSS positions only takes velocities from them (``position_velocity``: the displacement over
``POSITION_SPAN_S``, σ √2·σ_p/2 s = 0.7 m/s for σ_p = 1 m; only the latest is tested, their
errors being correlated), but a fix confirms rest only when its velocity σ is at most
``CONFIRM_SD_MAX`` (0.3 m/s on every axis: a 1 m/s creep is then beyond 3σ), so such
positions (0.7 m/s for σ_p = 1 m; metres per second on 1 Hz phone logs) confirm none and
the drive gets no zero-velocity update. A drive without GNSS gets no
standstill (``estimators.zupt``): on a simulated IMU without vibration every steady cruise
reads as rest (a position-only hill-drive's smoother cost rose 42-fold with IMU-only ZUPTs).

Steady means. At rest the means of f and ω hold still. A run of still samples is cut where
the window's means leave those of the run's n samples in the 2W before it,
||f̄_k − f̄_ref||²/σ_a² + ||ω̄_k − ω̄_ref||²/σ_g² > (1/W + 1/n)·χ²⁻¹₆(1 − ``CUT_ALPHA``)
(``steady_runs``). The reference slides: the simulated consumer IMU's means wander at rest
(2–4σ of white noise between 1 s means: its bias walk), and against the run's start hill-drive
seed 13's four stops came out in nine pieces. A gentle start tilts f by a/g and a gentle turn
moves ω̄, which the variances hardly see but the means do within a fraction of a second, so
the cut keeps the ZUPTs off a vehicle that creeps away (docs/real_logs.md, "Standstills and
course on the RTK drives"). After the cut a constant acceleration is a
steady f again (an IMU cannot tell it from a tilted rest): the GNSS speed then refuses it.

Minimum duration. A sample gives a ZUPT only once its run has lasted ``MIN_DURATION_S``.

Every test reads data up to t_k only, but for the noise cap: the decision at t_k is causal
given the drive's noise settings. ``Standstill.intervals`` are the spans where ZUPTs apply,
[t_start, t_end] in s on the drive clock.

Measurement. Each ZUPT is the pseudo-measurement v_n = 0 (the IMU's velocity in n) with σ
per axis ``Standstill.vel_sd``: the velocity that the detector's accelerometer noise leaves
over its window, σ_a·Δt·√W, floored at ``ZUPT_SD_FLOOR``; the ekf applies one every
1/``ZUPT_RATE_HZ`` s inside the intervals, the graph one velocity prior per keyframe inside.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2

from ..types.streams import FloatArray

PROB = 0.999  # probability of the GNSS χ² tests
WINDOW_S = 0.5  # SHOE window [s] (at least 2 samples)
MIN_DURATION_S = 1.0  # a run of still samples gives ZUPTs after this long [s]
GNSS_WINDOW_S = 1.0  # fixes of this trailing span must agree with zero [s] (≥ 1.5 fix spacings)
POSITION_SPAN_S = 2.0  # GNSS positions without velocity: displacement over this span [s]
ZUPT_RATE_HZ = 10.0  # ekf ZUPT rate inside an interval [Hz]
ZUPT_SD_FLOOR = 0.01  # σ floor of the zero-velocity pseudo-measurement [m/s]
# false-alarm probability of the IMU tests (the variance test T ≤ γ and the steady-means cut)
# per window: both are applied at every sample of a run, so a refusal must be rare (at 1e-3
# the simulated hill-drive's 14 s stop was cut in two by its accelerometer bias's
# Gauss-Markov drift, and seed 13's stops into four pieces)
CUT_ALPHA = 1e-5
QUIET_QUANTILE = 5.0  # % of the windows taken as rest when scaling the noise down
# the noise at rest, at most this times that of the quietest windows. Detected standstill on
# the RTK drives (reference: car 61 s, walk 29 s) and the fastest reference speed at a ZUPT:
# 3: car 59 s (its long opening stop cut in two), 0.10 m/s, walk 11 s; 5: car 61 s, 0.15 m/s,
# walk 14 s; 10: car 62 s, 0.22 m/s, walk 18 s; no cap: car 62 s, 0.22 m/s, walk 24 s
QUIET_MARGIN = 5.0


@dataclass(frozen=True)
class Standstill:
    """The detector's answer on one drive (module docstring).

    still: (N,) bool, a ZUPT applies at IMU sample k; statistic: (N,) T_k (NaN before the
    first full window); threshold: γ; imu_still / gnss_ok: (N,) bool, each test alone;
    intervals: (M, 2) [t_start, t_end] [s]; vel_sd: σ of the zero-velocity measurement per
    axis [m/s]; sd_accel / sd_gyro: per-sample σ used [m/s², rad/s]; window: W [samples].
    """

    t: FloatArray
    still: np.ndarray
    statistic: FloatArray
    threshold: float
    imu_still: np.ndarray
    gnss_ok: np.ndarray
    intervals: FloatArray
    vel_sd: float
    sd_accel: float
    sd_gyro: float
    window: int

    def interval_list(self) -> list[list[float]]:
        """``intervals`` as a JSON-ready list of [t_start, t_end] [s]."""
        return [[float(a), float(b)] for a, b in self.intervals]

    def summary(self) -> dict[str, float | None]:
        """JSON-ready detector settings: threshold γ, window [s], per-sample σ, and the
        pseudo-measurement σ."""
        rate = (self.t.size - 1) / float(self.t[-1] - self.t[0]) if self.t.size > 1 else 1.0
        out = {"threshold": self.threshold, "window_s": self.window / rate,
               "sd_accel": self.sd_accel, "sd_gyro": self.sd_gyro, "vel_sd": self.vel_sd}
        return {k: (float(v) if np.isfinite(v) else None) for k, v in out.items()}

    def update_times(self, rate_hz: float = ZUPT_RATE_HZ) -> FloatArray:
        """IMU stamps of the ZUPT updates: the first still sample of each 1/``rate_hz`` slot
        of the drive clock [s]."""
        idx = np.flatnonzero(self.still)
        if idx.size == 0:
            return np.zeros(0)
        slot = np.floor((self.t[idx] - self.t[0]) * rate_hz).astype(np.int64)
        first = np.r_[True, slot[1:] != slot[:-1]]
        return self.t[idx[first]]


def shoe_terms(accel_b: FloatArray, gyro_b: FloatArray, window: int
               ) -> tuple[FloatArray, FloatArray]:
    """The two sums of T_k before weighting, each divided by W: (1/W)Σ||f − f̄||² [m²/s⁴]
    and (1/W)Σ||ω − ω̄||² [rad²/s²] over the trailing ``window`` samples, each (N,), NaN for
    the first window − 1 samples. accel_b (N, 3) [m/s²], gyro_b (N, 3) [rad/s].

    With S = Σx, Q = Σ||x||² over the window, Σ||x − S/W||² = Q − ||S||²/W."""
    n = accel_b.shape[0]
    out = []
    for x in (accel_b, gyro_b):
        o = np.full(n, np.nan)
        if n >= window:
            cs = np.vstack([np.zeros((1, 3)), np.cumsum(x, axis=0)])
            cq = np.r_[0.0, np.cumsum(np.sum(x**2, axis=1))]
            sx = cs[window:] - cs[:-window]
            q = cq[window:] - cq[:-window]
            o[window - 1:] = np.maximum(q - np.sum(sx**2, axis=1) / window, 0.0) / window
        out.append(o)
    return out[0], out[1]


def quiet_sd(term: FloatArray) -> float:
    """``QUIET_MARGIN`` times the per-axis rms of the ``QUIET_QUANTILE`` % quietest windows
    of a ``shoe_terms`` sum (NaN when there is no full window)."""
    ok = np.isfinite(term)
    if not ok.any():
        return float("nan")
    return float(QUIET_MARGIN * np.sqrt(np.percentile(term[ok], QUIET_QUANTILE) / 3.0))


def shoe_threshold(window: int, prob: float = PROB) -> float:
    """γ = χ²⁻¹_{6W−6}(p) / W (module docstring)."""
    return float(chi2.ppf(prob, 6 * window - 6) / window)


# the largest GNSS velocity σ [m/s] (any axis) of a fix that may confirm a standstill: a
# 1 m/s creep is then more than 3σ from rest
CONFIRM_SD_MAX = 0.3


def gnss_agrees(t: FloatArray, gnss_t: FloatArray, vel_n: FloatArray, vel_sd: FloatArray,
                window_s: float, prob: float = PROB, mean_test: bool = True) -> np.ndarray:
    """(N,) bool: the fixes stamped in (t_k − window_s, t_k] exist, their inverse-variance
    mean velocity (with ``mean_test``; off for correlated velocities) and the latest fix
    alone each pass the χ²₃ test of zero (module docstring). vel_n, vel_sd (G, 3)."""
    w = 1.0 / np.maximum(vel_sd, 1e-6) ** 2
    cw = np.vstack([np.zeros((1, 3)), np.cumsum(w, axis=0)])
    cv = np.vstack([np.zeros((1, 3)), np.cumsum(w * vel_n, axis=0)])
    hi = np.searchsorted(gnss_t, t, side="right")
    lo = np.searchsorted(gnss_t, t - window_s, side="right")
    sw = cw[hi] - cw[lo]
    sv = cv[hi] - cv[lo]
    have = hi > lo
    gate = chi2.ppf(prob, 3)
    c2 = np.where(have[:, None], sv**2 / np.where(sw > 0, sw, 1.0), np.inf).sum(axis=1)
    latest = np.maximum(hi - 1, 0)
    last = np.sum(vel_n**2 * w, axis=1)[latest]
    # a fix confirms rest only when its σ can tell rest from a walking-pace creep: noisier
    # velocities (1 Hz phone positions, σ_v of metres per second) pass the χ² test at 1 m/s
    sharp = np.max(vel_sd, axis=1)[latest] <= CONFIRM_SD_MAX
    return have & sharp & ((c2 <= gate) | (not mean_test)) & (last <= gate)


def no_standstill(t: FloatArray) -> Standstill:
    """The answer for a drive whose standstill cannot be confirmed (no GNSS): none."""
    none = np.zeros(t.size, dtype=bool)
    return Standstill(t, none, np.full(t.size, np.nan), float("nan"), none, none,
                      np.zeros((0, 2)), ZUPT_SD_FLOOR, float("nan"), float("nan"), 0)


def steady_runs(cand: np.ndarray, x: FloatArray, window: int, gate: float) -> np.ndarray:
    """(N,) int: the first sample of the run each candidate sample belongs to (N elsewhere).
    ``x`` (N, d): samples whitened per axis (x/σ). A run of candidates starting at s (its first
    window holds samples s − W + 1 … s) is cut at the first k where the current window's mean
    leaves the mean of the n run samples in the 2W before that window: ||x̄_k − x̄_ref||² /
    (1/W + 1/n) > ``gate`` (for k − s < W: the first window's mean, variance 2/W). Causal: a
    cut at k depends on data up to t_k."""
    n = cand.size
    run_start = np.full(n, n, dtype=np.int64)
    c = np.vstack([np.zeros((1, x.shape[1])), np.cumsum(x, axis=0)])
    edges = np.diff(np.r_[0, cand.astype(np.int8), 0])
    for a, b in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1), strict=True):
        s = int(a)
        while s < b:
            k = np.arange(s, b)
            cur = (c[k + 1] - c[k + 1 - window]) / window
            first = (c[s + 1] - c[s + 1 - window]) / window
            # reference: the run's samples in the 2W before the current window
            m = np.minimum(k - s, 2 * window)
            late = k - s >= window
            hi = np.maximum(k - window + 1, 0)
            ref = np.where(late[:, None],
                           (c[hi] - c[np.maximum(hi - m, 0)]) / np.maximum(m, 1)[:, None], first)
            var = np.where(late, 1.0 / window + 1.0 / np.maximum(m, 1), 2.0 / window)
            d2 = np.sum((cur - ref) ** 2, axis=1) / var
            bad = np.flatnonzero(d2 > gate)
            e = s + int(bad[0]) if bad.size else int(b)
            run_start[s:e] = s
            s = e
    return run_start


def position_velocity(gnss_t: FloatArray, pos_n: FloatArray, pos_sd: FloatArray,
                      span_s: float = POSITION_SPAN_S) -> tuple[FloatArray, FloatArray,
                                                                FloatArray]:
    """Velocities from GNSS positions for a drive without GNSS velocity: at each fix i the
    displacement from the latest fix at least ``span_s`` before it over their time apart,
    σ = √(σ_i² + σ_j²)/Δt per axis. pos_n, pos_sd (G, 3) [m]. Returns (stamps (M,), velocity
    (M, 3) [m/s], σ (M, 3) [m/s]) of the fixes that have such a partner."""
    j = np.searchsorted(gnss_t, gnss_t - span_s, side="right") - 1
    ok = j >= 0
    i, j = np.flatnonzero(ok), j[ok]
    dt = (gnss_t[i] - gnss_t[j])[:, None]
    vel = (pos_n[i] - pos_n[j]) / dt
    sd = np.sqrt(pos_sd[i] ** 2 + pos_sd[j] ** 2) / dt
    return gnss_t[i], vel, sd


def detect_standstill(t: FloatArray, accel_b: FloatArray, gyro_b: FloatArray, sd_accel: float,
                      sd_gyro: float, gnss_t: FloatArray | None = None,
                      gnss_vel: FloatArray | None = None, gnss_vel_sd: FloatArray | None = None,
                      *, window_s: float = WINDOW_S, min_duration_s: float = MIN_DURATION_S,
                      gnss_window_s: float = GNSS_WINDOW_S, prob: float = PROB,
                      mean_test: bool = True) -> Standstill:
    """Standstill of a drive (module docstring). t (N,) IMU stamps [s]; accel_b, gyro_b
    (N, 3); sd_accel, sd_gyro: per-sample white-noise σ [m/s², rad/s]; gnss_t (G,),
    gnss_vel (G, 3) in n [m/s], gnss_vel_sd (G, 3) [m/s]: the GNSS velocities
    that must agree (``position_velocity`` on a drive without them, with ``mean_test``
    False: their errors are correlated), all None for the IMU alone."""
    if not (sd_accel > 0 and sd_gyro > 0):
        raise ValueError("detect_standstill: sd_accel and sd_gyro must be > 0")
    n = t.size
    rate = (n - 1) / float(t[-1] - t[0]) if n > 1 else 1.0
    window = max(2, int(round(window_s * rate)))
    term_a, term_g = shoe_terms(accel_b, gyro_b, window)
    # a real log's σ holds the vibration in motion: scaled down to its quiet windows
    # (a noiseless simulated drive's quiet windows are exactly 0: the model's floors stay)
    qa, qg = quiet_sd(term_a), quiet_sd(term_g)
    sd_accel = float(min(sd_accel, qa)) if qa > 0 else sd_accel
    sd_gyro = float(min(sd_gyro, qg)) if qg > 0 else sd_gyro
    stat = term_a / sd_accel**2 + term_g / sd_gyro**2
    gamma = shoe_threshold(window, 1.0 - CUT_ALPHA)
    imu_still = np.isfinite(stat) & (stat <= gamma)
    if gnss_t is not None and gnss_vel is not None and gnss_vel_sd is not None \
            and gnss_t.size:
        spacing = float(np.median(np.diff(gnss_t))) if gnss_t.size > 1 else gnss_window_s
        gok = gnss_agrees(t, gnss_t, gnss_vel, gnss_vel_sd,
                          max(gnss_window_s, 1.5 * spacing), prob, mean_test)
    else:
        gok = np.ones(n, dtype=bool)
    cand = imu_still & gok
    run_start = steady_runs(cand, np.hstack([accel_b / sd_accel, gyro_b / sd_gyro]), window,
                            float(chi2.ppf(1.0 - CUT_ALPHA, 6)))
    # causal minimum duration: the run ending at k started at least min_duration_s before t_k
    still = cand & (t - t[np.minimum(run_start, n - 1)] >= min_duration_s)
    edges = np.diff(np.r_[0, still.astype(np.int8), 0])
    a, b = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1) - 1
    intervals = np.column_stack([t[a], t[b]]) if a.size else np.zeros((0, 2))
    dt = 1.0 / rate
    vel_sd = max(sd_accel * dt * np.sqrt(window), ZUPT_SD_FLOOR)
    return Standstill(t, still, stat, gamma, imu_still, gok, intervals, float(vel_sd),
                      float(sd_accel), float(sd_gyro), window)
