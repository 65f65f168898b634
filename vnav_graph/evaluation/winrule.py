"""The study's win rule: a win counts only on a metric where the loser's reported σ does not
cover its error.

``benchmarks/hard_scenarios.py`` (the EKF-vs-graph study) and ``benchmarks/make_results.py``
(the results page) apply it to ``bench.json`` runs: a paired difference over seeds whose 95 %
interval excludes zero (``compare.paired_gain``) is a *win* only when ``win_rule`` counts it.
A loser that honestly says it does not know (its σ covers its error) is not beaten by being
more accurate where it says so.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .compare import paired_gain

# mean NEES/dof (or (|err|/σ)²) above which an estimator's σ does not cover its error; also
# the bound above which a winner counts as overconfident (unless the loser's is higher)
NEES_MAX = 2.0


def _value(row: dict[str, Any], key: str) -> float | None:
    """A run's metric, or one derived from it (NEES/dof, baro errors), None if not finite."""
    from .montecarlo import derived_metrics

    v = (row | derived_metrics(row)).get(key)
    return None if v is None or not math.isfinite(v) else float(v)


def paired_values(runs: list[dict[str, Any]], scenario: str, a: str, b: str, key: str
                  ) -> tuple[np.ndarray, np.ndarray, list[int]]:
    """Values of ``key`` for a and b over the seeds where both ran and have it."""
    by = {(r["estimator"], r["seed"]): r for r in runs
          if r["scenario"] == scenario and r["status"] == "ok"}
    xa, xb, seeds = [], [], []
    for (est, seed), ra in sorted(by.items(), key=lambda kv: kv[0][1]):
        rb = by.get((b, seed))
        if est != a or rb is None:
            continue
        va, vb = _value(ra, key), _value(rb, key)
        if va is not None and vb is not None:
            xa.append(va)
            xb.append(vb)
            seeds.append(int(seed))
    return np.array(xa), np.array(xb), seeds


# The win rule: a win counts only on a metric where the loser's reported σ does not cover
# its error (a loser that says honestly it does not know is not beaten by being more
# accurate where it says so). Per metric, "covers" is measured from the same runs:
# - heading: the win must hold on ``heading_known_rmse_deg`` too (each estimator scored only
#   where its own σ_yaw ≤ 5°), paired CI excluding 0 with the same sign;
# - baro parameters: the loser's mean (|estimate − truth| / σ)² over the seeds ≤ NEES_MAX;
# - every other error metric (position, height, velocity, outage maxima): the loser's mean
#   NEES/dof of position and velocity over the seeds ≤ NEES_MAX;
# - runtime has no σ: a win counts, as does a win over a loser that reports no σ (no NEES);
#   heading without ``heading_known_rmse_deg`` scores falls back on the NEES rule.
WIN_RULE = ("a win counts only on a metric where the loser's reported σ does not cover its "
            "error: for heading the win must also hold on heading_known_rmse_deg (each "
            "estimator scored only where its own σ_yaw ≤ 5°); for baro parameters the "
            "loser's mean (|error|/σ)² over the seeds must exceed {n:g}; for position, height "
            "and velocity errors (and heading without a heading_known score) the loser's "
            "mean NEES/dof must exceed {n:g}; a loser that reports no σ claims nothing, and a "
            "win over it counts")
BARO_KEYS = {"baro_scale_abs_err": "scale", "baro_latency_abs_err_s": "latency_s",
             "baro_bias_abs_err_m": "bias_m"}


def _loser_z2(runs: list[dict[str, Any]], scenario: str, loser: str, key: str
              ) -> float | None:
    """The loser's mean squared normalised error over the seeds: NEES/dof, or (|err|/σ)² of a
    baro parameter."""
    vals = []
    for r in runs:
        if r["scenario"] != scenario or r["estimator"] != loser or r["status"] != "ok":
            continue
        if key in BARO_KEYS:
            p = (r.get("baro") or {}).get(BARO_KEYS[key]) or {}
            if p.get("est") is not None and p.get("truth") is not None and p.get("sd"):
                vals.append(((p["est"] - p["truth"]) / p["sd"]) ** 2)
        else:
            v = _value(r, "nees_per_dof")
            if v is not None:
                vals.append(v)
    return float(np.mean(vals)) if vals else None


def win_rule(runs: list[dict[str, Any]], scenario: str, a: str, b: str, key: str,
             s: dict[str, Any]) -> dict[str, Any]:
    """Whether a significant difference counts as a win (``WIN_RULE``): ``winner``,
    ``loser``, ``counts`` (None when not significant), ``loser_z2`` (the loser's mean
    NEES/dof or (|err|/σ)², heading: null) and, for heading, ``known`` (the paired statistics
    on heading_known_rmse_deg)."""
    out: dict[str, Any] = {"winner": None, "loser": None, "counts": None, "loser_z2": None}
    ci = s.get("diff_ci95")
    if ci is None or not (ci[0] > 0 or ci[1] < 0):
        return out
    winner, loser = (b, a) if ci[0] > 0 else (a, b)
    out.update(winner=winner, loser=loser)
    if key == "runtime_s":
        out["counts"] = True
        return out
    if key.startswith("heading"):
        xa, xb, _ = paired_values(runs, scenario, a, b, "heading_known_rmse_deg")
        if xa.size:
            k = paired_gain(xa, xb)
            kci = k["diff_ci95"]
            out["known"] = k
            out["counts"] = bool(kci is not None
                                 and ((kci[0] > 0) if winner == b else (kci[1] < 0)))
            return out
    # without a heading_known score, heading falls back on the NEES rule below
    z2 = _loser_z2(runs, scenario, loser, key)
    out["loser_z2"] = z2
    # a loser that reports no σ for it claims nothing its error could be covered by
    out["counts"] = bool(z2 is None or z2 > NEES_MAX)
    return out


