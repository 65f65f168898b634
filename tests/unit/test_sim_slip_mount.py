"""Simulator options for a non-holonomic-constraint study: car side-slip and IMU mounting
misalignment, checked against closed forms and finite differences.

- Side-slip β = k·v·cosγ·ψ̇: the body-frame lateral velocity is exactly v·cosγ·sinβ.
- Mounting misalignment C_vb: with no slip the vehicle's velocity is v·e_x, so the IMU frame
  sees v·C_vbᵀe_x (e.g. −v·sinψ_m laterally for a yaw misalignment ψ_m).
- In both, the gyro's ω_nb^b matches the attitude's finite-difference rate, and the
  accelerometer matches C_bn·(dv_n/dt + (2ω_ie + ω_en)×v_n − g) by finite differences.
- Off by default: the scenario files give no slip and no misalignment.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from vnav_graph.geo.earth import earth_rate_n, gravity, transport_rate_n
from vnav_graph.geo.frames import quat_to_mat
from vnav_graph.simulation import load_scenario, simulate
from vnav_graph.simulation.scenario import scenario_from_dict
from vnav_graph.simulation.trajectories import hill_drive_profiles, kinematics, mount_imu

ORIGIN = np.array([np.radians(47.0), np.radians(11.0), 500.0])
RATE = 200.0
K_SLIP = 0.01  # rad per m/s²: 0.57° of slip per m/s² of lateral acceleration


def _drive(slip: float = 0.0, mount_deg=None):
    t = np.arange(0.0, 120.0, 1.0 / RATE)
    prof = hill_drive_profiles(120.0, np.random.default_rng([4, 1]), static_s=5.0)
    kin = kinematics(t, *prof, ORIGIN, coordinated_turns=False, slip_gain=slip)
    if mount_deg is not None:
        kin = mount_imu(kin, np.radians(mount_deg))
    return t, prof, kin


def _v_body(kin):
    c_nb = quat_to_mat(kin.truth.q_nb)
    return np.einsum("nji,nj->ni", c_nb, kin.truth.vel_n)


def test_side_slip_lateral_velocity_closed_form():
    t, (speed, heading, fpa), kin = _drive(K_SLIP)
    v, _, _ = speed.eval(t)
    _, psid, _ = heading.eval(t)
    gam, _, _ = fpa.eval(t)
    beta = K_SLIP * v * np.cos(gam) * psid
    vb = _v_body(kin)
    np.testing.assert_allclose(vb[:, 1], v * np.cos(gam) * np.sin(beta), rtol=0, atol=1e-9)
    assert np.max(np.abs(vb[:, 1])) > 0.05  # the drive turns: the slip is visible
    _, _, kin0 = _drive(0.0)
    np.testing.assert_allclose(_v_body(kin0)[:, 1], 0.0, atol=1e-9)  # no slip: NHC holds


@pytest.mark.parametrize("mount", [(0.0, 0.0, 2.0), (1.5, -2.0, 3.0)])
def test_mount_misalignment_velocity_closed_form(mount):
    t, (speed, _, _), kin = _drive(0.0, mount)
    v, _, _ = speed.eval(t)
    c_vb = Rotation.from_euler("ZYX", mount[::-1], degrees=True).as_matrix()
    np.testing.assert_allclose(_v_body(kin), np.outer(v, c_vb.T[:, 0]), rtol=0, atol=1e-9)


@pytest.mark.parametrize("slip, mount", [(K_SLIP, None), (0.0, (1.5, -2.0, 3.0)),
                                         (K_SLIP, (0.0, 0.0, -4.0))])
def test_imu_readings_match_the_motion(slip, mount):
    t, _, kin = _drive(slip, mount)
    dt = 1.0 / RATE
    c_nb = quat_to_mat(kin.truth.q_nb)
    # gyro: ω_nb^b against the attitude's rate, log(C_nb(k)ᵀ C_nb(k+1)) / dt at mid-interval
    rel = np.einsum("nji,njk->nik", c_nb[:-1], c_nb[1:])
    w_fd = Rotation.from_matrix(rel).as_rotvec() / dt
    w_mid = 0.5 * (kin.omega_nb_b[:-1] + kin.omega_nb_b[1:])
    # measured: 5.7e-8 rad/s without slip, 2.7e-6 with it (β̇ carries ψ̈, whose ramps are
    # sharper); leaving β̇ out of the yaw rate gives 7.3e-3
    assert np.max(np.abs(w_fd - w_mid)) < 1e-5
    # accelerometer: C_bn (dv_n/dt + (2ω_ie + ω_en) × v_n − g) by central differences
    lla, vn = kin.truth.lla, kin.truth.vel_n
    acc = (vn[2:] - vn[:-2]) / (2 * dt)
    la, h, v = lla[1:-1, 0], lla[1:-1, 2], vn[1:-1]
    f_n = acc + np.cross(2 * earth_rate_n(la) + transport_rate_n(la, h, v), v)
    f_n[:, 2] -= gravity(la, h)
    f_b = np.einsum("nji,nj->ni", c_nb[1:-1], f_n)
    assert np.max(np.abs(f_b - kin.accel_b[1:-1])) < 1e-4


def test_off_by_default_and_from_toml():
    for name in ("hill-drive", "default", "urban", "cold-start", "sortie"):
        cfg = load_scenario(name)
        assert cfg.side_slip_gain == 0.0 and cfg.imu_mount_rph_deg == (0.0, 0.0, 0.0)
    d = dict(name="nhc", kind="hill-drive", duration_s=30.0, side_slip_gain=K_SLIP,
             imu_mount_rph_deg=[0, 0, 2])
    drive = simulate(scenario_from_dict(d), 1)
    assert drive.meta["side_slip_gain"] == K_SLIP
    assert drive.meta["imu_mount_rph_deg"] == [0.0, 0.0, 2.0]
    assert "imu_mount_rph_deg" not in simulate("hill-drive", 1, duration_s=30.0).meta
    with pytest.raises(ValueError, match="imu_mount_rph_deg"):
        scenario_from_dict({**d, "imu_mount_rph_deg": [0, 0]})
    with pytest.raises(ValueError, match="hill-drive and sortie"):
        scenario_from_dict({**d, "kind": "vertical"})
