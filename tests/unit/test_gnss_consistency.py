"""The GNSS velocity σ that the positions support (``sensors.gnss_consistency``)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from vnav_graph.sensors.gnss_consistency import (
    VEL_CONSISTENCY_LIMIT,
    velocity_consistency,
)

DT = 0.25  # s, a 4 Hz receiver
SP, SV = 0.01, 0.04  # m, m/s: an RTK receiver's stated σ


def _circle(n: int, speed: float = 10.0, radius: float = 50.0
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Times, NED positions and velocities of a level circle (centripetal a = v²/ρ)."""
    t = np.arange(n) * DT
    th = speed * t / radius
    p = np.column_stack([radius * np.sin(th), radius * (1 - np.cos(th)), np.zeros(n)])
    v = speed * np.column_stack([np.cos(th), np.sin(th), np.zeros(n)])
    return t, p, v


def _sd(n: int, s: float) -> np.ndarray:
    return np.full((n, 3), s)


def test_fixes_whose_sigma_hold_keep_it(rng) -> None:
    """White errors of the stated σ on a turning trajectory: R ≈ 1, nothing added."""
    n = 4000
    t, p, v = _circle(n)
    c = velocity_consistency(t, p + SP * rng.standard_normal((n, 3)), _sd(n, SP),
                             v + SV * rng.standard_normal((n, 3)), _sd(n, SV))
    assert c is not None and c.pairs == n - 1
    np.testing.assert_allclose(c.ratio, 1.0, atol=0.1)
    assert not c.raised and np.all(c.added_var == 0)


def test_interval_mean_velocity_gets_the_lag_error_as_sigma() -> None:
    """A receiver whose velocity at epoch k is the mean over the interval before it (the RTK
    car's): r_k = Δ²p/(2Δt), |Δ²p| = 4ρ sin²(θ/2) on a circle (θ = vΔt/ρ), so per horizontal
    axis mean r² = |r|²/2 and the added variance is 2(mean r² − var r) — the lag's error
    a·Δt/2 = 0.25 m/s at 2 m/s², less the stated σ's share."""
    n = 4001  # whole turns are not needed: ~6.4 revolutions average the phase
    speed, radius = 10.0, 50.0
    t, p, _ = _circle(n, speed, radius)
    v = np.vstack([np.zeros((1, 3)), np.diff(p, axis=0) / DT])
    c = velocity_consistency(t[1:], p[1:], _sd(n - 1, SP), v[1:], _sd(n - 1, SV))
    assert c is not None and c.raised
    th = speed * DT / radius
    r_abs = 4 * radius * np.sin(th / 2) ** 2 / (2 * DT)
    var_r = 2 * SP**2 / DT**2 + SV**2 / 2
    want = np.sqrt(2 * (r_abs**2 / 2 - var_r))
    np.testing.assert_allclose(np.sqrt(c.added_var[:2]), want, rtol=0.03)
    assert c.ratio[2] == 0.0 and c.added_var[2] == 0.0  # level: nothing on the down axis
    assert abs(r_abs - (speed**2 / radius) * DT / 2) < 0.001  # the small-angle form


def test_small_excess_is_not_raised(rng) -> None:
    """Velocity noise 1.2× its stated σ on a 4 Hz RTK receiver (R ≈ 1.1) stays below
    ``VEL_CONSISTENCY_LIMIT``; 3× it (R ≈ 2.7 east) is raised on that axis only."""
    n = 3000
    t, p, v = _circle(n)
    pn = p + SP * rng.standard_normal((n, 3))
    for k, raised in ((1.2, False), (3.0, True)):
        vn = v + SV * rng.standard_normal((n, 3)) * np.array([1.0, k, 1.0])
        c = velocity_consistency(t, pn, _sd(n, SP), vn, _sd(n, SV))
        assert c is not None
        assert c.raised == raised
        assert c.added_var[0] == 0.0 and c.added_var[2] == 0.0
        if raised:
            assert c.ratio[1] > VEL_CONSISTENCY_LIMIT


def test_one_position_glitch_does_not_raise(rng) -> None:
    """A 100 m jump of one fix among 300 at 1 Hz (σp 3 m): its two pairs are capped at 5σ
    and R stays below the limit; uncapped, R would be ~4.7."""
    n = 300
    t = np.arange(n) * 1.0
    v = np.tile([5.0, 0.0, 0.0], (n, 1))
    p = np.cumsum(np.vstack([np.zeros((1, 3)), v[1:]]), axis=0)
    pn = p + 3.0 * rng.standard_normal((n, 3))
    vn = v + 0.1 * rng.standard_normal((n, 3))
    pn[150, 0] += 100.0
    c = velocity_consistency(t, pn, _sd(n, 3.0), vn, _sd(n, 0.1))
    assert c is not None and not c.raised
    r = np.diff(pn[:, 0]) - 0.5 * (vn[1:, 0] + vn[:-1, 0])
    assert np.mean(r**2) / (2 * 9.0 + 0.005) > 2 * VEL_CONSISTENCY_LIMIT


