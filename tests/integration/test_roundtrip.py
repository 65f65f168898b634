"""Simulator and mechanisation agree: strapdown of the noiseless simulated IMU reproduces
the truth (issue 2: < 0.1 m after 60 s, < 1 m after 10 min on hill-drive)."""

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
    assert pos[: 60 * 200 + 1].max() < 0.1  # issue 2 bound at 60 s
    assert pos.max() < 1.0  # issue 2 bound at 10 min (measured: a few mm)
    assert att.max() < 1e-6  # coning-compensated attitude: sub-µrad


def test_sortie_roundtrip_with_turns_and_climbs():
    pos, vel, att = _free_inertial_error("sortie", 2, 600.0)
    assert pos.max() < 1.0  # 80 m/s coordinated turns, 15 m/s climbs (measured ≈ 1 cm)
    assert vel.max() < 1e-3
