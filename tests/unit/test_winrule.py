"""The accuracy win rule (``vnav_graph.evaluation.winrule``) on constructed bench rows, and the
quantities it reads from real evaluations: the per-axis NEES (``metrics.nees_axes``), the
error's 95th percentile and heading scored where both estimators know it
(``montecarlo.common_heading_blocks``)."""

from __future__ import annotations

import numpy as np
import pytest

from vnav_graph.evaluation.metrics import evaluate, heading_common, heading_errors
from vnav_graph.evaluation.montecarlo import (
    HEADING_ERRORS_KEY,
    common_heading_blocks,
    shorten_scenario,
)
from vnav_graph.evaluation.winrule import FALLBACK_6DOF, describe, win_rule
from vnav_graph.nav.rotations import rpy_quat
from vnav_graph.simulation import simulate
from vnav_graph.types import ERROR_STATE, Estimate, Trajectory


def row(est, seed, value, key="horiz_rmse_m", axes=None, nees=None, **extra):
    """A bench row; ``axes=None``: a run scored before ``nees_axes`` existed (no key)."""
    r = {"scenario": "s", "seed": seed, "estimator": est, "status": "ok", "error": None,
         key: value, "nees_mean": nees, "nees_dof": 6 if nees is not None else None,
         "baro": {}, **extra}
    if axes is not None:
        r["nees_axes"] = axes
    return r


def two(loser_axes, winner_axes, gain=0.3, n=10, key="horiz_rmse_m"):
    rng = np.random.default_rng(1)
    runs = []
    for seed in range(n):
        base = 10.0 + rng.normal()
        runs += [row("ekf-rts", seed, base, key, axes=loser_axes, nees=6.0,
                     horiz_p95_m=2 * base),
                 row("graph-batch", seed, (1 - gain) * base + 0.1 * rng.normal(), key,
                     axes=winner_axes, nees=6.0, horiz_p95_m=1.5 * base)]
    return runs


def test_a_30_percent_win_over_a_consistent_loser_counts():
    runs = two({"horiz": 1.0}, {"horiz": 0.9})
    w = win_rule(runs, "s", "ekf-rts", "graph-batch", "horiz_rmse_m")
    assert w["verdict"] == "win" and w["counts"] and w["winner"] == "graph-batch"
    assert w["stats"]["gain"] == pytest.approx(0.3, abs=0.02)
    assert w["calibration"]["ekf-rts"]["nees_per_dof"] == pytest.approx(1.0)
    assert w["calibration"]["graph-batch"]["source"] == "per-axis"
    assert w["missing"] == []
    text = describe(w, "ekf-rts", "graph-batch", "m")
    assert "**graph-batch wins**" in text and "horizontal, 2 dof" in text
    assert "NEES/dof (horizontal, 2 dof): ekf-rts 1.00, graph-batch 0.90" in text
    # tails: the worst seed is named, the 95th percentile is the mean/max of the run values
    t = w["tails"]["ekf-rts"]
    xs = [r["horiz_rmse_m"] for r in runs if r["estimator"] == "ekf-rts"]
    assert t["worst"] == max(xs) and t["worst_seed"] == int(np.argmax(xs))
    assert t["p95_mean"] == pytest.approx(2 * np.mean(xs))
    assert t["p95_max"] == pytest.approx(2 * max(xs))
    assert f"(seed {t['worst_seed']})" in text and "95th percentile of |error|" in text


def test_an_overconfident_winner_is_vetoed():
    # winner NEES/dof 5 on the horizontal axes, above 2 and above the loser's 3
    w = win_rule(two({"horiz": 3.0}, {"horiz": 5.0}), "s", "ekf-rts", "graph-batch",
                 "horiz_rmse_m")
    assert w["verdict"] == "bought by overconfidence" and w["counts"] is False
    assert "bought by overconfidence" in describe(w, "ekf-rts", "graph-batch", "m")
    # above 2 but below the loser's: the win counts
    w = win_rule(two({"horiz": 6.0}, {"horiz": 5.0}), "s", "ekf-rts", "graph-batch",
                 "horiz_rmse_m")
    assert w["verdict"] == "win" and w["counts"]
    # the axes decide, not the 6-dof NEES: 6-dof values are equal (1.0 per dof) in both
    w = win_rule(two({"horiz": 1.0, "alt": 9.0}, {"horiz": 5.0, "alt": 0.5},
                     key="alt_rmse_m"), "s", "ekf-rts", "graph-batch", "alt_rmse_m")
    assert w["calibration"]["graph-batch"]["nees_per_dof"] == pytest.approx(0.5)
    assert w["verdict"] == "win"
    # an estimator without σ on the axes (nees_axes null): no calibration, no veto
    runs = two({"horiz": 1.0}, {"horiz": 5.0})
    for r in runs:
        if r["estimator"] == "graph-batch":
            r["nees_axes"] = None
    w = win_rule(runs, "s", "ekf-rts", "graph-batch", "horiz_rmse_m")
    assert w["calibration"]["graph-batch"]["nees_per_dof"] is None and w["counts"]