def test_gaps_and_too_few_pairs(rng) -> None:
    """Pairs across a gap longer than 2.5 s are not compared; under 20 pairs: no verdict."""
    n = 40
    t, p, v = _circle(n)
    t = t.copy()
    t[20:] += 30.0  # a withheld window
    c = velocity_consistency(t, p, _sd(n, SP), v, _sd(n, SV))
    assert c is not None and c.pairs == n - 2
    assert velocity_consistency(t[:15], p[:15], _sd(15, SP), v[:15], _sd(15, SV)) is None


def test_sensor_model_raises_a_lagged_velocity_and_keeps_a_consistent_one() -> None:
    """On a simulated drive (σ that hold) the model's velocity σ are the receiver's. Its fixes
    thinned to 1 Hz, at the true positions, with each velocity the mean over the second
    before it (the RTK car's receiver does this at 4 Hz) and a 1 cm / 4 cm/s σ: the velocity
    σ are raised and the note says so."""
    from vnav_graph.geo.frames import lla_to_ned
    from vnav_graph.sensors.gnss_model import GNSS_SD_FLOOR
    from vnav_graph.sensors.model import sensor_model
    from vnav_graph.simulation import simulate

    drive = simulate("hill-drive", seed=0)
    g = drive.gnss
    m = sensor_model(drive)
    np.testing.assert_array_equal(m.gnss_vel_sd, np.maximum(g.vel_sd, GNSS_SD_FLOOR))
    assert m.gnss_vel_note() == "" and m.gnss_vel_check is not None
    assert np.all(m.gnss_vel_check.ratio < VEL_CONSISTENCY_LIMIT)

    g1 = g.select(np.arange(g.t.size) % 10 == 0)
    truth = drive.truth.at(g1.t)
    p = lla_to_ned(truth.lla, drive.origin_lla)
    v = np.vstack([truth.vel_n[:1], np.diff(p, axis=0) / np.diff(g1.t)[:, None]])
    lagged = replace(g1, lla=truth.lla, vel_n=v, pos_sd=np.full_like(g1.pos_sd, SP),
                     vel_sd=np.full_like(g1.vel_sd, SV))
    m2 = sensor_model(drive.replace(gnss=lagged))
    assert m2.gnss_vel_check is not None and m2.gnss_vel_check.raised
    assert np.all(m2.gnss_vel_sd[:, :2] > SV)
    assert "GNSS velocity σ raised" in m2.gnss_vel_note()


def test_position_outliers_are_left_out(rng) -> None:
    """10 % of a 10 Hz drive's fixes moved by 10–40 m (σp 1 m): each makes its two pairs
    opposite 5σ residuals, so they are left out as position spikes and R stays ≈ 1; with
    them in, the capped R is ≈ 4 on every axis."""
    n, dt = 3000, 0.1
    t = np.arange(n) * dt
    v = np.tile([10.0, 2.0, 0.0], (n, 1))
    p = np.cumsum(np.vstack([np.zeros((1, 3)), v[1:] * dt]), axis=0)
    pn = p + rng.standard_normal((n, 3))
    vn = v + 0.1 * rng.standard_normal((n, 3))
    bad = rng.choice(np.arange(1, n - 1), size=n // 10, replace=False)
    off = rng.standard_normal((bad.size, 3))
    off *= (rng.uniform(10.0, 40.0, bad.size) / np.linalg.norm(off, axis=1))[:, None]
    pn[bad] += off
    c = velocity_consistency(t, pn, _sd(n, 1.0), vn, _sd(n, 0.1))
    assert c is not None and not c.raised
    # isolated outliers are all found (adjacent pairs of outliers may hide each other)
    isolated = np.setdiff1d(bad, np.concatenate([bad - 1, bad + 1]))
    assert c.spikes >= isolated.size
    np.testing.assert_allclose(c.ratio, 1.0, atol=0.25)
    r = np.diff(pn, axis=0) / dt - 0.5 * (vn[1:] + vn[:-1])
    var = 2 * 1.0 / dt**2 + 0.5 * 0.01
    assert np.all(np.mean(np.minimum(r**2 / var, 25.0), axis=0) > 2 * VEL_CONSISTENCY_LIMIT)


def test_excess_is_not_put_on_velocities_that_cannot_carry_it(rng) -> None:
    """Positions whose real scatter is 3× their stated 1 m at 10 Hz: R ≈ 9, but the
    velocities' share of var r is 0.25 %, so the excess is reported as unattributed and
    no σ is added (it would be ≈ 40 m/s)."""
    n, dt = 2000, 0.1
    t = np.arange(n) * dt
    v = np.tile([10.0, 0.0, 0.0], (n, 1))
    p = np.cumsum(np.vstack([np.zeros((1, 3)), v[1:] * dt]), axis=0)
    c = velocity_consistency(t, p + 3.0 * rng.standard_normal((n, 3)), _sd(n, 1.0),
                             v + 0.1 * rng.standard_normal((n, 3)), _sd(n, 0.1))
    assert c is not None and np.all(c.ratio > 5.0)
    assert c.unattributed == (True, True, True) and not c.raised
