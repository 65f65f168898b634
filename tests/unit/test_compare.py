"""The headline: best estimator, runner-up, paired t-interval and verdict on synthetic
summaries with known answers; block RMSE against hand-computed values."""

from __future__ import annotations

import numpy as np
import pytest

from vnav_graph.evaluation.compare import (
    block_rmse,
    comparison,
    headline_lines,
    paired_interval,
    rank_metric,
    time_blocks,
)

# Student t quantiles t_{0.975, df} from tables (independent of scipy)
T975 = {1: 12.706, 3: 3.182}


def _est(alt: float, horiz: float | None = None, status: str = "ok") -> dict:
    return {"status": status, "alt_rmse_m": alt, "horiz_rmse_m": horiz}


def _blocks(alt: list[float | None]) -> list[dict]:
    return [{"alt_rmse_m": b, "horiz_rmse_m": None} for b in alt]


def test_time_blocks_and_block_rmse() -> None:
    assert time_blocks(0.0, 240.0) == [(30.0 * k, 30.0 * (k + 1)) for k in range(8)]
    assert len(time_blocks(0.0, 50.0)) == 2  # at least two blocks
    assert len(time_blocks(0.0, 3600.0)) == 10  # at most ten
    t = np.arange(0.0, 10.0)  # 0..9
    e = np.where(t < 5, 3.0, 4.0)
    e[7] = np.nan  # ignored
    # blocks [0, 5) and [5, 9]: a sample on the shared edge (t = 5) belongs to the later one
    assert block_rmse(t, e, [(0.0, 5.0), (5.0, 9.0)]) == [3.0, 4.0]
    assert block_rmse(t, e, [(20.0, 30.0)]) == [None]
    assert block_rmse(t, None, [(0.0, 5.0)]) == [None]


def test_paired_interval_closed_form() -> None:
    d = [0.4, 0.6, 0.5, 0.5]  # mean 0.5, sd (ddof 1) = sqrt(0.02/3)
    mean, lo, hi = paired_interval(d)
    half = T975[3] * np.sqrt(0.02 / 3) / 2.0
    assert mean == pytest.approx(0.5)
    assert (lo, hi) == pytest.approx((0.5 - half, 0.5 + half), abs=1e-3)
    assert paired_interval([1.0]) is None


def test_headline_picks_best_and_states_the_margin() -> None:
    ests = {"graph-batch": _est(1.0), "ekf": _est(1.5), "loop2": _est(3.0),
            "broken": _est(0.1, status="failed")}  # failed: never ranked
    pb = {"graph-batch": _blocks([0.9, 1.1, 1.0, 1.0]),
          "ekf": _blocks([1.3, 1.7, 1.5, 1.5]),  # d = 0.4, 0.6, 0.5, 0.5
          "loop2": _blocks([3.0] * 4), "broken": _blocks([0.1] * 4)}
    comp = comparison(ests, pb, "withheld GNSS (holdout)", [(0, 1)] * 4, "holdout window",
                      "note")
    h = comp["metrics"]["alt_rmse_m"]
    assert (h["best"], h["runner_up"]) == ("graph-batch", "ekf")
    assert h["diff"] == pytest.approx(0.5) and h["rel_pct"] == pytest.approx(100 / 3)
    half = T975[3] * np.sqrt(0.02 / 3) / 2.0
    assert h["ci95"] == pytest.approx([0.5 - half, 0.5 + half], abs=1e-3)
    assert h["verdict"] == "better" and h["n_blocks"] == 4
    assert h["text"] == ("Altitude RMSE, paired difference from graph-batch (1.00 m) over 4 "
                         "holdout windows, 95 % CI: ekf +0.50 m [+0.37, +0.63] (graph-batch "
                         "lower than ekf in 4 of 4).")
    # one estimator has a horizontal RMSE: nothing to rank
    assert comp["metrics"]["horiz_rmse_m"] is None
    assert h["summary_text"] == (
        "Altitude RMSE: graph-batch is best at 1.00 m, 1.5× better than the best filter "
        "(ekf 1.50 m) and 3.0× better than the best loop or observer (loop2 3.00 m).")
    assert comp["headline"] == [h["summary_text"], h["text"]]
    assert headline_lines({"comparison": comp}) == [h["summary_text"], h["text"], "note"]


