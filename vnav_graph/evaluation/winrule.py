"""The accuracy win rule of the studies: which estimator is more accurate, over seeds.

``benchmarks/hard_scenarios.py`` (the EKF-vs-graph study) and ``benchmarks/make_results.py``
(the results page) apply ``win_rule`` to ``bench.json`` runs and print ``WIN_RULE`` beside
its verdicts (``describe``).

The rule (``WIN_RULE``):

- the paired difference d = a − b of a metric over the seeds where both ran; its Student-t
  95 % CI (``compare.paired_gain``) excluding 0 is an accuracy **win** for the lower one;
- calibration is reported beside it, never instead of it: each estimator's mean NEES/dof
  over the seeds on the metric's own axes (``metrics.nees_axes``: altitude 1 dof,
  horizontal 2, velocity its axes, heading (error/σ_yaw)²; baro parameters (|error|/σ)²);
- the only veto: a winner whose NEES/dof on those axes exceeds ``NEES_MAX`` and the loser's
  is marked "bought by overconfidence" and the win is not counted;
- heading is compared at the epochs where both report σ_yaw ≤ 5° (the run rows'
  ``heading_common``, ``montecarlo.common_heading_blocks``), the whole-drive score beside it;
- a seed where either lacks the metric (failed, skipped, or the value is null) is counted and
  named, never dropped silently;
- tails beside the mean: each one's worst seed and the 95th percentile of its |error|
  (``metrics.error_p95``, mean and largest over the seeds).

Runs made before a calibration or tail quantity was scored lack it; the rule then says what
it used instead (``calibration[...]["source"]``, ``heading_basis``) and the text says so.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from .compare import paired_gain

# NEES/dof above which an estimator's σ does not cover its error: a winner above it (and
# above the loser) won by overconfidence
NEES_MAX = 2.0

WIN_RULE = ("a paired difference over seeds whose 95 % CI excludes 0 is a win; calibration "
            "is reported beside it (each estimator's mean NEES/dof on the metric's own axes: "
            "altitude 1 dof, horizontal 2, velocity its axes, heading (error/σ_yaw)², baro "
            "parameters (|error|/σ)²); the only veto: a winner whose NEES/dof on those axes "
            "exceeds {n:g} and exceeds the loser's is marked \"bought by overconfidence\" and "
            "not counted; heading is compared at the epochs where both report σ_yaw ≤ 5°, "
            "with the whole-drive score beside it; a seed without the metric is counted and "
            "named; the worst seed and the 95th percentile of the error are given beside the "
            "mean")

# metric key → its axes in ``nees_axes`` (the online_* keys of the real-time rows alike)
AXIS = {"alt_rmse_m": "alt", "alt_max_abs_m": "alt", "outage_alt_max_m": "alt",
        "horiz_rmse_m": "horiz", "outage_horiz_max_m": "horiz",
        "vel_down_rmse_mps": "vel_down", "heading_rmse_deg": "heading",
        "heading_known_rmse_deg": "heading", "lag_alt_rmse_m": "alt",
        "lag_horiz_rmse_m": "horiz"}
AXIS |= {f"online_{k}": v for k, v in list(AXIS.items()) if not k.startswith("lag_")}
AXIS_LABEL = {"alt": "altitude, 1 dof", "horiz": "horizontal, 2 dof",
              "vel": "velocity, 3 dof", "vel_down": "vertical velocity, 1 dof",
              "heading": "heading, (error/σ_yaw)²"}
# axis → the run key of the 95th percentile of |error| (``metrics.error_p95``)
TAIL_KEY = {"alt": "alt_p95_m", "horiz": "horiz_p95_m", "heading": "heading_p95_deg",
            "vel_down": "vel_down_p95_mps"}
BARO_KEYS = {"baro_scale_abs_err": "scale", "baro_latency_abs_err_s": "latency_s",
             "baro_bias_abs_err_m": "bias_m"}
# metrics without a σ: a win on them has no calibration to report
NO_SIGMA = ("runtime_s", "realtime_factor")
# calibration metrics, not accuracy: lower is not better, no win is declared on them
CALIBRATION_KEYS = ("nees_mean", "nees_per_dof", "online_nees_per_dof")
HEADING_KEYS = ("heading_rmse_deg", "heading_known_rmse_deg")
# the 6-dof fallback's marker (runs scored before ``nees_axes``)
FALLBACK_6DOF = "position+velocity, 6 dof: the runs carry no per-axis NEES"


def _value(row: dict[str, Any], key: str) -> float | None:
    """A run's metric, or one derived from it (NEES/dof, baro errors), None if not finite."""
    from .montecarlo import derived_metrics

    v = row.get(key)
    if v is None:
        v = derived_metrics(row).get(key)
    return None if v is None or not math.isfinite(v) else float(v)


