"""Simulated magnetometer (MagSpec, simulate_mag) and its opt-in scenario section."""

import math
from dataclasses import replace

import numpy as np
import pytest

from vnav_graph.evaluation.montecarlo import shorten_scenario
from vnav_graph.geo.frames import quat_to_mat
from vnav_graph.geo.magfield import earth_field
from vnav_graph.sensors.magnetometer import MagSpec
from vnav_graph.simulation import list_scenarios, load_scenario, simulate
from vnav_graph.simulation.measurements import simulate_mag
from vnav_graph.simulation.scenario import scenario_from_dict
from vnav_graph.types import Trajectory


@pytest.fixture(scope="module")
def pair():
    """hill-drive and hill-drive-mag, 90 s, same seed."""
    return simulate("hill-drive", 5, duration_s=90.0), simulate("hill-drive-mag", 5,
                                                                   duration_s=90.0)


def _residual(drive):
    """z − C_nbᵀ m_n with the true attitude and the recorded field [µT]."""
    mag, mt = drive.mag, drive.meta["mag_truth"]
    c_nb = quat_to_mat(drive.truth.at(mag.t).q_nb)
    return mag.field_b - np.einsum("nji,j->ni", c_nb, np.asarray(mt["field_ned_ut"]))


def test_field_norm_hard_iron_and_noise(pair):
    _, d = pair
    mag, mt = d.mag, d.meta["mag_truth"]
    spec = load_scenario("hill-drive-mag").magnetometer
    assert mag.sd_ut == spec.sd_ut == 0.5
    assert mag.t[0] == 0.0 and np.allclose(np.diff(mag.t), 1.0 / spec.rate_hz)
    assert mag.t.size == 901
    # the recorded field is the WMM's at the origin in the scenario's year
    f = earth_field(*d.origin_lla, spec.year)
    np.testing.assert_allclose(mt["field_ned_ut"], f.ned_ut)
    assert mt["model"] == "WMM2025" and mt["year"] == 2025.5
    assert mt["declination_rad"] == f.declination_rad
    assert mt["hard_iron_ut"] == [4.0, -3.0, 2.0]
    # without the hard iron the norm is |m_n| up to the noise (σ of the norm ≈ σ per axis)
    r = _residual(d)
    norm = np.linalg.norm(mag.field_b - mt["hard_iron_ut"], axis=1)
    assert np.all(np.abs(norm - f.total_ut) < 5 * mag.sd_ut)
    assert np.mean(norm - f.total_ut) == pytest.approx(0.0, abs=4 * mag.sd_ut / math.sqrt(901))
    # the mean residual is the hard iron, its spread the noise
    se = mag.sd_ut / math.sqrt(r.shape[0])
    np.testing.assert_allclose(r.mean(axis=0), mt["hard_iron_ut"], atol=4 * se)
    np.testing.assert_allclose(r.std(axis=0), mag.sd_ut, rtol=0.15)


def test_mag_switches_nothing_else(pair):
    a, b = pair
    assert a.mag is None and "mag_truth" not in a.meta
    assert b.mag is not None
    for x, y in ((a.imu.gyro_b, b.imu.gyro_b), (a.imu.accel_b, b.imu.accel_b),
                 (a.gnss.t, b.gnss.t), (a.gnss.lla, b.gnss.lla), (a.baro.t, b.baro.t),
                 (a.baro.altitude, b.baro.altitude), (a.truth.lla, b.truth.lla),
                 (a.truth.q_nb, b.truth.q_nb), (a.truth.bias_baro, b.truth.bias_baro)):
        np.testing.assert_array_equal(x, y)
    assert a.baro_truth == b.baro_truth


@pytest.mark.parametrize("name", [s for s in list_scenarios() if s != "hill-drive-mag"])
def test_existing_scenarios_have_no_magnetometer(name):
    assert load_scenario(name).magnetometer is None


def test_default_drive_has_no_mag():
    d = simulate("default", 0, duration_s=20.0)
    assert d.mag is None and "mag_truth" not in d.meta


def test_reproducible_and_seeded(pair):
    _, b = pair
    b2 = simulate("hill-drive-mag", 5, duration_s=90.0)
    np.testing.assert_array_equal(b.mag.field_b, b2.mag.field_b)
    c = simulate("hill-drive-mag", 6, duration_s=90.0)
    assert not np.array_equal(b.mag.field_b[:10], c.mag.field_b[:10])


def test_simulate_mag_direct():
    d = simulate("default", 1, duration_s=10.0)
    spec = MagSpec(rate_hz=20.0, sd_ut=0.1, hard_iron_ut=(0.0, 0.0, 0.0))
    m_n = np.array([20.0, 2.0, 43.0])
    s1 = simulate_mag(d.truth, spec, m_n, np.random.default_rng(7))
    s2 = simulate_mag(d.truth, spec, m_n, np.random.default_rng(7))
    np.testing.assert_array_equal(s1.field_b, s2.field_b)
    assert s1.t.size == 201 and s1.sd_ut == 0.1
    # rotating back with the true attitude gives m_n
    c_nb = quat_to_mat(d.truth.at(s1.t).q_nb)
    back = np.einsum("nij,nj->ni", c_nb, s1.field_b)
    assert np.max(np.abs(back - m_n)) < 6 * spec.sd_ut



def test_simulate_mag_axes():
    # level, heading east: forward = east, right = south, down = down
    t = np.linspace(0.0, 2.0, 21)
    q_east = np.tile([math.cos(math.pi / 4), 0.0, 0.0, math.sin(math.pi / 4)], (t.size, 1))
    truth = Trajectory(t, np.zeros((t.size, 3)), np.zeros((t.size, 3)), q_east)
    spec = MagSpec(sd_ut=1e-9, hard_iron_ut=(1.0, 2.0, 3.0))
    s = simulate_mag(truth, spec, np.array([20.0, 2.0, 43.0]), np.random.default_rng(0))
    np.testing.assert_allclose(s.field_b, np.tile([2.0 + 1, -20.0 + 2, 43.0 + 3], (21, 1)),
                               atol=1e-6)


def test_scenario_section_and_shorten():
    cfg = load_scenario("hill-drive-mag")
    assert cfg.magnetometer == MagSpec()
    short = shorten_scenario("hill-drive-mag", 60.0)
    assert short.duration_s == 60.0 and short.magnetometer == cfg.magnetometer
    d = simulate(short, 2)
    assert d.mag is not None and d.mag.t[-1] == pytest.approx(60.0)
    base = {"name": "x", "kind": "hill-drive", "duration_s": 30.0}
    c = scenario_from_dict({**base, "magnetometer": {"rate_hz": 5, "hard_iron_ut": [1, 2, 3],
                                                     "year": 2014.5}})
    assert c.magnetometer.hard_iron_ut == (1.0, 2.0, 3.0) and c.magnetometer.rate_hz == 5
    d = simulate(c, 0)
    assert d.meta["mag_truth"]["model"] == "WMM2010"
    assert scenario_from_dict(base).magnetometer is None
    with pytest.raises(ValueError, match="unknown field"):
        scenario_from_dict({**base, "magnetometer": {"noise": 1.0}})
    with pytest.raises(ValueError, match="hard_iron_ut"):
        scenario_from_dict({**base, "magnetometer": {"hard_iron_ut": [1, 2]}})
    with pytest.raises(ValueError, match="no WMM before"):
        simulate(replace(c, magnetometer=MagSpec(year=2005.0)), 0)
