"""ekf, ekf-rts, vekf7, graph-batch and graph-isam2 receive the same sensor model.

The numbers are read where each estimator hands them to its numerical core, not from the
shared function: the EKF's ``run_filter`` input records (process-noise table, initial
covariance, baro noise, GNSS sigmas, gap flags), the graph's problem set-up (preintegration
covariances, baro prior, GNSS sigmas, gap intervals) and vekf7's propagation and update
calls. An estimator that re-derived a parameter on its own would differ here.
"""

from __future__ import annotations

import inspect
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from vnav_graph.estimators.base import create
from vnav_graph.estimators.ekf import kernel as kernel_mod
from vnav_graph.estimators.ekf import model as km
from vnav_graph.estimators.graph.batch import smoother as batch_mod
from vnav_graph.estimators.graph.isam2 import causal as isam2_mod
from vnav_graph.estimators.graph.model import problem as problem_mod
from vnav_graph.estimators.vertical import vekf7 as vekf7_mod
from vnav_graph.nav.gaps import gap_threshold
from vnav_graph.simulation import simulate

REL = 1e-9
REL_V = 1e-6  # vekf7 adds 1e-12 to its prior variances (regularisation)
LOGS = [
    "erle_pxf_218/218.BIN",
    "erle_pxf_181_gps_glitch/181.BIN",
    "erle_pxf_loiter_rtl/Loiter_RTL.bin",
    "ski_iphone_100hz",
    "car_phone_1hz_2025-03-01a/2025-03-01_15-04-26.csv",
    "car_phone_1hz_2025-07-18/2025-07-18_23-13-43.csv",
    "px4_ulog_samples/sample_px4_events.ulg",
]


class _Stop(Exception):
    pass


def _ekf_used(drive, name: str, monkeypatch: pytest.MonkeyPatch) -> dict:
    got: dict = {}
    sig = inspect.signature(kernel_mod.run_filter.py_func)

    def capture(*args):
        got.update(sig.bind(*args).arguments)
        raise _Stop

    monkeypatch.setattr(kernel_mod, "run_filter", capture)
    with pytest.raises(_Stop):
        create(name).run(drive)
    monkeypatch.undo()
    grids, init, noise = got["grids"], got["init"], got["noise"]
    gnss, baro = got["meas"].gnss, got["meas"].baro
    t, grid_of, qd, p0 = grids.t, grids.grid_of, noise.q_diag, init.p0
    tg = t[grid_of >= 0]
    dtg = np.diff(tg)
    gap = np.flatnonzero(grids.gap_step)
    ok = np.flatnonzero(dtg > 0)[:5] + 1  # regular grid intervals (no gap in the first ones)
    ok = ok[~np.isin(np.flatnonzero(grid_of >= 0)[ok], gap + 1)]
    return {
        "accel_nd": float(np.sqrt(qd[ok[0], km.IVEL] / dtg[ok[0] - 1])),
        "gyro_nd": float(np.sqrt(qd[ok[0], km.IATT] / dtg[ok[0] - 1])),
        "gyro_bias_sd": float(np.sqrt(p0[9, 9])),
        "accel_bias_sd": float(np.sqrt(p0[12, 12])),
        # the accelerometer scale factors' prior σ (1e-7: not estimated)
        "accel_scale_sd": float(np.sqrt(p0[18, 18])),
        "bias_tau": (float(noise.tau_g), float(noise.tau_a), float(noise.tau_b)),
        "baro": (float(np.sqrt(p0[15, 15])), float(init.par0[km.PTD]),
                 float(np.sqrt(p0[16, 16])), float(np.sqrt(p0[17, 17])),
                 float(baro.sd)),
        "gnss_pos_sd": np.asarray(gnss.pos_sd),
        "gnss_vel_sd": np.asarray(gnss.vel_sd) if gnss.has_vel else None,
        "gaps": gap,
    }