def _rows(runs: list[dict[str, Any]], scenario: str) -> dict[tuple[str, int], dict[str, Any]]:
    return {(r["estimator"], int(r["seed"])): r for r in runs if r["scenario"] == scenario}


def _pairs(runs: list[dict[str, Any]], scenario: str, a: str, b: str,
           get_a: Callable[[dict[str, Any]], float | None],
           get_b: Callable[[dict[str, Any]], float | None]
           ) -> tuple[np.ndarray, np.ndarray, list[int]]:
    """``get_a`` of a's row and ``get_b`` of b's over the seeds where both ran and have it."""
    by = _rows(runs, scenario)
    xa, xb, seeds = [], [], []
    for seed in sorted({s for e, s in by if e in (a, b)}):
        ra, rb = by.get((a, seed)), by.get((b, seed))
        if ra is None or rb is None or ra["status"] != "ok" or rb["status"] != "ok":
            continue
        va, vb = get_a(ra), get_b(rb)
        if va is not None and vb is not None:
            xa.append(va)
            xb.append(vb)
            seeds.append(int(seed))
    return np.array(xa), np.array(xb), seeds


def paired_values(runs: list[dict[str, Any]], scenario: str, a: str, b: str, key: str
                  ) -> tuple[np.ndarray, np.ndarray, list[int]]:
    """Values of ``key`` for a and b over the seeds where both ran and have it."""
    return _pairs(runs, scenario, a, b, lambda r: _value(r, key), lambda r: _value(r, key))


def _common_heading(row: dict[str, Any], other: str) -> float | None:
    blk = (row.get("heading_common") or {}).get(other) or {}
    v = blk.get("rmse_deg")
    return None if v is None or not math.isfinite(v) else float(v)


def _heading_pairs(runs: list[dict[str, Any]], scenario: str, a: str, b: str
                   ) -> tuple[np.ndarray, np.ndarray, list[int]]:
    """Heading RMSE of a and b at their common known epochs (``heading_common``), per seed."""
    return _pairs(runs, scenario, a, b, lambda r: _common_heading(r, b),
                  lambda r: _common_heading(r, a))


def _has_common_heading(runs: list[dict[str, Any]], scenario: str, a: str, b: str) -> bool:
    """Whether the rows carry the common-epoch heading of this pair (null values included:
    a seed where they never both know heading is then a named missing seed)."""
    return any(r["scenario"] == scenario and r["estimator"] == a and r["status"] == "ok"
               and b in (r.get("heading_common") or {}) for r in runs)


def _missing(runs: list[dict[str, Any]], scenario: str, a: str, b: str,
             value: Any) -> list[dict[str, Any]]:
    """The seeds of either estimator where a or b has no value: ``[{"seed", "estimator",
    "why"}]`` (no run, its status and error, or no value of the metric)."""
    by = _rows(runs, scenario)
    out = []
    for seed in sorted({s for e, s in by if e in (a, b)}):
        for est, other in ((a, b), (b, a)):
            r = by.get((est, seed))
            if r is None:
                why = "no run"
            elif r["status"] != "ok":
                err = str(r.get("error") or "")
                why = r["status"] + (f": {err[:60]}{'…' if len(err) > 60 else ''}"
                                     if err else "")
            elif value(r, other) is None:
                why = "no value"
            else:
                continue
            out.append({"seed": seed, "estimator": est, "why": why})
    return out


def _calibration(runs: list[dict[str, Any]], scenario: str, est: str, key: str,
                 seeds: list[int]) -> dict[str, Any]:
    """``{"nees_per_dof", "axes", "source", "n"}``: est's mean NEES/dof over ``seeds`` on the
    axes of ``key`` (per-axis from ``nees_axes``, else the 6-dof fallback, marked); baro
    parameters: mean (|error|/σ)²; None where it reports no σ."""
    by = _rows(runs, scenario)
    rows = [by[(est, s)] for s in seeds if (est, s) in by]
    out: dict[str, Any] = {"nees_per_dof": None, "axes": None, "source": None, "n": 0}
    if key in BARO_KEYS:
        vals = []
        for r in rows:
            p = (r.get("baro") or {}).get(BARO_KEYS[key]) or {}
            if p.get("est") is not None and p.get("truth") is not None and p.get("sd"):
                vals.append(((p["est"] - p["truth"]) / p["sd"]) ** 2)
        out.update(axes=f"baro {BARO_KEYS[key]}, (|error|/σ)²", source="per-parameter")
    else:
        axis = AXIS.get(key)
        if axis is None:
            return out
        online = key.startswith("online_")
        vals = []
        if not online and any("nees_axes" in r for r in rows):
            vals = [v for r in rows if (v := (r.get("nees_axes") or {}).get(axis)) is not None
                    and math.isfinite(v)]
            out.update(axes=AXIS_LABEL[axis], source="per-axis")
        elif axis != "heading":
            vals = [v for r in rows if (v := _value(r, "nees_per_dof")) is not None]
            out.update(axes=AXIS_LABEL[axis], source=FALLBACK_6DOF)
    out["n"] = len(vals)
    if vals:
        out["nees_per_dof"] = float(np.mean(vals))
    return out


