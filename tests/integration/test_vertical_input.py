"""The GNSS-aided attitude reference behind ``vertical_inputs`` (the "INS attitude" of the seed
papers): tilt error and attitude-induced vertical-specific-force error against truth.

Bounds. The tilt of an accelerometer-levelled platform is limited by the horizontal
accelerometer bias, |ψ_h| ≈ |b_a,h|/g (≈ 7 mrad for the consumer preset's 5 mg per axis,
≈ 1.4 mrad for the industrial 1 mg), plus the residual of the gyro-bias loop (consumer turn-on
bias ≈ 0.05 °/s ≈ 0.9 mrad/s, removed with time constant ≈ 1/ω_t = 20 s). The error that
attitude puts into f_D is ≈ |ψ_h|·|a_h| + g·|ψ_h|²/2; with |a_h| RMS ≈ 1.5-2 m/s² on the
simulated drives this is ≈ 1.5-2 × the tilt in mrad, in mm/s².
"""

from __future__ import annotations

import numpy as np
import pytest

from vnav_graph.config import IMU_PRESETS
from vnav_graph.estimators.vertical.inputs import vertical_inputs
from vnav_graph.geo.frames import attitude_error_n, quat_to_mat
from vnav_graph.simulation import simulate


def _errors(drive):
    vi = vertical_inputs(drive)
    err = attitude_error_n(vi.q_nb, drive.truth.q_nb)
    tilt = np.hypot(err[:, 0], err[:, 1])
    c_true = quat_to_mat(drive.truth.q_nb)
    # attitude-induced error only: the same measured specific force resolved with the truth
    fd_err = vi.f_down - np.einsum("nj,nj->n", c_true[:, 2, :], drive.imu.accel_b)
    t = drive.imu.t
    aided = t > 60.0  # after alignment (static period, first course, bias loop settling)
    for a, b in drive.meta["gnss_outages"]:
        aided &= ~((t >= a) & (t < b + 30.0))  # free-running gyro in outages, then recovery
    return vi, tilt, fd_err, aided


# (scenario, imu, tilt RMS bound [mrad], aided tilt max bound [mrad], f_D RMS bound [mm/s²])
# consumer: 7 mrad accel-bias floor + gyro-bias residual -> RMS < 20, peaks < 50 in turns;
# industrial: 1.4 mrad floor -> RMS < 4, peaks < 15. f_D bound = 1.5 × tilt bound × ~1 m/s²
# (the docstring's |ψ_h|·|a_h| with the RMS |a_h| ≈ 1.5-2 m/s² partly averaged out).
CASES = [
    ("hill-drive", "consumer", 20.0, 50.0, 20.0),
    ("sortie", "consumer", 20.0, 50.0, 20.0),
    ("hill-drive", "industrial", 4.0, 15.0, 6.0),
    ("sortie", "industrial", 4.0, 15.0, 6.0),
]


@pytest.mark.parametrize("scenario,imu,tilt_rms_max,tilt_peak_max,fd_rms_max", CASES)
@pytest.mark.parametrize("seed", [2, 3])
def test_tilt_and_vertical_specific_force(
    scenario, imu, tilt_rms_max, tilt_peak_max, fd_rms_max, seed
):
    d = simulate(scenario, seed, imu=IMU_PRESETS[imu], duration_s=600.0)
    vi, tilt, fd_err, aided = _errors(d)
    assert np.sqrt(np.mean(tilt**2)) * 1e3 < tilt_rms_max
    assert np.max(tilt[aided]) * 1e3 < tilt_peak_max
    assert np.sqrt(np.mean(fd_err**2)) * 1e3 < fd_rms_max
    # C33 and F_z are consistent with f_D: f_D = C31 F_x + C32 F_y + C33 F_z (exact identity)
    c = quat_to_mat(vi.q_nb)
    np.testing.assert_allclose(c[:, 2, 2], vi.c33, atol=1e-12)  # round-off only
    np.testing.assert_allclose(
        np.einsum("nj,nj->n", c[:, 2, :], d.imu.accel_b), vi.f_down, atol=1e-9
    )  # round-off of the quaternion->matrix conversion


def test_noiseless_sensors_give_truth_attitude():
    """Perfect IMU and (almost) perfect GNSS velocity: the only errors left are the coarse
    levelling residual and the pre-course heading period, both removed by the loop."""
    from dataclasses import replace

    from vnav_graph.simulation import load_scenario

    cfg = load_scenario("hill-drive", duration_s=300.0)
    cfg = replace(cfg, imu=IMU_PRESETS["industrial"].noiseless(),
                  gnss=replace(cfg.gnss, vel_sd=1e-5))
    d = simulate(cfg, 1)
    _, tilt, fd_err, aided = _errors(d)
    # 1 mrad: Earth-rate misprojection before the first course (yaw unknown for ~20 s,
    # Ω·cos(lat)·20 s ≈ 1 mrad), removed afterwards with time constant 20 s.
    assert np.max(tilt[aided]) < 1e-3
    # 2 mm/s²: 1 mrad tilt × ≤ 2 m/s² horizontal acceleration
    assert np.max(np.abs(fd_err[aided])) < 2e-3
