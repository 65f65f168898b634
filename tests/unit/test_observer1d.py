"""Seed 003 reproduction: 1-DOF INS + GPS altitude observer with L = [0.4, 0.04, 0.002]."""

from __future__ import annotations

import numpy as np
import pytest

from vnav_graph.estimators.vertical.observer1d import (
    Observer1D,
    ObserverConfig,
    analytic_settling,
    observer_kernel,
    steady_state,
)
from vnav_graph.simulation import simulate
from vnav_graph.studies.seed003 import seed003_monte_carlo, seed003_noise_for_sigma


@pytest.fixture(scope="module")
def mc_zoh():
    # 200 runs × 300 s at 100 Hz (seed 003's Monte Carlo); ~1 s vectorised
    return seed003_monte_carlo(200, 0)


def test_seed003_steady_sigma_and_settling(mc_zoh):
    r = mc_zoh
    # seed 003: "final value near 1.2 m", GPS alone 2 m; ±15 % band
    assert abs(r.steady_sd_m - 1.2) < 0.15 * 1.2
    # GPS-alone σ is the simulated 2 m; 200×300 draws give ±0.4 % (1σ) -> 2 % tolerance
    assert abs(r.gps_only_sd_m - 2.0) < 0.04
    # seed 003: "around 50 samples" at 1 Hz; band 30-80 s
    assert 30.0 <= r.settling_s <= 80.0
    # the Monte Carlo settling equals the analytic one (same definition) to one sample
    assert abs(r.settling_s - r.analytic_settling_s) <= 1.0


def test_monte_carlo_matches_lyapunov(mc_zoh):
    r = mc_zoh
    a = r.analytic
    # ~200 runs × 150 s / ~18 s correlation ≈ 1700 independent samples -> σ estimate ±1.7 %;
    # 6 % is 3.5σ
    assert abs(r.steady_sd_m / a.sd_mean - 1) < 0.06
    assert abs(r.steady_sd_post_m / a.sd_post - 1) < 0.06
    assert abs(r.steady_sd_prior_m / a.sd_prior - 1) < 0.06
    # just before a fix the error is larger than just after (prediction then correction)
    assert a.sd_prior > a.sd_mean > a.sd_post


def test_closed_loop_eigenvalues():
    a = steady_state()
    lam = np.sort_complex(a.eigenvalues)
    # characteristic polynomial of (I − LH)Φ, Φ = [[1,1,.5],[0,1,1],[0,0,1]], L = [.4,.04,.002]:
    # det(zI − A_cl) = z³ + (l1 + l2 + l3/2 − 3) z² + (3 − 2 l1 − l2 + l3/2) z + (l1 − 1)
    l1, l2, l3 = 0.4, 0.04, 0.002
    ref = np.sort_complex(np.roots([1, l1 + l2 + l3 / 2 - 3, 3 - 2 * l1 - l2 + l3 / 2, l1 - 1]))
    np.testing.assert_allclose(lam, ref, atol=1e-12)  # round-off only
    assert analytic_settling() == 49.0  # exact integer result of the definition


def test_noise_level_for_exact_seed_value():
    q = seed003_noise_for_sigma(1.2)
    # the seed's 1.2 m needs ~32× the MPU-9250 noise density; check by re-evaluation
    assert abs(steady_state(accel_noise_density=q).sd_mean - 1.2) < 1e-6
    assert 20 * 300e-6 * 9.80665 < q < 50 * 300e-6 * 9.80665


def test_zoh_vs_tustin_ins_only_closed_form():
    """Free-inertial altitude: ZOH holds a_k over each step, Tustin averages a_k and a_{k+1}.
    Summing, v_zoh − v_tus = (h/2)(a_0 − a(t)) and z_zoh − z_tus = (h/2)(a_0 t − v(t) + v_0)
    + O(h²). The seed003 profile starts at rest (a_0 = 0, v_0 = 0)."""
    d = simulate("seed003", 0, duration_s=200.0)
    t = d.imu.t
    h = t[1] - t[0]
    v_up = -d.truth.vel_n[:, 2]
    a = np.gradient(v_up, t)[None, :]
    x0 = np.array([[0.0, 0.0, 0.0]])
    args = (np.empty(0), np.empty((1, 0)), np.zeros(3))
    zz = observer_kernel(t, a, *args, False, x0, 0.0, 0.0, 1)[0][0]
    zt = observer_kernel(t, a, *args, True, x0, 0.0, 0.0, 1)[0][0]
    pred = -(h / 2) * (v_up - v_up[0]) + (h / 2) * a[0, 0] * (t - t[0])
    # O(h²) remainder: (h²/4)|a_0 − a(t)| < 1e-4 m; tolerance 1e-4 m
    np.testing.assert_allclose(zz - zt, pred, atol=1e-4)


def test_zoh_and_tustin_steady_sigma_agree(mc_zoh):
    mt = seed003_monte_carlo(200, 0, discretisation="tustin")
    # Φ is identical (A nilpotent); only the input sampling differs, which changes the
    # integrated noise by O(h): relative difference < 0.1 %
    assert abs(mt.steady_sd_m / mc_zoh.steady_sd_m - 1) < 1e-3


@pytest.mark.parametrize("disc", ["zoh", "tustin"])
def test_estimator_on_seed003_drives(disc):
    errs = []
    for seed in (1, 2, 3):
        d = simulate("seed003", seed)
        est = Observer1D(ObserverConfig(discretisation=disc)).run(d)
        assert est.provides == frozenset({"alt", "vel_d"})
        assert np.all(np.isnan(est.trajectory.lla[:, :2]))
        assert np.all(np.isnan(est.trajectory.vel_n[:, :2]))
        m = est.trajectory.t >= 100.0
        errs.append(est.trajectory.alt[m] - d.truth.alt[m])
    rms = np.sqrt(np.mean(np.concatenate(errs) ** 2))
    # 3 runs × 200 s / ~18 s correlation ≈ 33 independent samples -> ±12 % (1σ) on the RMS;
    # the full chain (AHRS, gravity feedback) adds < 1 %. 35 % ≈ 3σ.
    assert abs(rms / steady_state().sd_mean - 1) < 0.35