def _tails(runs: list[dict[str, Any]], scenario: str, est: str, key: str,
           seeds: list[int], values: np.ndarray) -> dict[str, Any]:
    """est's worst seed of the compared values, and the 95th percentile of its |error| on the
    metric's axis (``metrics.error_p95``) as mean and largest over ``seeds``."""
    out: dict[str, Any] = {"worst": None, "worst_seed": None, "p95_key": None,
                           "p95_mean": None, "p95_max": None}
    if values.size:
        i = int(np.argmax(values))
        out.update(worst=float(values[i]), worst_seed=seeds[i])
    axis = AXIS.get(key)
    tk = TAIL_KEY.get(axis or "")
    if tk is None or key.startswith("online_"):
        return out
    by = _rows(runs, scenario)
    p = [v for s in seeds if (v := _value(by.get((est, s)) or {}, tk)) is not None]
    out["p95_key"] = tk
    if p:
        out.update(p95_mean=float(np.mean(p)), p95_max=float(np.max(p)))
    return out


def win_rule(runs: list[dict[str, Any]], scenario: str, a: str, b: str, key: str
             ) -> dict[str, Any]:
    """The verdict of ``WIN_RULE`` on ``key`` between a and b (d = a − b, lower is better).

    Returns ``{"key", "stats"`` (``paired_gain`` over the paired seeds), ``"seeds"``,
    ``"verdict"`` ("win", "bought by overconfidence", "not resolved", "identical",
    "no paired seeds", "calibration metric"), ``"winner"``, ``"loser"``, ``"counts"`` (True
    for a counted win, False for a vetoed one, None otherwise), ``"reason"`` (why not
    resolved), ``"calibration"`` ({a: ..., b: ...}: ``_calibration``), ``"loser_z2"`` (the
    loser's NEES/dof), ``"missing"`` (``_missing``), ``"tails"`` ({a: ..., b: ...}),
    and for heading ``"heading_basis"`` ("common known epochs", or the fallback used) and
    ``"whole_drive"`` (``paired_gain`` of the whole-drive heading RMSE)}``."""
    out: dict[str, Any] = {"key": key, "winner": None, "loser": None, "counts": None,
                           "loser_z2": None, "reason": None}
    if key in HEADING_KEYS and _has_common_heading(runs, scenario, a, b):
        xa, xb, seeds = _heading_pairs(runs, scenario, a, b)
        out["missing"] = _missing(runs, scenario, a, b, _common_heading)
        out["heading_basis"] = "at the epochs where both report σ_yaw ≤ 5°"
    else:
        used = key
        if key in HEADING_KEYS:
            # without a common-epoch score, the nearest: each where its own σ_yaw ≤ 5°
            known = any(r["scenario"] == scenario and r["estimator"] in (a, b)
                        and r.get("heading_known_rmse_deg") is not None for r in runs)
            used = "heading_known_rmse_deg" if known else "heading_rmse_deg"
            out["heading_basis"] = (
                "each where its own σ_yaw ≤ 5° (the runs carry no common-epoch heading)"
                if known else "over the whole drive (the runs carry no common-epoch heading "
                "and no heading_known score)")
        xa, xb, seeds = paired_values(runs, scenario, a, b, used)
        out["missing"] = _missing(runs, scenario, a, b, lambda r, _o: _value(r, used))
    if key in HEADING_KEYS:
        wa, wb, _ = paired_values(runs, scenario, a, b, "heading_rmse_deg")
        out["whole_drive"] = paired_gain(wa, wb)
    s = paired_gain(xa, xb)
    out.update(stats=s, seeds=seeds)
    out["calibration"] = {e: _calibration(runs, scenario, e, key, seeds) for e in (a, b)}
    out["tails"] = {e: _tails(runs, scenario, e, key, seeds, x)
                    for e, x in ((a, xa), (b, xb))}
    ci = s["diff_ci95"]
    if key in CALIBRATION_KEYS:
        out["verdict"] = "calibration metric"
    elif s["n"] == 0:
        out["verdict"] = "no paired seeds"
    elif np.all(xa == xb):
        out["verdict"] = "identical"
    elif ci is None:
        out["verdict"] = "not resolved"
        out["reason"] = f"{s['n']} paired seed: no CI"
    elif not (ci[0] > 0 or ci[1] < 0):
        out["verdict"] = "not resolved"
        out["reason"] = "the 95 % CI of the difference contains 0"
    else:
        winner, loser = (b, a) if ci[0] > 0 else (a, b)
        zw = out["calibration"][winner]["nees_per_dof"]
        zl = out["calibration"][loser]["nees_per_dof"]
        over = (key not in NO_SIGMA and zw is not None and zw > NEES_MAX
                and (zl is None or zw > zl))
        out.update(winner=winner, loser=loser, loser_z2=zl, counts=not over,
                   verdict="bought by overconfidence" if over else "win")
    return out