def _graph_used(drive, name: str, monkeypatch: pytest.MonkeyPatch) -> dict:
    got: dict = {}
    orig = problem_mod.setup

    def capture(d, cfg, causal=False):
        got["P"] = orig(d, cfg, causal)
        raise _Stop

    monkeypatch.setattr(batch_mod if name == "graph-batch" else isam2_mod, "setup", capture)
    with pytest.raises(_Stop):
        create(name).run(drive)
    monkeypatch.undo()
    P = got["P"]
    pri = P.pri
    spec = P.imu_spec
    return {
        "accel_nd": float(np.sqrt(P.params.getAccelerometerCovariance()[0, 0])),
        "gyro_nd": float(np.sqrt(P.params.getGyroscopeCovariance()[0, 0])),
        "gyro_bias_sd": spec.gyro_bias_sd, "accel_bias_sd": spec.accel_bias_sd,
        "accel_scale_sd": P.ka.sd if P.ka is not None else 1e-7,
        "bias_tau": (spec.gyro_bias_tau, spec.accel_bias_tau, pri["b_tau"]),
        "baro": (pri["s_sd"], pri["tau0"], pri["tau_sd"], pri["b_sd"], pri["noise"]),
        "gnss_pos_sd": P.g_pos_sd, "gnss_vel_sd": P.g_vel_sd, "pos_drop": P.g_pos_drop,
        "gap_intervals": np.flatnonzero(problem_mod.imu_gaps(drive.imu.t, P.kf_idx)),
        "kf_idx": P.kf_idx,
    }


def _vekf7_used(drive, monkeypatch: pytest.MonkeyPatch) -> dict:
    got: dict = {"var_baro": set(), "var_gnss": []}
    prop, upd = vekf7_mod.propagate, vekf7_mod.scalar_update

    def first(nom, p):  # the state before the first propagation or update: the prior
        if "p0" not in got:
            got["p0"], got["nom0"] = p.copy(), nom.copy()

    def cap_prop(*a):
        first(a[-4], a[-3])
        if "gap_dt" not in got:
            got["gap_dt"], got["gap_q"] = a[-6], a[-5]
            got["t"] = a[2]
        return prop(*a)

    def cap_upd(nom, p, hrow, r, var_r):
        first(nom, p)
        if hrow[vekf7_mod.IBB] != 0.0:  # the baro row carries the bias
            got["var_baro"].add(float(var_r))
        elif hrow[vekf7_mod.IH] == 1.0:
            got["var_gnss"].append(float(var_r))
        return upd(nom, p, hrow, r, var_r)

    monkeypatch.setattr(vekf7_mod, "propagate", cap_prop)
    monkeypatch.setattr(vekf7_mod, "scalar_update", cap_upd)
    create("vekf7").run(drive)
    monkeypatch.undo()
    d = np.sqrt(np.diag(got["p0"]))
    return {"accel_bias_sd": float(d[vekf7_mod.IB]),
            "baro": (float(d[vekf7_mod.IS]), float(got["nom0"][vekf7_mod.ITD]),
                     float(d[vekf7_mod.ITD]), float(d[vekf7_mod.IBB])),
            "var_baro": got["var_baro"], "var_gnss": np.array(got["var_gnss"]),
            "gap_dt": float(got["gap_dt"]), "gap_q": float(got["gap_q"]),
            "t": got["t"]}


def _check_same(drive, monkeypatch: pytest.MonkeyPatch) -> None:
    ekf = _ekf_used(drive, "ekf", monkeypatch)
    rts = _ekf_used(drive, "ekf-rts", monkeypatch)
    for k in ekf:
        np.testing.assert_array_equal(np.asarray(ekf[k], dtype=object),
                                      np.asarray(rts[k], dtype=object), err_msg=k)
    for name in ("graph-batch", "graph-isam2"):
        g = _graph_used(drive, name, monkeypatch)
        for k in ("accel_nd", "gyro_nd", "gyro_bias_sd", "accel_bias_sd", "accel_scale_sd"):
            assert g[k] == pytest.approx(ekf[k], rel=REL), (name, k)
        assert g["bias_tau"] == pytest.approx(ekf["bias_tau"], rel=REL), name
        assert g["baro"] == pytest.approx(ekf["baro"], rel=REL), name
        # the same σ, except where the graph's pre-gate refused a position and kept the
        # velocity (its position rows then have σ POS_DROPPED_SD)
        keep = ~g["pos_drop"]
        np.testing.assert_array_equal(g["gnss_pos_sd"][keep], ekf["gnss_pos_sd"][keep])
        assert np.all(g["gnss_pos_sd"][~keep] == problem_mod.POS_DROPPED_SD)
        if ekf["gnss_vel_sd"] is not None:
            np.testing.assert_array_equal(g["gnss_vel_sd"], ekf["gnss_vel_sd"])
        # the same IMU gaps: the keyframe intervals holding the EKF's gap samples
        kf_of_gap = np.unique(np.searchsorted(g["kf_idx"], ekf["gaps"], side="right") - 1)
        kf_of_gap = kf_of_gap[(kf_of_gap >= 0) & (kf_of_gap < g["kf_idx"].size - 1)]
        np.testing.assert_array_equal(g["gap_intervals"], kf_of_gap, err_msg=name)
    v = _vekf7_used(drive, monkeypatch)
    assert v["accel_bias_sd"] == pytest.approx(ekf["accel_bias_sd"], rel=REL_V)
    s_sd, tau_m, tau_sd, b_sd, noise = ekf["baro"]
    assert v["baro"] == pytest.approx((s_sd, tau_m, tau_sd, b_sd), rel=REL_V)
    assert len(v["var_baro"]) == 1
    assert v["var_baro"].pop() == pytest.approx(noise**2, rel=REL)
    if v["var_gnss"].size:
        assert set(np.round(v["var_gnss"] / ekf["gnss_pos_sd"][:, 2].min() ** 2, 9)) <= set(
            np.round(ekf["gnss_pos_sd"][:, 2] ** 2 / ekf["gnss_pos_sd"][:, 2].min() ** 2, 9))
    # the same gap rule: exactly the EKF's gap samples exceed vekf7's threshold
    dt = np.diff(v["t"])
    np.testing.assert_array_equal(np.flatnonzero(dt > v["gap_dt"]), ekf["gaps"])
    assert v["gap_dt"] == gap_threshold(drive.imu.t)