def test_runs_without_per_axis_nees_fall_back_on_the_6dof_value_and_say_so():
    w = win_rule(two(None, None), "s", "ekf-rts", "graph-batch", "horiz_rmse_m")
    for r in (w["calibration"]["ekf-rts"], w["calibration"]["graph-batch"]):
        assert r["source"] == FALLBACK_6DOF and r["nees_per_dof"] == pytest.approx(1.0)
    assert "the runs carry no per-axis NEES" in describe(w, "ekf-rts", "graph-batch", "m")


def test_an_unresolved_difference_is_not_a_win_and_says_why():
    rng = np.random.default_rng(2)
    runs = []
    for seed in range(6):
        x = 10.0 + rng.normal()
        runs += [row("a", seed, x), row("b", seed, x + rng.normal())]
    w = win_rule(runs, "s", "a", "b", "horiz_rmse_m")
    lo, hi = w["stats"]["diff_ci95"]
    assert lo < 0 < hi
    assert w["verdict"] == "not resolved" and w["counts"] is None and w["winner"] is None
    assert "not resolved (the 95 % CI of the difference contains 0)" in describe(w, "a", "b",
                                                                                 "m")


def test_a_seed_missing_a_metric_is_counted_and_named():
    runs = two({"horiz": 1.0}, {"horiz": 1.0})
    runs[2 * 3 + 1]["horiz_rmse_m"] = None  # graph-batch seed 3: no value
    runs[2 * 5]["status"], runs[2 * 5]["error"] = "failed", "estimate: diverged"  # ekf-rts 5
    runs = [r for r in runs if not (r["estimator"] == "graph-batch" and r["seed"] == 7)]
    w = win_rule(runs, "s", "ekf-rts", "graph-batch", "horiz_rmse_m")
    assert w["stats"]["n"] == 7 and 3 not in w["seeds"] and 5 not in w["seeds"]
    assert w["missing"] == [
        {"seed": 3, "estimator": "graph-batch", "why": "no value"},
        {"seed": 5, "estimator": "ekf-rts", "why": "failed: estimate: diverged"},
        {"seed": 7, "estimator": "graph-batch", "why": "no run"}]
    text = describe(w, "ekf-rts", "graph-batch", "m")
    assert "3 seed(s) without the metric: seed 3 (graph-batch: no value)" in text


def test_heading_is_scored_at_the_common_known_epochs():
    """Over the whole drive ekf-rts is far worse (its unknown start); where both report
    σ_yaw ≤ 5° they are equal: not resolved, the whole-drive difference beside it."""
    rng = np.random.default_rng(3)
    runs = []
    for seed in range(8):
        common = 1.0 + 0.1 * rng.normal(size=2)
        runs += [row("ekf-rts", seed, 20.0 + rng.normal(), key="heading_rmse_deg",
                     heading_common={"graph-batch": {"rmse_deg": common[0]}}),
                 row("graph-batch", seed, 2.0, key="heading_rmse_deg",
                     heading_common={"ekf-rts": {"rmse_deg": common[1]}})]
    w = win_rule(runs, "s", "ekf-rts", "graph-batch", "heading_rmse_deg")
    assert w["heading_basis"] == "at the epochs where both report σ_yaw ≤ 5°"
    assert w["verdict"] == "not resolved"
    assert w["whole_drive"]["diff_ci95"][0] > 10  # resolved over the whole drive
    text = describe(w, "ekf-rts", "graph-batch", "deg")
    assert "heading at the epochs where both report σ_yaw ≤ 5°; whole drive d = " in text


# ------------------------------------------------ quantities measured on evaluated estimates
@pytest.fixture(scope="module")
def drive():
    return simulate(shorten_scenario("hill-drive", 30.0), 0)


