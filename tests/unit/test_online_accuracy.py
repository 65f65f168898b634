"""The scoring of benchmarks/online_accuracy.py: common epochs, RMSE, aggregate verdicts."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np

from vnav_graph.geo.frames import lla_to_ned, ned_to_lla
from vnav_graph.simulation import simulate
from vnav_graph.types import Trajectory

_P = Path(__file__).resolve().parents[2] / "benchmarks" / "online_accuracy.py"
_spec = importlib.util.spec_from_file_location("online_accuracy", _P)
oa = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(oa)


def test_error_at_common_epochs_is_the_known_offset():
    """A trajectory = truth + (3 m N, 4 m E, 2 m D), given at other epochs than the scoring
    ones: the interpolated horizontal / vertical RMSE are 5 m / 2 m (closed form)."""
    d = simulate("hill-drive", 0, duration_s=30.0)
    t = d.truth.t[::7]
    ned = lla_to_ned(d.truth.at(t).lla, d.origin_lla) + np.array([3.0, 4.0, 2.0])
    tr = Trajectory(t, ned_to_lla(ned, d.origin_lla), d.truth.at(t).vel_n)
    t_score = np.arange(2.0, 28.0, 1.0)
    h, v = oa._rmse(oa._ned_err(d, tr, t_score))
    assert abs(h - 5.0) < 0.01 and abs(v - 2.0) < 0.01


def test_aggregate_counts_seeds_and_goal():
    def run(seed, g, e):
        out = {"scenario": "x", "seed": seed}
        for name, (hh, vv) in (("graph-isam2", g), ("ekf", e)):
            out[name] = {"horiz_rmse_m": hh, "vert_rmse_m": vv,
                         "horiz_rmse_all_m": hh, "vert_rmse_all_m": vv}
        return out

    runs = [run(0, (1.0, 0.5), (2.0, 0.4)), run(1, (3.0, 0.2), (2.0, 0.4))]
    a = oa.aggregate(runs)["x"]
    assert a["horiz_rmse_m"]["seeds_graph_le_ekf"] == 1
    assert abs(a["horiz_rmse_m"]["ratio"] - 1.0) < 1e-12  # means 2.0 / 2.0
    assert abs(a["vert_rmse_m"]["ratio"] - 0.35 / 0.4) < 1e-12
    assert a["goal_met"]
    # paired differences −1 and +1: mean 0, standard error sd/√n = √2/√2 = 1
    assert abs(a["horiz_rmse_m"]["diff_mean"]) < 1e-12
    assert abs(a["horiz_rmse_m"]["diff_se"] - 1.0) < 1e-12
    runs[1]["graph-isam2"]["vert_rmse_m"] = 0.5
    assert not oa.aggregate(runs)["x"]["goal_met"]  # vertical mean 0.5 > 0.4