@pytest.mark.parametrize("scenario", ["default", "hill-drive"])
def test_simulated_drive_same_model(scenario: str, monkeypatch: pytest.MonkeyPatch) -> None:
    drive = simulate(scenario, 2, duration_s=60.0)
    _check_same(drive, monkeypatch)


def test_drive_with_imu_gap_same_model(monkeypatch: pytest.MonkeyPatch) -> None:
    """Two logging gaps cut into the IMU stream: every estimator sees the same two gaps."""
    drive = simulate("default", 4, duration_s=60.0)
    t = drive.imu.t
    keep = ~(((t > 20.0) & (t < 21.0)) | ((t > 40.0) & (t < 40.4)))
    imu = replace(drive.imu, t=t[keep], gyro_b=drive.imu.gyro_b[keep],
                  accel_b=drive.imu.accel_b[keep])
    drive = drive.replace(imu=imu)
    _check_same(drive, monkeypatch)


def test_raised_gnss_velocity_sigma_reaches_every_estimator(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Fixes at the true positions with σ 1 cm, velocities with 5× their stated 0.1 m/s
    noise: the shared model raises the velocity σ (``sensors.gnss_consistency``), and the
    ekf, ekf-rts and both graphs weight the velocities with those raised σ."""
    from vnav_graph.sensors.model import sensor_model

    drive = simulate("default", 2, duration_s=60.0)
    g = drive.gnss
    truth = drive.truth.at(g.t)
    rng = np.random.default_rng(7)
    noisy = replace(g, lla=truth.lla, pos_sd=np.full_like(g.pos_sd, 0.01),
                    vel_n=truth.vel_n + 0.5 * rng.standard_normal(g.vel_n.shape),
                    vel_sd=np.full_like(g.vel_sd, 0.1))
    drive = drive.replace(gnss=noisy)
    model = sensor_model(drive)
    assert model.gnss_vel_check is not None and model.gnss_vel_check.raised
    assert np.all(model.gnss_vel_sd > 0.3)
    ekf = _ekf_used(drive, "ekf", monkeypatch)
    np.testing.assert_array_equal(ekf["gnss_vel_sd"], model.gnss_vel_sd)
    _check_same(drive, monkeypatch)
    # reported by both families: info, a warning and a fallback entry
    from vnav_graph.run.runner import run_captured

    note = model.gnss_vel_note()
    for name in ("ekf", "graph-batch"):
        info = run_captured(name, drive).info
        assert info["gnss_vel_note"] == note, name
        assert note in info["warnings"] and note in info["fallbacks"], name


@pytest.mark.slow
@pytest.mark.parametrize("rel", LOGS)
def test_shared_logs_same_model(rel: str, data_dir: Path,
                                monkeypatch: pytest.MonkeyPatch) -> None:
    path = data_dir / rel
    if not path.exists():
        pytest.skip(f"{rel} not present in the shared data")
    from vnav_graph.io import load_drive

    drive = load_drive(path)
    _check_same(drive, monkeypatch)
