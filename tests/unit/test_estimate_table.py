"""``Estimate.to_dataframe``: every state and sigma, and the same table in the run's Parquet."""

import numpy as np
import pandas as pd

from vnav_graph.geo.frames import lla_to_ned
from vnav_graph.types import (
    ERROR_STATE,
    SD_COLUMNS,
    BaroEstimate,
    Drive,
    Estimate,
    ParamEstimate,
    Trajectory,
)
from vnav_graph.types.streams import ImuStream

ORIGIN = np.array([np.radians(47.0), np.radians(11.0), 500.0])


def _estimate(rng, full=True):
    """A 10 s estimate at 10 Hz with covariances every 1 s (on trajectory epochs)."""
    t = np.round(np.arange(0.0, 10.0 + 1e-9, 0.1), 10)
    n = t.size
    lla = ORIGIN + np.column_stack([1e-6 * t, 2e-6 * t, 0.5 * t])
    vel = np.column_stack([np.ones(n), 2 * np.ones(n), -0.5 * np.ones(n)])
    yaw = 0.1 * t
    q = np.column_stack([np.cos(yaw / 2), np.zeros(n), np.zeros(n), np.sin(yaw / 2)])
    traj = Trajectory(t, lla, vel, q, rng.normal(0, 1e-4, (n, 3)), rng.normal(0, 1e-2, (n, 3)),
                      np.linspace(1.0, 2.0, n))
    t_cov = t[::10]
    a = rng.normal(size=(t_cov.size, 18, 18))
    cov = a @ a.transpose(0, 2, 1) + 0.1 * np.eye(18)
    cov[:, ERROR_STATE["baro_latency"], :] = np.nan  # a state this estimator does not have
    cov[:, :, ERROR_STATE["baro_latency"]] = np.nan
    baro = BaroEstimate(scale=ParamEstimate(0.01, 0.001), latency_s=None,
                        bias_m=ParamEstimate(1.5, 0.2))
    if not full:
        nan_h = np.array([np.nan, np.nan, 1.0])  # vertical-only: NaN north/east
        return Estimate("vert", Trajectory(t, lla * nan_h, vel * nan_h), {"alt", "vel_d"})
    return Estimate("full", traj, {"alt", "vel_d", "pos_h", "vel_h", "att", "baro", "cov"},
                    cov=cov, t_cov=t_cov, baro=baro)


def test_columns_of_a_full_estimate(rng):
    est = _estimate(rng)
    df = est.to_dataframe(ORIGIN)
    expected = {"t_s", "lat_rad", "lon_rad", "alt_m", "pos_n_m", "pos_e_m", "pos_d_m",
                "vel_n_mps", "vel_e_mps", "vel_d_mps", "roll_rad", "pitch_rad", "yaw_rad",
                "bias_gyro_x_radps", "bias_gyro_y_radps", "bias_gyro_z_radps",
                "bias_accel_x_mps2", "bias_accel_y_mps2", "bias_accel_z_mps2",
                "baro_bias_m", "baro_scale", "horiz_sd_m"}
    expected |= set(SD_COLUMNS) - {"baro_latency_sd_s"}  # NaN block in cov → column absent
    assert set(df.columns) == expected
    assert len(df) == est.trajectory.t.size
    # values are the trajectory's, converted by independent routes
    np.testing.assert_allclose(df["yaw_rad"], 0.1 * df["t_s"], atol=1e-12)
    np.testing.assert_allclose(df[["pos_n_m", "pos_e_m", "pos_d_m"]],
                               lla_to_ned(est.trajectory.lla, ORIGIN))
    assert np.all(df["baro_scale"] == 0.01)
    assert "baro_latency_s" not in df  # not estimated (Estimate.baro.latency_s is None)


def test_sigmas_are_the_root_of_the_covariance_diagonal_at_t_cov(rng):
    est = _estimate(rng)
    df = est.to_dataframe()
    at = np.searchsorted(df["t_s"].to_numpy(), est.t_cov)
    assert np.allclose(df["t_s"].to_numpy()[at], est.t_cov)
    var = np.diagonal(est.cov, axis1=1, axis2=2)
    for j, col in enumerate(SD_COLUMNS):
        if col in df:
            np.testing.assert_allclose(df[col].to_numpy()[at], np.sqrt(var[:, j]), rtol=1e-12)
    np.testing.assert_allclose(df["horiz_sd_m"].to_numpy()[at], np.sqrt(var[:, 0] + var[:, 1]))
    # between epochs: linear in sigma, so bounded by the neighbouring epochs' values
    mid = df["alt_sd_m"].to_numpy()[at[0] + 5]
    lo, hi = sorted(np.sqrt(var[:2, 2]))
    assert lo <= mid <= hi


def test_sigma_is_not_extrapolated_beyond_one_epoch_spacing(rng):
    est = _estimate(rng)
    short = est.replace(cov=est.cov[:4], t_cov=est.t_cov[:4])  # covariance up to t = 3 s
    df = short.to_dataframe()
    t = df["t_s"].to_numpy()
    assert np.all(np.isfinite(df["alt_sd_m"][t <= 4.0 + 1e-9]))  # held for one spacing (1 s)
    assert np.all(np.isnan(df["alt_sd_m"][t > 4.0 + 1e-9]))


def test_vertical_only_estimate_has_nan_horizontal_columns_and_no_optional_ones(rng):
    df = _estimate(rng, full=False).to_dataframe(ORIGIN)
    assert list(df.columns) == ["t_s", "lat_rad", "lon_rad", "alt_m", "vel_n_mps", "vel_e_mps",
                                "vel_d_mps"]
    assert df["lat_rad"].isna().all() and df["vel_n_mps"].isna().all()
    assert df["alt_m"].notna().all()


def test_run_parquet_has_the_dataframe_columns(rng, tmp_path):
    """``write_outputs`` (``vnav-graph run``) writes exactly ``to_dataframe(origin)``."""
    from vnav_graph.run.pipeline import RunResult, summarize, write_outputs

    est = _estimate(rng)
    t = np.arange(0.0, 10.0, 0.01)
    imu = ImuStream(t, np.zeros((t.size, 3)), np.tile([0.0, 0.0, -9.81], (t.size, 1)))
    drive = Drive(imu, None, None, ORIGIN, meta={"name": "synthetic"})
    results = [RunResult("full", est, None, 0.1)]
    write_outputs(tmp_path, summarize(drive, results), results, drive)
    back = pd.read_parquet(tmp_path / "estimates" / "full.parquet")
    pd.testing.assert_frame_equal(back, est.to_dataframe(ORIGIN))
    assert "pos_n_m" in back and "horiz_sd_m" in back


def test_position_columns_need_an_origin_and_a_horizontal_estimate(rng):
    est = _estimate(rng)
    assert "pos_n_m" not in est.to_dataframe()  # no origin given
    no_h = est.replace(provides=est.provides - {"pos_h"})
    assert "pos_n_m" not in no_h.to_dataframe(ORIGIN)


def test_to_dataframe_needs_no_origin_after_the_runner():
    from vnav_graph.run.runner import run_estimators
    from vnav_graph.simulation import simulate

    drive = simulate("default", 0, duration_s=30.0)
    est = run_estimators(drive, ["ekf"])[0].estimate
    np.testing.assert_array_equal(est.origin_lla, drive.origin_lla)
    auto, given = est.to_dataframe(), est.to_dataframe(drive.origin_lla)
    assert "pos_n_m" in auto.columns
    pd.testing.assert_frame_equal(auto, given)