def test_not_resolved_when_ci_includes_zero() -> None:
    # overall ekf-rts is lower, but per window the sign flips: d = +1, −1, +1, −0.6
    vals = {"ekf-rts": 2.0, "graph-isam2": 2.1}
    blocks = {"ekf-rts": [1.0, 3.0, 1.0, 2.6], "graph-isam2": [2.0, 2.0, 2.0, 2.0]}
    h = rank_metric(vals, blocks, "alt_rmse_m", "Altitude RMSE", "holdout window")
    assert h["best"] == "ekf-rts" and h["verdict"] == "tied"  # the JSON value, unchanged
    assert h["ci95"][0] < 0 < h["ci95"][1]
    assert h["n_blocks_best_lower"] == 2
    # |d| = 1, 1, 1, 0.6: 90 % of Σ|d| needs all four windows, so the reason is the CI
    assert h["tied"][0]["sits_in"] == 4
    assert h["summary_text"] == (
        "Altitude RMSE: the smoothers (ekf-rts, graph-isam2) at 2.00–2.10 m, not resolved "
        "from one another.")
    for word in ("tie", "separated"):
        assert word not in h["summary_text"] and word not in h["text"]


def test_the_reason_names_the_blocks_an_excess_sits_in() -> None:
    """The default drive's case: ekf 22.9 m against smoothers at 0.62 m, its excess in 2 of 8
    blocks (CI containing 0): not resolved, with that reason, not "tied"."""
    ekf = [0.18, 0.21, 0.16, 0.13, 11.63, 63.8, 0.31, 0.13]
    best = [0.05, 0.1, 0.12, 0.08, 1.22, 1.21, 0.18, 0.09]
    h = rank_metric({"graph-isam2": 0.62, "ekf": 22.9}, {"graph-isam2": best, "ekf": ekf},
                    "horiz_rmse_m", "Horizontal RMSE", "time block")
    assert h["ci95"][0] < 0 < h["ci95"][1]
    assert h["summary_text"] == ("Horizontal RMSE: graph-isam2 lowest at 0.62 m; ekf (22.9 m) "
                                 "not resolved from it: its excess over graph-isam2 sits in "
                                 "2 of 8 time blocks.")
    # closed form of concentration: |d| sorted 62.59, 10.41, ...; 90 % of the sum needs two
    from vnav_graph.evaluation.compare import concentration

    assert concentration([1.0, 1.0, 1.0, 1.0]) == 4  # 90 % of 4 needs all four
    assert concentration([10.0, -0.5, 0.5]) == 1  # 10 ≥ 0.9 · 11
    assert concentration([8.0, -2.0, 1.0]) == 2  # 8 < 9.9 ≤ 8 + 2
    assert concentration([]) == 0


def test_headline_mixed_and_no_ci() -> None:
    # lower overall RMSE but every paired block favours the runner-up
    h = rank_metric({"a": 1.0, "b": 1.1}, {"a": [2.0, 2.1, 1.9], "b": [1.0, 1.0, 1.0]},
                    "alt_rmse_m", "Altitude RMSE", "time block")
    assert h["verdict"] == "mixed" and h["ci95"][1] < 0
    # a block missing for one estimator is not paired: one pair left, no interval
    h = rank_metric({"a": 1.0, "b": 1.1}, {"a": [1.0, None], "b": [1.2, 1.3]},
                    "alt_rmse_m", "Altitude RMSE", "holdout window")
    assert h["verdict"] == "no CI" and h["ci95"] is None and h["n_blocks"] == 1
    assert h["text"] == ("Altitude RMSE: 1 paired holdout window(s): no confidence interval "
                         "(at least 4 are needed).")
    assert rank_metric({"a": 1.0, "b": None}, {}, "alt_rmse_m", "x", "y") is None


