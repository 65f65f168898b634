"""The scoring of benchmarks/online_accuracy.py: common epochs, RMSE, paired goal verdicts."""

from __future__ import annotations

import dataclasses
import importlib.util
from pathlib import Path

import numpy as np
import pytest

from vnav_graph.geo.frames import lla_to_ned, ned_to_lla
from vnav_graph.simulation import simulate
from vnav_graph.types import Trajectory

_P = Path(__file__).resolve().parents[2] / "benchmarks" / "online_accuracy.py"
_spec = importlib.util.spec_from_file_location("online_accuracy", _P)
oa = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(oa)


def test_common_epochs_are_the_shared_stamps():
    """5 Hz and 1 Hz grids (the second with 1e-9 s round-off) share the whole seconds."""
    a = np.arange(0.0, 10.0, 0.2)
    b = np.arange(0.0, 10.0, 1.0) + 1e-9
    ia, ib = oa.common_epochs(a, b)
    np.testing.assert_allclose(a[ia], np.arange(10.0), atol=1e-9)
    np.testing.assert_array_equal(ib, np.arange(10))


def test_score_pair_is_the_known_offset_at_common_epochs():
    """Truth + (3 m N, 4 m E, 2 m D) against truth + (0, 0, −1 m), at 1 Hz and 0.5 Hz: 5 m /
    2 m and 0 m / 1 m (closed form), over the 0.5 Hz epochs."""
    d = simulate("hill-drive", 0, duration_s=30.0)

    def shifted(t, dn):
        ned = lla_to_ned(d.truth.at(t).lla, d.origin_lla) + np.asarray(dn)
        return Trajectory(t, ned_to_lla(ned, d.origin_lla), d.truth.at(t).vel_n)

    s = oa.score_pair(d, shifted(np.arange(0.0, 30.0, 1.0), [3.0, 4.0, 2.0]),
                      shifted(np.arange(0.0, 30.0, 2.0), [0.0, 0.0, 1.0]))
    assert s["epochs"] == 15
    assert s["a"]["horiz_rmse_m"] == pytest.approx(5.0, abs=0.01)
    assert s["a"]["alt_rmse_m"] == pytest.approx(2.0, abs=0.01)
    assert s["b"]["horiz_rmse_m"] == pytest.approx(0.0, abs=0.01)
    assert s["b"]["alt_rmse_m"] == pytest.approx(1.0, abs=0.01)


def _run(sc, seed, a, b, comp="online"):
    out = {"scenario": sc, "seed": seed, "online": None, "lag": None}
    out[comp] = {"a": {"horiz_rmse_m": a}, "b": {"horiz_rmse_m": b}}
    return out


def test_goal_verdicts():
    """urban: b = a/2 on 4 seeds, gain 50 % with the CI of the difference above 0: met.
    hill-drive: b 1 % above a on every seed: within +2 %, met and resolved (zero spread).
    sortie: b 5 % above a: missed. long-outage: no lag → the lag goals are not measured."""
    a = np.array([1.0, 2.0, 3.0, 4.0])
    runs = [_run("urban", k, x, x / 2) for k, x in enumerate(a)]
    runs += [_run("hill-drive", k, x, 1.01 * x) for k, x in enumerate(a)]
    runs += [_run("sortie", k, x, 1.05 * x) for k, x in enumerate(a)]
    g = {(x["scenario"], x["comparison"]): x for x in oa.goals(runs)}
    u = g[("urban", "online")]
    assert u["gain"] == pytest.approx(0.5) and u["met"] and u["resolved"]
    assert u["seeds_b_lower"] == 4 and u["n"] == 4
    h = g[("hill-drive", "online")]
    assert h["gain"] == pytest.approx(-0.01) and h["met"] and h["resolved"]
    assert not g[("sortie", "online")]["met"]
    assert g[("hill-drive", "lag")]["status"] == "not measured"
    assert g[("hill-drive", "lag")]["met"] is None
    assert ("long-outage", "online") not in g  # no runs of it
    assert all(line for line in oa.goal_lines(list(g.values())))


def test_away_from_outages_closed_form():
    """Fixes at 1 Hz over 0-100 s with a 30 s outage (fixes at 40 and 70 s, none between) and
    L = 10 s: kept are the epochs with [t − 10, t + 10] inside [0, 100] and clear of (40, 70),
    i.e. 10 ≤ t ≤ 30 and 80 ≤ t ≤ 90. A single missing fix (a 2 s gap) is no outage."""
    t_fix = np.concatenate([np.arange(0.0, 41.0), np.arange(70.0, 101.0)])
    t_fix = t_fix[t_fix != 85.0]
    t = np.arange(0.0, 101.0)
    keep = oa.away_from_outages(t, t_fix, 10.0)
    expect = ((t >= 10) & (t <= 30)) | ((t >= 80) & (t <= 90))
    np.testing.assert_array_equal(keep, expect)
    assert not oa.away_from_outages(t, t_fix[:1], 10.0).any()


def test_lag_gnss_scores_only_epochs_away_from_outages():
    """hill-drive with its GNSS cut between 20 and 50 s, L = 5 s, 1 Hz grids: the lag_gnss
    pair scores the epochs t with [t − 5, t + 5] inside the fixes before the cut or inside
    those after it, and the score is the known offset there."""
    d = simulate("hill-drive", 0, duration_s=80.0)
    t0 = d.imu.t[0]
    d = dataclasses.replace(d, gnss=d.gnss.select((d.gnss.t < t0 + 20.0) | (d.gnss.t > t0 + 50.0)))
    tf = d.gnss.t
    before, after = tf[tf < t0 + 35.0], tf[tf > t0 + 35.0]
    t = np.arange(t0, t0 + 80.0, 1.0)
    inside = (((t - 5.0 >= before[0]) & (t + 5.0 <= before[-1]))
              | ((t - 5.0 >= after[0]) & (t + 5.0 <= after[-1])))
    ned = lla_to_ned(d.truth.at(t).lla, d.origin_lla) + np.array([3.0, 4.0, 0.0])
    a = Trajectory(t, ned_to_lla(ned, d.origin_lla), d.truth.at(t).vel_n)
    b = Trajectory(t, d.truth.at(t).lla, d.truth.at(t).vel_n)
    s = oa.score_pair(d, a, b, lag_s=5.0)
    assert s["epochs"] == int(inside.sum()) and 15 <= s["epochs"] <= 50
    assert s["from_s"] == pytest.approx(t[inside][0] - t0)
    assert s["a"]["horiz_rmse_m"] == pytest.approx(5.0, abs=0.01)
