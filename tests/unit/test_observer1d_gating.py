"""GNSS innovation gate of the seed-003 observer: Lyapunov innovation variance, false-alarm rate
on clean data, unchanged seed-003 σ, isolated spike, re-initialisation after a persistent step."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from vnav_graph.estimators.vertical.observer1d import (
    Observer1D,
    gate_threshold,
    gate_var,
    observer_kernel_gated,
    steady_state,
)
from vnav_graph.simulation import simulate
from vnav_graph.studies.seed003 import seed003_monte_carlo

QA = 300e-6 * 9.80665  # consumer accelerometer noise density [m/s²/√Hz]


def test_gate_variance_equals_lyapunov_prior():
    ss = steady_state(gps_sd=2.0, accel_noise_density=QA, accel_bias_rw=1e-4)
    # S(τ = T) from the post-fix covariance is the a-priori Lyapunov covariance + R; both are
    # the same polynomial in T, so only round-off separates them
    s = gate_var(ss.p_post, 1.0, QA, 1e-4, 4.0)
    assert s == pytest.approx(ss.p_prior[0, 0] + 4.0, rel=1e-12)
    # 1-dof χ² quantile at 1 − 1e-3: 3.2905² (tables)
    assert np.sqrt(gate_threshold(1e-3)) == pytest.approx(3.2905, abs=1e-4)
    assert gate_threshold(None) == np.inf


@pytest.mark.parametrize("p_fa", [1e-3, 1e-2])
def test_false_alarm_rate_and_sigma_on_clean_seed003(p_fa):
    # no initial bias error: after the warm-up the innovations are N(0, S_ss) (linear loop in
    # its steady state), so the gate rejects p_fa of them
    ref = seed003_monte_carlo(200, 0, bias_error0=0.0)
    r = seed003_monte_carlo(200, 0, bias_error0=0.0, gate_prob=p_fa)
    n = 200 * 248  # gated fixes: 300 fixes minus the 52-s warm-up, 200 runs
    sd = np.sqrt(p_fa * (1 - p_fa) / n)
    # binomial σ of the fraction (innovations 1 s apart are correlated, ~×1.5 on σ); 5σ
    assert abs(r.rejected_fraction - p_fa) < 5 * 1.5 * sd
    assert r.n_reinit == 0  # 20 s of consecutive false alarms: probability ~p_fa^20
    # the rejected fixes are the largest 0.1 % (1 %) of the innovations: the σ moves by
    # 0.3 % (2 %) measured; 1 % (3 %) bounds
    assert abs(r.steady_sd_m / ref.steady_sd_m - 1) < (0.01 if p_fa == 1e-3 else 0.03)


def test_default_reproduction_is_ungated():
    r = seed003_monte_carlo(200, 0)
    # seed-003 reproduction (test_observer1d): unchanged, no gate in the Monte Carlo default
    assert r.rejected_fraction == 0.0 and r.n_reinit == 0
    assert abs(r.steady_sd_m - 1.2) < 0.15 * 1.2


def _kernel(z_fix, t_fix, reinit_s=20.0, p_fa=1e-3):
    t = np.arange(0.0, 200.0 + 1e-9, 0.01)
    ss = steady_state(gps_sd=2.0, accel_noise_density=QA)
    return observer_kernel_gated(
        t, np.zeros((1, t.size)), t_fix, z_fix[None, :], np.array([0.4, 0.04, 0.002]), False,
        np.array([[z_fix[0], 0.0, 0.0]]), 0.0, 0.0, 1, gate_threshold(p_fa), ss.p_post, QA,
        0.0, 4.0, 10.0, reinit_s)


def test_spike_rejected_equals_fix_removed():
    rng = np.random.default_rng(5)
    t_fix = np.arange(0.0, 200.0 + 1e-9, 1.0)
    z = rng.normal(size=t_fix.size) * 2.0
    z[100] += 60.0
    out = _kernel(z, t_fix)
    assert out[5][0, 100] == 1 and np.sum(out[5][0] == 1) == 1
    keep = np.arange(t_fix.size) != 100
    out2 = _kernel(z[keep], t_fix[keep])
    # a rejected fix changes nothing (the gate's τ also runs from the last accepted fix):
    # bit-identical trajectories
    np.testing.assert_array_equal(out[0], out2[0])


def test_persistent_step_reinitialises_after_reinit_s():
    t_fix = np.arange(0.0, 200.0 + 1e-9, 1.0)
    z = np.where(t_fix >= 100.0, 100.0, 0.0)  # noiseless, a 100 m datum jump at 100 s
    out = _kernel(z, t_fix, reinit_s=20.0)
    code = out[5][0]
    # fixes 100..119 rejected (span 19 s < 20 s), fix 120 re-initialises, then warm-up (10 s)
    # and the loop is on the new datum: all accepted
    assert np.flatnonzero(code == 1).tolist() == list(range(100, 120))
    assert np.flatnonzero(code == 2).tolist() == [120]
    assert out[3][0, 120] == 100.0  # re-initialised at the fix
    # zero input, v = 0 and c = 0 at the re-init: the state sits exactly on the new datum
    np.testing.assert_allclose(out[0][0, -100:], 100.0, atol=1e-9)


def test_estimator_spike_moves_altitude_less_than_gnss_noise():
    d = simulate("seed003", 2, duration_s=200.0)
    g = d.gnss
    lla = g.lla.copy()
    lla[120, 2] += 80.0  # one isolated 80 m spike (40 σ)
    d2 = dataclasses.replace(d, gnss=dataclasses.replace(g, lla=lla))
    e1 = Observer1D().run(d)
    e2 = Observer1D().run(d2)
    assert e1.info["gnss_rejected"] == 0  # clean 200 fixes at p_fa 1e-3: P(≥1) ≈ 15 %
    assert e2.info["gnss_rejected"] == 1
    # the spike still reaches the AHRS (velocity by differencing the positions), not the
    # height channel: it must not move the altitude by more than the GNSS σ (2 m)
    assert np.max(np.abs(e2.trajectory.alt - e1.trajectory.alt)) < 2.0