def _num(x: float | None, scale: float, spec: str) -> str:
    if x is None:
        return "—"
    text = format(x * scale, spec)
    return text[1:] if text.startswith("-") and float(text) == 0 else text  # no "-0.00"


def _iv(iv: list[float] | None, scale: float, spec: str) -> str:
    return "" if iv is None else f" [{_num(iv[0], scale, spec)}, {_num(iv[1], scale, spec)}]"


def describe(w: dict[str, Any], a: str, b: str, unit: str, scale: float = 1.0,
             spec: str = ".3g") -> str:
    """One line of a verdict: the paired difference and gain, the verdict (and its measured
    reason), calibration, tails, missing seeds and (heading) the whole-drive score."""
    s = w["stats"]
    u = f" {unit}" if unit else ""
    v = w["verdict"]
    if v == "no paired seeds":
        text = "no paired seeds"
    elif v == "identical":
        text = f"identical on every seed (n = {s['n']})"
    else:
        text = (f"d = {_num(s['diff'], scale, spec)}{_iv(s['diff_ci95'], scale, spec)}{u}, "
                f"gain {_num(s['gain'], 100, '.0f')}{_iv(s['gain_ci95'], 100, '.0f')} %, "
                f"n = {s['n']}: ")
        if v == "win":
            text += f"**{w['winner']} wins**"
        elif v == "bought by overconfidence":
            text += (f"{w['winner']} lower, **bought by overconfidence** (not counted: its "
                     f"NEES/dof {w['calibration'][w['winner']]['nees_per_dof']:.2f} > "
                     f"{NEES_MAX:g} and above {w['loser']}'s)")
        elif v == "calibration metric":
            text += "a calibration metric, not an accuracy win"
        else:
            text += f"not resolved ({w['reason']})"
    parts = [text]
    if "heading_basis" in w:
        parts.append(f"heading {w['heading_basis']}")
        wd = w.get("whole_drive") or {}
        if wd.get("n") and not w["heading_basis"].startswith("over the whole drive"):
            parts.append(f"whole drive d = {_num(wd['diff'], scale, spec)}"
                         f"{_iv(wd['diff_ci95'], scale, spec)}{u}")
    cal = w["calibration"]
    if any(c["nees_per_dof"] is not None for c in cal.values()):
        axes = next(c["axes"] for c in cal.values() if c["axes"])
        src = next(c["source"] for c in cal.values() if c["source"])
        label = axes if src in ("per-axis", "per-parameter") else src
        parts.append(f"NEES/dof ({label}): " + ", ".join(
            f"{e} {_num(c['nees_per_dof'], 1, '.2f')}" for e, c in cal.items()))
    tails = w["tails"]
    if v not in ("no paired seeds", "identical") and any(
            t["worst"] is not None for t in tails.values()):
        tail = "worst seed: " + ", ".join(
            f"{e} {_num(t['worst'], scale, spec)}{u} (seed {t['worst_seed']})"
            for e, t in tails.items() if t["worst"] is not None)
        if any(t["p95_mean"] is not None for t in tails.values()):
            tail += ("; 95th percentile of |error| over the drive (mean / largest over "
                     "seeds): ") + ", ".join(
                f"{e} {_num(t['p95_mean'], scale, spec)} / {_num(t['p95_max'], scale, spec)}{u}"
                for e, t in tails.items() if t["p95_mean"] is not None)
        elif any(t["p95_key"] for t in tails.values()):
            tail += "; 95th percentile of |error|: not in these runs"
        parts.append(tail)
    if w["missing"]:
        groups: dict[tuple[str, str], list[int]] = {}
        for m in w["missing"]:
            groups.setdefault((m["estimator"], m["why"]), []).append(m["seed"])
        parts.append(f"{len({m['seed'] for m in w['missing']})} seed(s) without the metric: "
                     + ", ".join(f"{'seed' if len(sd) == 1 else 'seeds'} "
                                 f"{', '.join(map(str, sd))} ({e}: {why})"
                                 for (e, why), sd in groups.items()))
    return "; ".join(parts)


__all__ = ["NEES_MAX", "WIN_RULE", "describe", "paired_values", "win_rule"]
