"""Seed 003 study: Monte Carlo of the 1-DOF INS/GPS altitude observer against the paper.

The paper (seed 003) reports ≈ 1.2 m steady altitude σ with GPS σ 2 m at 1 Hz and gains
L = [0.4, 0.04, 0.002], ≈ 50 s settling. ``seed003_monte_carlo`` reproduces those numbers on
simulated vertical drives through the ``observer1d`` estimator's kernel;
``compare_discretisations`` compares its zero-order-hold and Tustin propagation. Study code:
used by ``benchmarks/reproduce_seeds.py`` and the tests, not by any estimator.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..estimators.vertical.observer1d import (
    SEED003_GAIN,
    SteadyState,
    analytic_settling,
    gate_threshold,
    observer_kernel,
    observer_kernel_gated,
    steady_state,
)
from ..types.streams import FloatArray


@dataclass(frozen=True)
class Seed003Result:
    """Monte Carlo result of ``seed003_monte_carlo``.

    steady_sd_m : RMS over runs and over the IMU epochs of [t_steady, end] of the altitude
        error about its ensemble mean [m] (the continuous output, as the seed plots it)
    steady_sd_post_m / steady_sd_prior_m : same, only just after / just before the fixes
    gps_only_sd_m : RMS of the GPS altitude errors [m]
    settling_s : settling time (module docstring), from the ensemble-mean error
    analytic : the ``SteadyState`` for the same noise; analytic_settling_s
    mean_error_m : (M,) ensemble-mean altitude error just after each fix; t_fix : (M,)
    rejected_fraction : fraction of the gated fixes (after the warm-up) that the GNSS gate
        rejected (0 without gate); n_reinit : re-initialisations over all runs
    """

    steady_sd_m: float
    steady_sd_post_m: float
    steady_sd_prior_m: float
    gps_only_sd_m: float
    settling_s: float
    analytic: SteadyState
    analytic_settling_s: float
    n_runs: int
    discretisation: str
    mean_error_m: FloatArray
    t_fix: FloatArray
    rejected_fraction: float = 0.0
    n_reinit: int = 0


def seed003_monte_carlo(
    n_runs: int = 200, seed0: int = 0, *, duration_s: float = 300.0,
    discretisation: str = "zoh", accel_noise_density: float | None = None,
    accel_bias_rw: float = 0.0, bias_error0: float = 2.0, gps_sd: float | None = None,
    t_steady: float = 150.0, settle_tol: float = 0.10, gain=SEED003_GAIN,
    gate_prob: float | None = None, warmup_s: float | None = None, reinit_s: float = 20.0,
) -> Seed003Result:
    """Monte Carlo of the seed-003 observer on the seed003 scenario's trajectory.

    The truth (vertical profile, IMU rate, GPS epochs) is ``simulate("seed003", seed0)``; each
    run draws its own accelerometer noise (white, ``accel_noise_density`` — default the
    scenario's consumer preset, 300 µg/√Hz — per-sample σ = density/√h), bias random walk
    (``accel_bias_rw`` [m/s²/√s]) and GPS altitude noise (σ ``gps_sd``, default the scenario's
    2 m). All runs share a constant accelerometer bias ``bias_error0`` [m/s²] (the observer
    starts with ĉ = 0, so this is its initial correction error) — it defines the settling
    transient: settling_s is the last fix time (from the first fix) at which |ensemble-mean
    altitude error| exceeds ``settle_tol`` × its peak (see the module docstring). The
    observer starts at the first fix altitude, v̂ = 0.
    Because the loop is linear, its error does not depend on the trajectory; using the real
    one also exercises the discretisation on a moving profile.
    Run count and seed: run r uses ``np.random.default_rng([seed0, r])``.
    ``gate_prob`` (default None: the seed's ungated observer) switches on the GNSS gate of
    ``Observer1D`` with the same noise model (``warmup_s`` None: the analytic settling time).
    """
    from ..simulation import load_scenario, simulate

    cfg = load_scenario("seed003", duration_s=duration_s)
    d = simulate(cfg, seed0)
    t = d.imu.t
    h = float(np.median(np.diff(t)))
    qa = cfg.imu.accel_noise_density if accel_noise_density is None else accel_noise_density
    sd_g = cfg.gnss.pos_sd_v if gps_sd is None else gps_sd
    z_true = d.truth.alt
    a_true = -np.gradient(d.truth.vel_n[:, 2], t)  # up acceleration (smooth profile)
    t_fix = d.gnss.t
    z_true_fix = np.interp(t_fix, t, z_true)
    n, m = t.size, t_fix.size
    a_meas = np.empty((n_runs, n))
    z_fix = np.empty((n_runs, m))
    for r in range(n_runs):
        rng = np.random.default_rng([seed0, r])
        b = bias_error0 + np.concatenate(
            [[0.0], np.cumsum(rng.normal(size=n - 1) * accel_bias_rw * np.sqrt(h))])
        a_meas[r] = a_true + b + rng.normal(size=n) * qa / np.sqrt(h)
        z_fix[r] = z_true_fix + rng.normal(size=m) * sd_g
    # the observer's c is an additive correction: v̇ = a_meas + c, so c must learn −bias
    x0 = np.column_stack([z_fix[:, 0], np.zeros(n_runs), np.zeros(n_runs)])
    # start at the first fix: drop the IMU epochs before it
    k0 = int(np.searchsorted(t, t_fix[0] - 1e-9))
    stride = 1
    period = float(np.median(np.diff(t_fix)))
    ana = steady_state(gain, period, sd_g, qa, accel_bias_rw)
    warm = analytic_settling(gain, period) if warmup_s is None else warmup_s
    z, _, _, z_post, z_prior, code, _ = observer_kernel_gated(
        t[k0:], np.ascontiguousarray(a_meas[:, k0:]), t_fix, z_fix, np.asarray(gain, float),
        discretisation == "tustin", x0, 0.0, 0.0, stride, gate_threshold(gate_prob),
        ana.p_post, qa, accel_bias_rw, sd_g**2, warm, reinit_s,
    )
    gated = t_fix >= t_fix[0] + warm
    n_gated = int(np.sum(code[:, gated] >= 0))
    rej_frac = float(np.sum(code[:, gated] == 1) / max(n_gated, 1))
    err = z - z_true[k0:][None, :]
    mean_err = err.mean(axis=0)
    ss = t[k0:] >= t_steady
    steady_sd = float(np.sqrt(np.mean((err[:, ss] - mean_err[ss]) ** 2)))
    e_post = z_post - z_true_fix[None, :]
    e_prior = z_prior - z_true_fix[None, :]
    sf = t_fix >= t_steady
    sd_post = float(np.sqrt(np.mean((e_post[:, sf] - e_post[:, sf].mean(0)) ** 2)))
    sd_prior = float(np.sqrt(np.mean((e_prior[:, sf] - e_prior[:, sf].mean(0)) ** 2)))
    gps_only = float(np.sqrt(np.mean((z_fix - z_true_fix[None, :]) ** 2)))
    me = np.abs(e_post.mean(axis=0))
    settle = float(t_fix[np.flatnonzero(me > settle_tol * me.max())[-1]] - t_fix[0])
    return Seed003Result(
        steady_sd, sd_post, sd_prior, gps_only, settle, ana,
        analytic_settling(gain, period, settle_tol), n_runs,
        discretisation, e_post.mean(axis=0), t_fix, rej_frac, int(np.sum(code == 2)),
    )


def seed003_noise_for_sigma(target_sd: float = 1.2, gps_sd: float = 2.0) -> float:
    """Accelerometer noise density [m/s²/√Hz] for which the analytic time-averaged steady
    σ (``SteadyState.sd_mean``) equals ``target_sd`` (bisection)."""
    lo, hi = 0.0, 10.0
    for _ in range(100):
        mid = 0.5 * (lo + hi)
        if steady_state(gps_sd=gps_sd, accel_noise_density=mid).sd_mean < target_sd:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


@dataclass(frozen=True)
class DiscretisationComparison:
    """INS-only (no fixes) altitude difference ZOH − Tustin on the seed003 truth input, and
    the Monte Carlo steady σ with each discretisation."""

    ins_only_max_diff_m: float
    steady_sd_zoh_m: float
    steady_sd_tustin_m: float


def compare_discretisations(n_runs: int = 200, seed0: int = 0,
                            duration_s: float = 300.0) -> DiscretisationComparison:
    """ZOH vs Tustin: free-inertial altitude on the noiseless seed003 input, and MC σ."""
    from ..simulation import simulate

    d = simulate("seed003", seed0, duration_s=duration_s)
    t = d.imu.t
    a = -np.gradient(d.truth.vel_n[:, 2], t)[None, :]
    x0 = np.array([[d.truth.alt[0], 0.0, 0.0]])
    none_t = np.empty(0)
    none_z = np.empty((1, 0))
    g = np.zeros(3)
    zz = observer_kernel(t, a, none_t, none_z, g, False, x0, 0.0, 0.0, 1)[0]
    zt = observer_kernel(t, a, none_t, none_z, g, True, x0, 0.0, 0.0, 1)[0]
    mz = seed003_monte_carlo(n_runs, seed0, duration_s=duration_s, discretisation="zoh")
    mt = seed003_monte_carlo(n_runs, seed0, duration_s=duration_s, discretisation="tustin")
    return DiscretisationComparison(float(np.max(np.abs(zz - zt))), mz.steady_sd_m,
                                    mt.steady_sd_m)
