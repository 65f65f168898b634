"""The EKF-vs-graph study scenarios (cold-start, cold-start-posonly, cold-start-phone, urban,
long-outage, hot-baro): each loads, simulates, and has what its TOML header promises."""

import numpy as np
import pytest

from vnav_graph.geo.atmosphere import T0, L
from vnav_graph.simulation import list_scenarios, load_scenario, simulate
from vnav_graph.simulation.trajectories import hill_drive_profiles

STUDY = ["cold-start", "cold-start-posonly", "cold-start-phone", "urban", "long-outage",
         "hot-baro"]


@pytest.mark.parametrize("name", STUDY)
def test_study_scenario_loads_and_simulates(name):
    assert name in list_scenarios()
    cfg = load_scenario(name)
    assert cfg.name == name
    assert cfg.description and "\n" not in cfg.description
    d = simulate(name, 0, duration_s=120.0)
    assert d.imu.t[-1] == pytest.approx(120.0)
    assert d.gnss is not None and d.baro is not None and d.gnss.t.size > 100
    assert np.all(np.isfinite(d.gnss.lla)) and np.all(np.isfinite(d.baro.altitude))


def test_cold_start_moves_at_once():
    cfg = load_scenario("cold-start")
    assert cfg.params["static_s"] == 0.0
    d = simulate(cfg, 0, duration_s=30.0)
    speed = np.linalg.norm(d.truth.vel_n, axis=1)
    assert speed[0] == 0.0  # from rest …
    assert np.max(speed[d.truth.t <= 2.0]) > 0.5  # … and moving within 2 s: no standstill
    assert d.gnss.t[0] == pytest.approx(0.1) and d.gnss.vel_n is not None
    # the same on many seeds, from the trajectory profiles alone (cheap)
    for seed in range(50):
        sp, _, _ = hill_drive_profiles(cfg.duration_s, np.random.default_rng([seed, 1]),
                                       **cfg.params)
        v = sp.eval(np.array([0.0, 2.0]))[0]
        assert v[0] == 0.0 and v[1] > 0.5, seed


def test_cold_start_posonly_is_cold_start_without_velocity():
    a = simulate("cold-start", 4, duration_s=60.0)
    b = simulate("cold-start-posonly", 4, duration_s=60.0)
    assert b.gnss.vel_n is None and b.gnss.vel_sd is None
    assert a.gnss.vel_n is not None
    # same truth, IMU samples and GNSS positions: only the velocity output is missing
    np.testing.assert_array_equal(a.truth.lla, b.truth.lla)
    np.testing.assert_array_equal(a.imu.gyro_b, b.imu.gyro_b)
    np.testing.assert_array_equal(a.gnss.lla, b.gnss.lla)


def test_urban_has_bursts_random_outages_and_nominal_sd():
    d = simulate("urban", 0)
    g = d.gnss
    m = d.meta
    assert m["gnss_burst_windows"] and m["gnss_random_outages"]
    # all outages (here only random ones) are in gnss_outages, for the plots to shade
    assert m["gnss_outages"] == m["gnss_random_outages"]
    for a, b in m["gnss_random_outages"]:
        assert not np.any((g.t >= a) & (g.t < b))
    in_burst = np.zeros(g.t.size, dtype=bool)
    for a, b in m["gnss_burst_windows"]:
        in_burst |= (g.t >= a) & (g.t < b)
    assert in_burst.sum() == m["gnss_burst_fixes"] > 0
    # reported σ: sqrt(0.5² + 2.5²) and sqrt(1² + 4²) at every fix, bursts included
    np.testing.assert_allclose(g.pos_sd, np.tile([np.hypot(0.5, 2.5)] * 2 + [np.hypot(1, 4)],
                                                 (g.t.size, 1)))
    speed = np.linalg.norm(d.truth.vel_n, axis=1)
    assert np.max(speed) < 14.5  # city speeds (speed_range_mps = [4, 14])


def test_long_outage_has_three_180_s_outages_without_fixes():
    d = simulate("long-outage", 1)
    assert d.meta["gnss_outages"] == [[250.0, 430.0], [600.0, 780.0], [950.0, 1130.0]]
    t = d.gnss.t
    for a, b in d.meta["gnss_outages"]:
        assert b - a == 180.0
        assert not np.any((t >= a) & (t < b))
        k = (d.truth.t >= a) & (d.truth.t < b)
        # the windows hold climbs or descents and turns (checked on seeds 0-5 in the TOML)
        assert np.max(np.abs(d.truth.vel_n[k, 2])) > 0.5
        yaw = np.unwrap(d.truth.to_rph()[k, 2])
        assert np.ptp(yaw) > np.radians(30.0)


def test_hot_baro_has_pressure_and_the_stated_effective_scale():
    d = simulate("hot-baro", 0, duration_s=120.0)
    spec = d.baro.spec
    assert d.baro.pressure is not None and d.baro.alt is None
    assert d.baro_truth.latency_s == spec.latency_s == 0.3
    # Standard-law altimeter in an ISA + dT troposphere, its setting exact at h0: with
    # T(h) = T0 + dT − L·h the pressure is p0·(T(h)/(T0 + dT))^(g/RL), the reading
    # (T0/L)·(1 − k·T(h)/(T0 + dT)), so its slope against the true height is
    # (T0 − L·h0)/(T0 − L·h0 + dT) at every height. The sensor's own scale s enters as
    # dT = (T0 + ΔT)/(1 + s) − T0 (a standard day read with scale s needs dT = −s·T0/(1 + s)).
    s, h0 = spec.scale, d.origin_lla[2]
    dT = (T0 + spec.isa_offset_k) / (1.0 + s) - T0
    t_h0 = T0 - L * h0
    assert d.baro_truth.scale == pytest.approx(t_h0 / (t_h0 + dT) - 1.0, rel=1e-9)
    assert (s, spec.isa_offset_k, h0) == (-0.03, 15.0, 890.0)  # the TOML's inputs


def test_urban_drive_round_trips_through_npz(tmp_path):
    from vnav_graph.io.drive_io import load_npz, save_npz

    d = simulate("urban", 2, duration_s=200.0)
    e = load_npz(save_npz(d, tmp_path / "urban.npz"))
    assert e.gnss.spec == d.gnss.spec  # range fields come back as tuples
    assert e.meta["gnss_burst_windows"] == d.meta["gnss_burst_windows"]
    assert e.meta["gnss_outages"] == d.meta["gnss_outages"]
