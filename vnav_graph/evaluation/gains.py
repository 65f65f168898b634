"""Filter against graph, paired over seeds, per scenario and metric: the numbers behind the
forest plot of the bench report and the results page.

Two like-for-like comparisons, each the filter family as ``a`` and the graph family as ``b``:

- **real time**: the forward ``ekf`` against ``graph-isam2``'s causal estimate, each scored by
  its ``online`` block over their common span (``real_time_rows``);
- **offline**: ``ekf-rts`` against ``graph-batch``, scored by the final trajectories.

A gain is g = 1 − mean(b)/mean(a) over the seeds both have (positive: the graph lower), with
its delta-method 95 % CI (``compare.paired_gain``), and the verdict of the win rule
(``winrule.win_rule``) beside it.
"""

from __future__ import annotations

from typing import Any

from .winrule import win_rule

# the keys a real-time row takes from its online (common-span) block
REAL_TIME_KEYS = ("alt_rmse_m", "horiz_rmse_m", "heading_rmse_deg", "heading_known_rmse_deg",
                  "heading_known_after_s", "vel_down_rmse_mps", "nees_mean", "nees_dof")
# keys of a bench row that describe the final trajectory only (cleared in real-time rows)
FINAL_ONLY = ("alt_p95_m", "horiz_p95_m", "heading_p95_deg", "vel_down_p95_mps")
# (label, filter, graph, real time?)
FAMILY_PAIRS = (("real time", "ekf", "graph-isam2", True),
                ("offline", "ekf-rts", "graph-batch", False))
# (key, label, unit): the metrics of the forest plot
GAIN_METRICS = (("alt_rmse_m", "altitude RMSE", "m"), ("horiz_rmse_m", "horizontal RMSE", "m"),
                ("heading_rmse_deg", "heading RMSE", "deg"))


def real_time_rows(runs: list[dict[str, Any]], a: str, b: str) -> list[dict[str, Any]]:
    """The rows of ``a`` and ``b`` with their real-time metrics in place of the trajectory's,
    both over their common span, from the later of their two first epochs: a row whose
    causal estimate starts earlier takes ``online_common[<other>]`` (the bench scores it from
    the other's first epoch, ``montecarlo.common_start_blocks``), the other its ``online``
    block. Rows without an online block are left out."""
    out = []
    for r in runs:
        if r["estimator"] not in (a, b) or not r.get("online"):
            continue
        other = b if r["estimator"] == a else a
        blk = (r.get("online_common") or {}).get(other) or r["online"]
        rt = {**r, **{k: blk.get(k) for k in REAL_TIME_KEYS}, "online": blk,
              # the final trajectory's: not the causal estimate's (the win rule then says
              # what it used instead)
              "heading_common": None, **dict.fromkeys(FINAL_ONLY)}
        rt.pop("nees_axes", None)
        out.append(rt)
    return out


def gain_rows(runs: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """One row per (scenario, comparison, metric) the runs allow: ``{"scenario",
    "comparison", "a", "b", "key", "label", "unit", "n", "gain", "gain_ci95", "diff",
    "diff_ci95", "verdict", "counts", "ci_disagree"}`` (``gain``/``gain_ci95`` None when there
    is no mean or fewer than two paired seeds; ``diff``/``diff_ci95``: the paired difference
    a − b that the win rule judges; ``ci_disagree``: not resolved by that difference while the
    gain's CI excludes 0, see ``gain_lines``)."""
    out = []
    for sc in dict.fromkeys(r["scenario"] for r in runs):
        for comp, a, b, rt in FAMILY_PAIRS:
            rows = real_time_rows(runs, a, b) if rt else runs
            have = {r["estimator"] for r in rows if r["scenario"] == sc}
            if a not in have or b not in have:
                continue
            for key, label, unit in GAIN_METRICS:
                w = win_rule(rows, sc, a, b, key)
                s = w["stats"]
                if s["n"] == 0:
                    continue
                out.append({"scenario": sc, "comparison": comp, "a": a,
                            "b": b, "key": key, "label": label, "unit": unit, "n": s["n"],
                            "gain": s["gain"], "gain_ci95": s["gain_ci95"],
                            "diff": s["diff"], "diff_ci95": s["diff_ci95"],
                            "verdict": w["verdict"], "counts": w["counts"],
                            "ci_disagree": (w["verdict"] == "not resolved"
                                            and s["diff_ci95"] is not None
                                            and _excludes_zero(s["gain_ci95"]))})
    return out


def _excludes_zero(iv: list[float] | None) -> bool:
    return iv is not None and (iv[0] > 0 or iv[1] < 0)


def gain_lines(rows: list[dict[str, Any]]) -> list[str]:
    """One Markdown bullet per gain row: the gain with its CI, the seeds and the verdict.

    The verdict judges the paired difference (Student t), the gain's CI is the delta
    method's, which scales each seed's difference by the filter's error on it; where the two
    disagree (a gain CI that excludes 0 on a difference that is not resolved) the line gives
    the difference's CI, so the words and the numbers do not contradict each other."""
    out = []
    for r in rows:
        if r["gain"] is None:
            continue
        ci = ("no CI" if r["gain_ci95"] is None else
              f"[{100 * r['gain_ci95'][0]:+.1f} %, {100 * r['gain_ci95'][1]:+.1f} %]")
        verdict = r["verdict"]
        if r.get("ci_disagree"):
            dci, unit = r["diff_ci95"], r.get("unit", "")
            verdict += (f": the win rule's paired difference d = {r['diff']:.3g} "
                        f"[{dci[0]:+.3g}, {dci[1]:+.3g}] {unit} contains 0; the gain's "
                        "delta-method CI, which scales each seed by the filter's error, "
                        "excludes it")
        out.append(f"- {r['scenario']}, {r['comparison']} ({r['a']} → {r['b']}), "
                   f"{r['label']}: gain {100 * r['gain']:+.1f} % {ci} over {r['n']} seeds, "
                   f"{verdict}")
    return out
