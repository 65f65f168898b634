"""Least-squares barometer calibration against GNSS (seed 001, eqs. 1-4).

Seed 001 models the baro altitude H_B against the GNSS (DGPS) height H_G as

    H_B(t) = (1 + dSF)·H_G(t − Td) + B + w                                     (1)
           ≈ H_G(t) + H_G(t)·dSF − V_G(t)·Td + B + w                           (2)
    dH(t)  = H_B(t) − H_G(t) = H_G(t)·dSF − V_G(t)·Td + B + w                  (3)
    [dSF, Td, B]ᵀ = pinv(M_G)·dH,  rows of M_G = [H_G(k), −V_G(k), 1]          (4)

which is the package's one baro model (``vnav_graph.sensors.baro``) with the scale acting on
the height above the drive origin: H_G = h_GNSS − h0, H_B = h_baro − h0, h0 =
``Drive.origin_lla[2]``, and V_G the vertical speed (+up). The exact model has the latency
multiplied by (1 + dSF) (``baro_row``); the regression coefficient θ_Td is therefore
(1 + dSF)·Td and ``calibrate_baro`` reports Td = θ_Td / (1 + dSF).

``calibrate_arrays`` without a noise model is the paper's ordinary least squares: standard
errors from the residual variance, cov = (MᵀM)⁻¹·σ̂², σ̂² = RSS/(N − 3), right only for white
residuals. A real baro's bias is not a constant but a Gauss-Markov process (docs/design.md),
so the residuals are correlated over the bias time constant and those standard errors are
several times too small (σ 10-16× smaller than the error on a sortie variant).
``calibrate_baro`` therefore solves the same regression by **generalised least squares** with
the residual covariance of the shared baro model (``sensors.model``: the drive's bias σ_b
and τ_b — the real-log prior on a log — and white baro plus GNSS height noise):
C = σ_b²·exp(−|t_i − t_j|/τ_b) + diag(σ_baro² + σ_GNSS,v²), θ = (MᵀC⁻¹M)⁻¹MᵀC⁻¹dH,
cov = (MᵀC⁻¹M)⁻¹·max(1, s²) with s² the whitened residual variance (when the data scatter
more than the model says, the σ grow with them and a warning says so). At most
``MAX_GLS_EPOCHS`` evenly spaced epochs enter (C is dense). Outliers (GNSS height spikes) are
removed first: residuals that depart from their running median over ±``OUTLIER_HALF_S`` by
more than ``OUTLIER_K`` robust σ. The GNSS height noise enters both dH and the regressor
H_G, which biases dSF by −σ_G²/var(H_G) — negligible for altitude changes of hundreds of
metres, and flagged through the observability warnings otherwise.

Observability warnings (``BaroCalibration.warnings``):

- a parameter whose standard error exceeds ``WARN_FRACTION`` (0.5) of its typical magnitude
  ``TYPICAL`` is "poorly observable". The typical magnitudes are of the order of seed 001
  Table 1 and docs/design.md: dSF 1 %, Td 0.1 s, B 5 m. Td needs vertical speed (climbs and
  descents), dSF needs altitude change, B needs neither.
- the design matrix with unit-RMS columns has a condition number above ``MAX_CONDITION`` (1e3):
  the three effects cannot be separated (e.g. a constant-rate climb ties H_G to time).
- V_G differentiated from GNSS heights (no GNSS velocity) is noisy and biases Td toward 0.

Contents: ``BaroCalibration`` (frozen result), ``calibrate_baro(drive)``,
``calibrate_arrays(...)`` (the bare regression), ``format_calibration`` and
``vnav-graph calibrate-baro DRIVE`` prints ``format_calibration(calibrate_baro(drive))``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ...types import Drive
from ...types.streams import FloatArray

# Seed 001 Table 1: (dSF [%], Td [s], B [ft]) estimated on the paper's seven flight test sets;
# the reference values the calibration is reproduced against (tests, benchmarks/reproduce_seeds).
SEED001_TABLE1: tuple[tuple[float, float, float], ...] = (
    (-1.2676, 0.0803, -10.81),
    (-1.6575, 0.0286, -18.80),
    (-0.3539, -0.0079, -13.23),
    (-0.6471, -0.0196, -11.99),
    (-2.5172, 0.0009, -25.63),
    (-1.0882, 0.0091, -24.99),
    (-2.3189, -0.0348, -27.98),
)

# Typical magnitudes [dSF -, Td s, B m] (seed 001 Table 1: dSF 0.35-2.5 %, |Td| ≤ 0.08 s,
# |B| 3-9 m; docs/design.md: s up to 3 %, τd up to 0.5 s, b metres to tens of metres).
TYPICAL = {"scale": 0.01, "latency_s": 0.1, "bias_m": 5.0}
WARN_FRACTION = 0.5
MAX_CONDITION = 1.0e3
# Baro samples must bracket a GNSS epoch within this gap to be interpolated to it [s].
MAX_BARO_GAP_S = 1.0
MAX_GLS_EPOCHS = 1500
OUTLIER_HALF_S = 15.0  # s
OUTLIER_K = 6.0
POOR_FIT_S2 = 4.0  # whitened residual variance above which the fit is called poor


@dataclass(frozen=True)
class BaroCalibration:
    """Result of the seed-001 least-squares baro calibration.

    Attributes
    ----------
    scale, latency_s, bias_m : estimates of dSF [-], Td [s] and B [m]
    scale_sd, latency_sd, bias_sd : their standard errors from the residual variance
    cov : (3, 3) covariance of (dSF, Td, B) [-, s, m]
    residual_sd : σ̂ of the regression residual [m]
    n_epochs : number of GNSS epochs used
    condition : condition number of the design with unit-RMS columns
    velocity_source : "gnss_velocity" or "differentiated_height"
    warnings : human-readable observability / conditioning warnings (empty if none)
    method : "ols" (the paper's) or "gls" (with the baro noise model, ``calibrate_baro``)
    outliers : number of epochs removed as outliers
    fit_ratio : whitened residual variance s² (1 when the noise model fits; GLS only)
    """

    scale: float
    latency_s: float
    bias_m: float
    scale_sd: float
    latency_sd: float
    bias_sd: float
    cov: FloatArray
    residual_sd: float
    n_epochs: int
    condition: float
    velocity_source: str
    warnings: tuple[str, ...]
    method: str = "ols"
    outliers: int = 0
    fit_ratio: float | None = None


def _outliers(t: FloatArray, r: FloatArray) -> np.ndarray:
    """Residuals that leave their running median over ±OUTLIER_HALF_S by > OUTLIER_K robust σ
    (a bias drifts slowly; a GNSS height spike does not)."""
    lo = np.searchsorted(t, t - OUTLIER_HALF_S, side="left")
    hi = np.searchsorted(t, t + OUTLIER_HALF_S, side="right")
    dev = r - np.array([np.median(r[a:b]) for a, b in zip(lo, hi, strict=True)])
    sc = 1.4826 * float(np.median(np.abs(dev)))
    return np.abs(dev) > OUTLIER_K * max(sc, 1e-9)


def _gls_epochs(hg: FloatArray, vg: FloatArray, hb: FloatArray, ok: Any, t: FloatArray,
                white_sd: Any) -> tuple[Any, FloatArray, FloatArray, int]:
    """Epochs of the GLS fit: finite ones without the spikes (residuals of a first OLS fit
    against their running median, ``_outliers``), thinned to at most ``MAX_GLS_EPOCHS``.
    Returns the mask, their times and white-noise σ, and the number of spikes removed."""
    n_out = 0
    tt = np.asarray(t, dtype=float)
    w_sd = np.broadcast_to(np.asarray(white_sd, dtype=float), hg.shape)
    ok = ok & np.isfinite(tt) & np.isfinite(w_sd)
    if ok.sum() >= 10:
        m0 = np.column_stack([hg[ok], -vg[ok], np.ones(int(ok.sum()))])
        th0, *_ = np.linalg.lstsq(m0, hb[ok] - hg[ok], rcond=None)
        bad = _outliers(tt[ok], hb[ok] - hg[ok] - m0 @ th0)
        n_out = int(bad.sum())
        idx = np.flatnonzero(ok)
        ok[idx[bad]] = False
    stride = max(1, int(np.ceil(ok.sum() / MAX_GLS_EPOCHS)))
    keep = np.flatnonzero(ok)[::stride]
    ok = np.zeros(hg.size, dtype=bool)
    ok[keep] = True
    return ok, tt[ok], w_sd[ok], n_out


def _warnings(sd: FloatArray, cond: float, fit_ratio: float | None, n_out: int,
              velocity_source: str) -> list[str]:
    """What the user should know about a calibration: a poorly observable parameter, an
    ill-conditioned design, a poor fit, removed spikes, a differentiated V_G."""
    warns: list[str] = []
    names = (("scale", "dSF", "altitude change"), ("latency_s", "Td", "vertical speed"),
             ("bias_m", "B", "data"))
    for (key, label, needs), se in zip(names, sd, strict=True):
        if se > WARN_FRACTION * TYPICAL[key]:
            warns.append(f"{label} poorly observable: standard error {se:.3g} exceeds "
                         f"{WARN_FRACTION:g} x typical {TYPICAL[key]:g} (needs more {needs})")
    if cond > MAX_CONDITION:
        warns.append(f"design ill-conditioned (condition number {cond:.3g} > {MAX_CONDITION:g}):"
                     " dSF, Td and B cannot be separated by this data")
    if fit_ratio is not None and fit_ratio > POOR_FIT_S2:
        warns.append(f"poor fit: the residuals scatter {np.sqrt(fit_ratio):.2g}x more than the "
                     "baro/GNSS noise model allows (standard errors scaled up by that factor)")
    if n_out:
        warns.append(f"{n_out} epochs removed as outliers (GNSS/baro spikes)")
    if velocity_source == "differentiated_height":
        warns.append("V_G differentiated from GNSS heights (no GNSS velocity): Td is noisy and "
                     "biased toward zero")
    return warns


def calibrate_arrays(
    h_gnss_rel: FloatArray, v_up: FloatArray, h_baro_rel: FloatArray,
    velocity_source: str = "gnss_velocity", t: FloatArray | None = None,
    noise: tuple[float, float, FloatArray] | None = None,
) -> BaroCalibration:
    """Solve seed 001 eq. 4 for (dSF, Td, B).

    Parameters
    ----------
    h_gnss_rel : (N,) GNSS height above the drive origin, H_G [m]
    v_up : (N,) vertical speed +up at the same epochs, V_G [m/s]
    h_baro_rel : (N,) baro altitude above the drive origin at the same epochs, H_B [m]
    velocity_source : recorded in the result (adds a warning if "differentiated_height")
    t : (N,) epoch times [s]; with ``noise`` = (σ_b [m], τ_b [s], σ_white (N,) [m]) the
        regression is the GLS of the module docstring, with outliers removed; else OLS
    """
    hg = np.asarray(h_gnss_rel, dtype=float)
    vg = np.asarray(v_up, dtype=float)
    hb = np.asarray(h_baro_rel, dtype=float)
    if not (hg.shape == vg.shape == hb.shape) or hg.ndim != 1:
        raise ValueError("calibrate_baro: H_G, V_G and H_B must be 1-D arrays of equal length")
    ok = np.isfinite(hg) & np.isfinite(vg) & np.isfinite(hb)
    gls = t is not None and noise is not None
    n_out = 0
    if gls:
        assert t is not None and noise is not None
        ok, tt, w_sd, n_out = _gls_epochs(hg, vg, hb, ok, t, noise[2])
    hg, vg, hb = hg[ok], vg[ok], hb[ok]
    n = hg.size
    if n < 10:
        raise ValueError(f"calibrate_baro: only {n} usable GNSS/baro epochs (need >= 10)")
    m = np.column_stack([hg, -vg, np.ones(n)])  # M_G, eq. 4
    dh = hb - hg  # eq. 3
    fit_ratio = None
    if gls:
        # the baro height as the regressor: H_G − H_B = β·H_B + θ_V·V_G + θ_B with
        # β = −dSF/(1 + dSF), θ_V = (1 + dSF)·Td, θ_B = −B. Whitening boosts the high
        # frequencies, where GNSS height noise (≈ 2 m) would bias a GNSS-height regressor
        # (errors in variables, −σ_G²/var(H̃_G): −4 % on hill-drive); the baro's is 0.3 m.
        m = np.column_stack([hb, vg, np.ones(n)])
        dh = hg - hb
        assert noise is not None
        b_sd, b_tau = float(noise[0]), float(noise[1])
        # a constant bias (τ_b infinite) is B itself: only the drifting part is noise
        kern = np.exp(-np.abs(tt[:, None] - tt[None, :]) / b_tau) if np.isfinite(b_tau) \
            else np.zeros((n, n))
        chol = np.linalg.cholesky(b_sd**2 * kern + np.diag(w_sd**2))
        from scipy.linalg import solve_triangular

        m = solve_triangular(chol, m, lower=True)  # whitened design and data
        dh = solve_triangular(chol, dh, lower=True)
    # unit-RMS column scaling: conditioning of the problem, not of its units
    scl = np.sqrt(np.mean(m**2, axis=0))
    scl[scl == 0] = 1.0
    ms = m / scl
    sv = np.linalg.svd(ms, compute_uv=False)
    cond = float(sv[0] / sv[-1]) if sv[-1] > 0 else float("inf")
    theta_s, *_ = np.linalg.lstsq(ms, dh, rcond=None)
    theta = theta_s / scl
    resid = dh - m @ theta
    sigma2 = float(resid @ resid) / max(n - 3, 1)
    if gls:  # whitened: σ̂² is the fit ratio s²; never let it shrink the model's σ
        fit_ratio = sigma2
        sigma2 = max(1.0, sigma2)
    # (MᵀM)⁻¹σ̂² via the scaled design (pinv tolerates a singular design: the flag says so)
    cov = np.linalg.pinv(ms.T @ ms) / np.outer(scl, scl) * sigma2
    if gls:  # (β, θ_V, θ_B) → (dSF, θ_Td, B), first-order propagation
        beta = float(theta[0])
        s_hat = -beta / (1.0 + beta)
        theta_td, b_hat = float(theta[1]), -float(theta[2])
        j0 = np.diag([-1.0 / (1.0 + beta) ** 2, 1.0, -1.0])
        cov = j0 @ cov @ j0.T
    else:
        s_hat, theta_td, b_hat = (float(x) for x in theta)
    # θ_Td = (1 + dSF)·Td in the exact model (see module docstring); first-order propagation
    td_hat = theta_td / (1.0 + s_hat)
    j = np.array([[1.0, 0.0, 0.0], [-theta_td / (1 + s_hat) ** 2, 1.0 / (1 + s_hat), 0.0],
                  [0.0, 0.0, 1.0]])
    cov = j @ cov @ j.T
    sd = np.sqrt(np.maximum(np.diag(cov), 0.0))
    warns = _warnings(sd, cond, fit_ratio, n_out, velocity_source)
    return BaroCalibration(
        scale=s_hat, latency_s=td_hat, bias_m=b_hat, scale_sd=float(sd[0]),
        latency_sd=float(sd[1]), bias_sd=float(sd[2]), cov=cov, residual_sd=float(np.sqrt(
            sigma2)), n_epochs=int(n), condition=cond, velocity_source=velocity_source,
        warnings=tuple(warns), method="gls" if gls else "ols", outliers=n_out,
        fit_ratio=fit_ratio,
    )


def calibrate_baro(drive: Drive) -> BaroCalibration:
    """Seed-001 least-squares calibration of the drive's baro against its GNSS.

    The baro altitude (``BaroStream.altitude``; ISA altitude when only pressure is logged) is
    linearly interpolated to the GNSS epochs inside the baro span (bracketing samples at most
    ``MAX_BARO_GAP_S`` apart). V_G is the GNSS vertical velocity (−vel_n[:, 2]) when the
    receiver gives velocity, else the central difference of GNSS heights.

    Raises ValueError when the drive lacks GNSS or baro, or has fewer than 10 common epochs.
    """
    if drive.gnss is None or drive.baro is None:
        raise ValueError("calibrate-baro: the drive needs both GNSS and baro data")
    g, b = drive.gnss, drive.baro
    h0 = float(drive.origin_lla[2])
    tb, hb_all = b.t, b.altitude
    tg = g.t
    inside = (tg >= tb[0]) & (tg <= tb[-1])
    idx = np.clip(np.searchsorted(tb, tg), 1, tb.size - 1)
    gap = tb[idx] - tb[idx - 1] if tb.size > 1 else np.full(tg.shape, np.inf)
    use = inside & (gap <= MAX_BARO_GAP_S)
    hb = np.interp(tg, tb, hb_all)
    hg = g.lla[:, 2] - h0
    if g.vel_n is not None:
        vg = -g.vel_n[:, 2]
        src = "gnss_velocity"
    else:
        if tg.size < 3:
            raise ValueError("calibrate-baro: too few GNSS fixes to differentiate heights")
        vg = np.gradient(g.lla[:, 2], tg)
        src = "differentiated_height"
    from ...sensors.model import sensor_model

    model = sensor_model(drive)
    bp = model.baro
    assert bp is not None and model.gnss_pos_sd is not None
    w_sd = np.sqrt(bp.noise_sd**2 + model.gnss_pos_sd[:, 2] ** 2)
    return calibrate_arrays(hg[use], vg[use], hb[use] - h0, velocity_source=src, t=tg[use],
                            noise=(bp.bias_sd, bp.bias_tau, w_sd[use]))


def format_calibration(cal: BaroCalibration) -> str:
    """A small text table of the estimates ± standard errors, then the warnings."""
    how = ("generalised least squares with the Gauss-Markov baro bias" if cal.method == "gls"
           else "ordinary least squares")
    lines = [
        f"baro calibration vs GNSS (seed 001 eq. 4, {how}), {cal.n_epochs} epochs, "
        f"V_G from {cal.velocity_source.replace('_', ' ')}",
        f"{'parameter':<12}{'estimate':>14}{'std. error':>14}",
        f"{'dSF [%]':<12}{100 * cal.scale:>14.4f}{100 * cal.scale_sd:>14.4f}",
        f"{'Td [s]':<12}{cal.latency_s:>14.4f}{cal.latency_sd:>14.4f}",
        f"{'B [m]':<12}{cal.bias_m:>14.3f}{cal.bias_sd:>14.3f}",
        f"residual sd {cal.residual_sd:.3f} m, condition number {cal.condition:.3g}",
    ]
    lines += [f"warning: {w}" for w in cal.warnings]
    return "\n".join(lines)