def test_headline_names_the_family_that_ties_and_its_margin() -> None:
    """Three smoothers within noise of each other: one sentence names the family, its value and
    how far the best filter and loop trail; the statistics name every tied estimator."""
    rng = np.random.default_rng(3)
    base = 0.18 + 0.02 * rng.standard_normal(8)
    noise = {"ekf-rts": 0.002, "graph-batch": 0.0, "graph-isam2": -0.001}
    ests, pb = {}, {}
    for n, off in noise.items():
        blocks = list(base + off + 0.01 * rng.standard_normal(8))
        pb[n] = _blocks(blocks)
        ests[n] = _est(float(np.sqrt(np.mean(np.square(blocks)))))
    for n, v in (("ekf", 0.34), ("vekf7", 0.50), ("loop3", 3.6)):
        pb[n], ests[n] = _blocks([v] * 8), _est(v)
    comp = comparison(ests, pb, "truth", [(0, 1)] * 8, "time block", "note")
    h = comp["metrics"]["alt_rmse_m"]
    assert {t["name"] for t in h["tied"]} == {"ekf-rts", "graph-batch", "graph-isam2"} - {
        h["best"]}
    assert h["resolved"]
    assert h["summary_text"].startswith(
        "Altitude RMSE: the smoothers (ekf-rts, graph-batch, graph-isam2) at 0.1")
    assert "not resolved from one another" in h["summary_text"]
    r_filter = 0.34 / h["best_value"]
    assert f"{r_filter:.1f}× better than the best filter (ekf 0.34 m)" in h["summary_text"]
    assert "better than the best loop or observer (loop3 3.60 m)" in h["summary_text"]
    third = ({"ekf-rts", "graph-batch", "graph-isam2"} - {h["best"], h["runner_up"]}).pop()
    assert f"; {third} +" in h["text"]  # every unresolved one with its paired CI
    assert comp["headline"] == [h["summary_text"], h["text"]]  # one line each, no repeat


def test_two_windows_cannot_rank() -> None:
    """Fewer than four windows: no CI, no ranking, one line saying so and what would resolve
    it; the rankings are not printed."""
    from vnav_graph.evaluation.compare import can_rank, ranking_lines, rankings

    ests = {"ekf-rts": _est(0.67), "graph-batch": _est(0.672), "vekf7": _est(1.73)}
    pb = {"ekf-rts": _blocks([0.6, 0.74]), "graph-batch": _blocks([0.62, 0.72]),
          "vekf7": _blocks([1.5, 1.9])}
    comp = comparison(ests, pb, "withheld GNSS (holdout)", [(0, 1)] * 2, "holdout window",
                      "note", remedy="--outage 30 gives 5 windows on this log")
    h = comp["metrics"]["alt_rmse_m"]
    assert not h["resolved"] and h["ci95"] is not None  # computed, kept in the JSON
    assert comp["headline"] == [
        "Not resolved: 2 paired holdout window(s) cannot rank the estimators (at least 4 are "
        "needed), so no confidence interval and no ranking is given; --outage 30 gives 5 "
        "windows on this log."]
    summary = {"comparison": comp, "rankings": rankings(ests)}
    assert not can_rank(summary) and ranking_lines(summary) == []
    lines = headline_lines(summary)
    assert not any("CI [" in x or "<" in x for x in lines)
    # four windows: ranked
    pb4 = {n: _blocks([b["alt_rmse_m"] for b in v] * 2) for n, v in pb.items()}
    comp4 = comparison(ests, pb4, "x", [(0, 1)] * 4, "holdout window", "note")
    assert comp4["resolved"] and comp4["remedy"] is None
    assert ranking_lines({"comparison": comp4, "rankings": rankings(ests)})


