"""Simulator and mechanisation agree: strapdown of the noiseless simulated IMU reproduces
the truth to millimetres after 10 min (bounds about 2-3x the measured errors)."""

import numpy as np
import pytest

from vnav_graph.config import IMU_PRESETS
from vnav_graph.geo.frames import attitude_error_n, lla_to_ned
from vnav_graph.nav.strapdown import NavState, integrate
from vnav_graph.simulation import simulate


def _free_inertial_error(scenario, seed, duration):
    d = simulate(scenario, seed, duration_s=duration, imu=IMU_PRESETS["consumer"].noiseless())
    tr = d.truth
    est = integrate(d.imu, NavState(tr.lla[0], tr.vel_n[0], tr.q_nb[0]))
    pos = lla_to_ned(est.lla, d.origin_lla) - lla_to_ned(tr.lla, d.origin_lla)
    att = attitude_error_n(est.q_nb, tr.q_nb)
    return np.linalg.norm(pos, axis=1), np.abs(est.vel_n - tr.vel_n), np.linalg.norm(att, axis=1)


@pytest.mark.slow
@pytest.mark.parametrize("seed", [0, 1])
def test_hill_drive_roundtrip(seed):
    pos, vel, att = _free_inertial_error("hill-drive", seed, 600.0)
    assert pos[: 60 * 200 + 1].max() < 1.5e-4  # measured 0.056 mm (seed 0), 0.040 mm (1)
    assert pos.max() < 0.02  # 10 min: measured 8.4 mm (seed 0), 7.5 mm (seed 1)
    assert att.max() < 5e-7  # coning-compensated attitude: measured 0.23 µrad


def test_sortie_roundtrip_with_turns_and_climbs():
    pos, vel, att = _free_inertial_error("sortie", 2, 600.0)
    assert pos.max() < 0.01  # 80 m/s coordinated turns, 15 m/s climbs (measured 4.3 mm)
    assert vel.max() < 5e-5  # measured 1.8e-5 m/s
