"""The GNSS residual autocorrelation (``sensors.gnss_residuals``) against closed forms: a
first-order Gauss-Markov series has ρ(L) = exp(−L/τ), white noise ρ = 0."""

from __future__ import annotations

import numpy as np
import pytest

from vnav_graph.sensors.gnss_residuals import MIN_PAIRS, autocorr_at, lag_pairs
from vnav_graph.simulation.noise import gauss_markov


@pytest.mark.parametrize("tau", [10.0, 30.0, 120.0])
def test_gauss_markov_series_gives_its_closed_form(tau):
    rng = np.random.default_rng(int(tau))
    t = np.arange(0.0, 20000.0, 0.2)  # 5 Hz, 1e5 samples: ~170 correlation times at τ 120 s
    x = gauss_markov(t, tau, 1.0, rng, 1)[:, 0]
    rho = autocorr_at(t, x, 5.0)
    # sampling σ of ρ̂ ≈ √(2τ/T) (Bartlett): 0.03 at τ 10 s … 0.11 at τ 120 s; 3σ
    assert rho == pytest.approx(np.exp(-5.0 / tau), abs=3 * np.sqrt(2 * tau / 20000.0))


def test_white_noise_is_uncorrelated_and_gaps_are_skipped():
    rng = np.random.default_rng(3)
    t = np.arange(0.0, 2000.0, 0.2)
    t = t[(t < 500.0) | (t > 520.0)]  # an outage: pairs across it are not at the lag
    x = rng.normal(size=t.size)
    rho = autocorr_at(t, x, 5.0)
    assert abs(rho) < 4 / np.sqrt(t.size)  # ρ̂ of white noise: σ 1/√N
    assert autocorr_at(t[:MIN_PAIRS], x[:MIN_PAIRS], 5.0) is None


def test_pair_count_of_the_diagnostic():
    t = np.arange(0.0, 100.0, 1.0)
    i, j = lag_pairs(t, 5.0)
    assert i.size == 95 and np.all(t[j] - t[i] == 5.0)