def offset_estimate(drive, name, yaw_deg, sd_yaw_deg, d_alt=0.0, d_vn=0.0):
    """The truth at 2 Hz with its yaw turned by ``yaw_deg`` (per epoch), its height raised by
    ``d_alt`` [m] and its north velocity by ``d_vn`` [m/s]; σ 1 m, 1 m/s, σ_yaw given."""
    t = np.arange(0.0, drive.truth.t[-1], 0.5)
    tr = drive.truth.at(t)
    rph = tr.to_rph()
    q = np.array([rpy_quat(r, p, y + np.radians(o))
                  for (r, p, y), o in zip(rph, yaw_deg(t), strict=True)])
    lla = tr.lla.copy()
    lla[:, 2] += d_alt
    vel = tr.vel_n + np.array([d_vn, 0.0, 0.0])
    cov = np.tile(np.eye(18), (t.size, 1, 1))
    cov[:, 6:9, 6:9] *= 1e-6
    yaw = ERROR_STATE["att_n"].start + 2
    cov[:, yaw, yaw] = np.radians(sd_yaw_deg(t)) ** 2
    prov = frozenset({"alt", "vel_d", "pos_h", "vel_h", "att", "cov"})
    return Estimate(name, Trajectory(t, lla, vel, q), prov, cov=cov, t_cov=t)


def test_nees_axes_and_error_p95_closed_form(drive):
    est = offset_estimate(drive, "x", lambda t: np.where(t < 7.0, 60.0, 3.0),
                          lambda t: np.where(t < 7.0, 30.0, 2.0), d_alt=2.0, d_vn=0.6)
    b = evaluate(est, drive)
    ax = b["nees_axes"]
    assert ax["alt"] == pytest.approx(4.0, rel=1e-6)  # (2 m / 1 m)², 1 dof
    assert ax["vel_down"] == pytest.approx(0.0, abs=1e-9)
    assert ax["vel"] == pytest.approx(0.36 / 3, rel=1e-6)  # 0.6² over 3 dof
    assert ax["horiz"] == pytest.approx(0.0, abs=1e-6)
    t = np.arange(0.0, drive.truth.t[-1], 0.5)
    z2 = np.where(t < 7.0, (60 / 30) ** 2, (3 / 2) ** 2)
    assert ax["heading"] == pytest.approx(np.mean(z2), rel=1e-6)
    assert b["alt_p95_m"] == pytest.approx(2.0, rel=1e-6)
    assert b["heading_p95_deg"] == pytest.approx(60.0, rel=1e-6)


def test_common_heading_blocks_score_each_where_both_know_heading(drive):
    """a knows heading from 7 s (10° error until 15 s, then 3°), b from 15 s (5° after):
    where both know it, a scores 3° and b 5°; a's own known score keeps its 10° epochs."""
    a = offset_estimate(drive, "a", lambda t: np.select([t < 7, t < 15], [60.0, 10.0], 3.0),
                        lambda t: np.where(t < 7.0, 30.0, 2.0))
    b = offset_estimate(drive, "b", lambda t: np.where(t < 15.0, 60.0, 5.0),
                        lambda t: np.where(t < 15.0, 30.0, 2.0))
    rows = [{"scenario": "s", "seed": 0, "estimator": e.estimator, "status": "ok",
             **evaluate(e, drive), HEADING_ERRORS_KEY: heading_errors(e, drive)}
            for e in (a, b)]
    rows.append({"scenario": "s", "seed": 0, "estimator": "vkf4", "status": "ok",
                 HEADING_ERRORS_KEY: None})
    ra, rb, rv = common_heading_blocks(rows)
    assert all(HEADING_ERRORS_KEY not in r for r in (ra, rb, rv))
    assert ra["heading_common"]["b"]["rmse_deg"] == pytest.approx(3.0, rel=1e-6)
    assert rb["heading_common"]["a"]["rmse_deg"] == pytest.approx(5.0, rel=1e-6)
    assert ra["heading_known_rmse_deg"] > 5.0  # its own σ counts the 10° epochs
    assert rv["heading_common"] is None
    # the epochs: t ≥ 15 s on a 0.5 s grid
    t = np.arange(0.0, drive.truth.t[-1], 0.5)
    assert ra["heading_common"]["b"]["n_epochs"] == int(np.sum(t >= 15.0))
    # no common known epoch: no score
    h = heading_common(t, np.ones(t.size), np.full(t.size, 2.0), t, np.full(t.size, 9.0))
    assert h["rmse_deg"] is None and h["n_epochs"] == 0