def test_against_baseline_puts_everyone_against_one() -> None:
    from vnav_graph.evaluation.compare import against_baseline

    ests = {"base": _est(1.0), "variant": _est(0.9), "worse": _est(1.5),
            "broken": _est(0.1, status="failed")}
    pb = {"base": _blocks([1.0, 1.1, 0.9, 1.0]), "variant": _blocks([0.9, 1.0, 0.8, 0.9]),
          "worse": _blocks([1.6, 1.4, 1.7, 1.3]), "broken": _blocks([0.1] * 4)}
    comp = comparison(ests, pb, "truth", [(0, 1)] * 4, "time block", "note")
    s = against_baseline({"estimators": ests, "comparison": comp}, "base")
    rows = s["comparison"]["baseline"]["metrics"]["alt_rmse_m"]
    assert set(rows) == {"variant", "worse"}  # failed: not compared
    assert rows["variant"]["diff"] == pytest.approx(-0.1)
    assert rows["variant"]["verdict"] == "better"  # d = −0.1 in every block: CI below 0
    assert rows["worse"]["verdict"] == "worse"  # +0.6, +0.3, +0.8, +0.3: CI [+0.11, +0.89]
    first = s["comparison"]["headline"][0]
    assert first.startswith("Altitude RMSE against base (1.00 m), paired 95 % CI over the "
                            "time blocks: variant -0.100 m")
    assert "tied" not in first
    missing = against_baseline({"estimators": ests, "comparison": comp}, "broken")
    assert missing["comparison"]["headline"][0] == ("Altitude RMSE: the baseline broken has "
                                                    "no result (failed).")


def test_rankings_real_time_from_online_blocks_offline_from_trajectories():
    """Real time ranks the online blocks (graph-isam2 labelled "(online)"), offline every
    trajectory (graph-isam2 labelled "(final)"); a failed estimator and a null value are
    left out; the lines name both rankings."""
    from vnav_graph.evaluation.compare import ranking_lines, rankings

    def blk(alt, online=None, status="ok"):
        return {"status": status, "alt_rmse_m": alt, "horiz_rmse_m": None,
                "heading_rmse_deg": None,
                "online": None if online is None else {"alt_rmse_m": online,
                                                       "horiz_rmse_m": None,
                                                       "heading_rmse_deg": None}}

    ests = {"ekf": blk(0.30, 0.30), "ekf-rts": blk(0.10), "graph-batch": blk(0.11),
            "graph-isam2": blk(0.12, 0.25), "vkf4": blk(0.5, 0.5, status="failed")}
    rk = rankings(ests)
    assert [(r["name"], r["value"]) for r in rk["real_time"]["alt_rmse_m"]] == [
        ("graph-isam2 (online)", 0.25), ("ekf", 0.30)]
    assert [r["name"] for r in rk["offline"]["alt_rmse_m"]] == [
        "ekf-rts", "graph-batch", "graph-isam2 (final)", "ekf"]
    assert rk["real_time"]["horiz_rmse_m"] == []
    lines = ranking_lines({"rankings": rk})
    assert lines == ["REAL TIME (causal estimates) Altitude RMSE [m]: graph-isam2 (online) "
                     "0.25 < ekf 0.30",
                     "OFFLINE (smoothers and final trajectories) Altitude RMSE [m]: ekf-rts "
                     "0.10 < graph-batch 0.11 < graph-isam2 (final) 0.12 < ekf 0.30"]


def test_rankings_have_heading_where_each_reports_sigma_yaw_within_5_deg():
    """The heading ranking over the whole span puts the ekf first (graph-isam2's online
    estimate is charged for the standstill where it says it does not know); the one over the
    epochs where each reports σ_yaw ≤ 5° orders them by that metric."""
    from vnav_graph.evaluation.compare import rankings

    def blk(heading, known, from_s):
        on = {"heading_rmse_deg": heading, "heading_known_rmse_deg": known, "from_s": from_s}
        return {"status": "ok", "heading_rmse_deg": heading, "heading_known_rmse_deg": known,
                "online": on}

    rk = rankings({"ekf": blk(7.2, 0.9, 20.0), "graph-isam2": blk(21.0, 0.6, 0.0)})
    rt = rk["real_time"]
    assert [r["name"] for r in rt["heading_rmse_deg"]] == ["ekf", "graph-isam2 (online)"]
    assert [(r["name"], r["value"]) for r in rt["heading_known_rmse_deg"]] == [
        ("graph-isam2 (online)", 0.6), ("ekf", 0.9)]
