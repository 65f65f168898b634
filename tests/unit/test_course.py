"""``nav.course``: the GNSS course as a heading, its σ in closed form and its test."""

from __future__ import annotations

import numpy as np
import pytest

from vnav_graph.nav.course import (
    COURSE_SNR,
    SWAY_MIN_FIXES,
    course_heading,
    course_sd,
    gyro_yaw,
    sway_sd,
)


def test_sigma_is_the_cross_track_noise_over_the_speed_plus_the_sideslip() -> None:
    # walking: 1.2 m/s with 0.05 m/s per axis, 2° sideslip: √(0.0417² + 0.0349²) rad
    sd = course_sd(np.array([1.2]), np.array([0.05]), np.radians(2.0))[0]
    assert sd == pytest.approx(np.hypot(0.05 / 1.2, np.radians(2.0)), rel=1e-12)
    assert np.degrees(sd) == pytest.approx(3.11, abs=0.01)
    # no sideslip: exactly σ_v/|v|, halving with twice the speed
    s1, s2 = course_sd(np.array([2.0, 4.0]), np.array([0.1, 0.1]), 0.0)
    assert s1 == pytest.approx(0.05) and s2 == pytest.approx(0.025)


def test_no_course_at_or_below_the_threshold() -> None:
    vsd = 0.1
    v = np.array([COURSE_SNR * vsd * 0.999, COURSE_SNR * vsd * 1.001, 0.0])
    sd = course_sd(v, np.full(3, vsd), 0.0)
    assert sd[0] == np.pi and sd[2] == np.pi
    assert sd[1] == pytest.approx(1.0 / (COURSE_SNR * 1.001))  # at most 1/k = 11.5°


def test_threshold_false_alarm_rate_at_a_standstill() -> None:
    # |v_h|²/σ_v² is χ²₂ at rest: P(|v_h| > kσ) = exp(−k²/2) = 3.7e-6 for k = 5
    rng = np.random.default_rng(0)
    v = rng.normal(0.0, 1.0, (2_000_000, 2))
    frac = np.mean(course_sd(np.hypot(v[:, 0], v[:, 1]), np.ones(len(v)), 0.0) < np.pi)
    assert frac == pytest.approx(np.exp(-COURSE_SNR**2 / 2), abs=4e-6)
    k3 = np.mean(np.hypot(v[:, 0], v[:, 1]) > 3.0)  # the statistic itself (the check can fail)
    assert k3 == pytest.approx(np.exp(-4.5), rel=0.02)


def test_sway_is_the_scatter_of_course_against_the_gyro_heading() -> None:
    t = np.arange(0.0, 10.0, 0.25)
    yaw_g = 0.1 * t  # a turning body
    steady = sway_sd(t, yaw_g + 0.3, np.ones(t.size, bool), yaw_g)  # constant crab: no scatter
    assert np.all(np.isnan(steady[:SWAY_MIN_FIXES - 1]))
    assert np.nanmax(steady) < 1e-6
    # a course swinging ±a about the body heading (a walker's sway) has scatter ≈ a/√2
    a = np.radians(20.0)
    swing = yaw_g + a * np.where(np.arange(t.size) % 2, 1.0, -1.0)
    sw = sway_sd(t, swing, np.ones(t.size, bool), yaw_g)
    # the window [t − 2 s, t] holds 9 fixes, 5 at −a and 4 at +a (or the other way):
    # R = |cos a + i sin a / 9|, σ = √(−2 ln R) ≈ a
    r = np.hypot(np.cos(a), np.sin(a) / 9.0)
    assert sw[-1] == pytest.approx(np.sqrt(-2.0 * np.log(r)), rel=1e-9)
    assert np.degrees(sw[-1]) == pytest.approx(20.1, abs=0.1)


def test_course_heading_takes_the_larger_of_floor_and_sway() -> None:
    t = np.arange(0.0, 10.0, 0.25)
    n = t.size
    a = np.radians(20.0)
    psi = np.radians(30.0) + a * np.where(np.arange(n) % 2, 1.0, -1.0)
    vel = 1.2 * np.column_stack([np.cos(psi), np.sin(psi)])
    c = course_heading(t, vel, np.full(n, 0.05), np.radians(2.0), np.zeros(n))
    assert c.yaw == pytest.approx(np.arctan2(np.sin(psi), np.cos(psi)))
    assert c.speed == pytest.approx(np.full(n, 1.2))
    beta = np.sqrt(-2.0 * np.log(np.hypot(np.cos(a), np.sin(a) / 9.0)))  # 9 fixes in 2 s
    assert c.yaw_sd[-1] == pytest.approx(np.hypot(0.05 / 1.2, beta), rel=1e-9)
    assert np.all(c.yaw_sd[:SWAY_MIN_FIXES - 1] == np.pi)  # too few fixes for a scatter
    # without the gyro heading: the floor alone
    c0 = course_heading(t, vel, np.full(n, 0.05), np.radians(2.0))
    assert c0.yaw_sd[-1] == pytest.approx(np.hypot(0.05 / 1.2, np.radians(2.0)))


def test_gyro_yaw_integrates_the_z_rate() -> None:
    t = np.linspace(0.0, 10.0, 1001)
    assert gyro_yaw(t, np.full(t.size, 0.2), np.array([0.0, 5.0, 10.0])) == pytest.approx(
        [0.0, 1.0, 2.0])


def test_a_one_hertz_receiver_gets_a_course_from_its_third_moving_fix() -> None:
    t = np.arange(0.0, 10.0, 1.0) + 0.003 * np.sin(np.arange(10.0))  # 1 Hz with jitter
    vel = np.tile([1.2, 0.0], (t.size, 1))
    c = course_heading(t, vel, np.full(t.size, 0.05), np.radians(2.0), np.zeros(t.size))
    assert np.all(c.yaw_sd[:2] == np.pi)
    assert c.yaw_sd[2:] == pytest.approx(np.hypot(0.05 / 1.2, np.radians(2.0)))
