"""Which estimator is best, by how much, and is the difference resolved?

The headline of a run (``summary.json["comparison"]``, the top of ``report.html`` and a line
of the terminal table) is built here from numbers already in the summary, so every place that
prints it prints the same words.

Per metric (altitude RMSE, horizontal RMSE where at least two estimators provide it):

- **best** = the estimator with the lowest RMSE in the comparison table, **runner-up** the
  next one; the difference is ``runner-up − best`` [m] and relative to the runner-up [%].
- **paired CI**: the same two estimators are scored on the same blocks (holdout windows of a
  real log, or equal time blocks of one simulated run). With ``d_k = RMSE_runner,k −
  RMSE_best,k`` over the ``n`` blocks where both have a value, the 95 % interval is the
  Student-t interval ``mean(d) ± t_{0.975, n−1} · sd(d)/√n``. The t-interval is used rather
  than a bootstrap because ``n`` is small (2 to 10): a bootstrap of 2 numbers returns their
  range, which is not a 95 % interval.
- **verdict** (the JSON value): ``"better"`` when the CI lies above zero, ``"tied"`` when it
  contains zero, ``"mixed"`` when it lies below zero (per-block differences favour the
  runner-up although its overall RMSE is higher), ``"no CI"`` with fewer than two paired
  blocks. The words printed say "not resolved", with the measured reason (``reason``): the
  excess sits in k of n blocks (``concentration``), or the CI contains 0, or the blocks favour
  the other one.
- Fewer than ``MIN_BLOCKS_TO_RANK`` paired blocks give no CI and no ranking in the printed
  words; one line says so and what would resolve it (the caller's ``remedy``: a longer drive,
  a shorter ``--outage``).

Honesty about the blocks: holdout windows are separated by at least one outage length of
GNSS, which re-anchors every estimator, so they are close to independent. Time blocks of one
simulated run are not independent (a baro bias with a time constant of minutes spans blocks);
this is the batch-means interval of a single run and is labelled so — an interval over runs
comes from ``vnav-graph bench`` with several seeds.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from ..types.streams import FloatArray

# Time blocks of one simulated run: about 30 s each, at least 2 and at most 10.
BLOCK_MIN_S = 30.0
MAX_BLOCKS = 10
# (summary key, label in the headline)
HEADLINE_METRICS = (("alt_rmse_m", "Altitude RMSE"), ("horiz_rmse_m", "Horizontal RMSE"))
# Fewer paired blocks than this cannot rank estimators: the t quantile with 2 degrees of
# freedom is 4.3 (3.2 with 3), so only a difference several times its scatter is resolved.
MIN_BLOCKS_TO_RANK = 4
# The finding sentence groups with the best the estimators the blocks do not resolve from it
# and whose value is within this fraction of it; the others are named with the reason.
TIE_REL = 0.10
# ``concentration``: the share of the summed |paired difference| the fewest blocks must hold
CONCENTRATION = 0.9


def time_blocks(t0: float, t1: float) -> list[tuple[float, float]]:
    """Equal contiguous blocks ``[(a, b), ...]`` covering ``[t0, t1]`` [s] (module docstring)."""
    n = int(min(MAX_BLOCKS, max(2, math.floor((t1 - t0) / BLOCK_MIN_S))))
    edges = np.linspace(t0, t1, n + 1)
    return [(float(a), float(b)) for a, b in zip(edges[:-1], edges[1:], strict=True)]


def block_rmse(t: FloatArray, err: FloatArray | None,
               blocks: Sequence[tuple[float, float]]) -> list[float | None]:
    """RMS of ``err`` over the samples of each block (None where a block has no finite one).

    A sample on a shared edge belongs to the later block, the last block is closed.
    """
    out: list[float | None] = []
    if err is None:
        return [None] * len(blocks)
    for k, (a, b) in enumerate(blocks):
        m = (t >= a) & ((t < b) if k < len(blocks) - 1 else (t <= b)) & np.isfinite(err)
        out.append(float(np.sqrt(np.mean(err[m] ** 2))) if m.any() else None)
    return out


def paired_interval(d: Sequence[float], level: float = 0.95) -> tuple[float, float, float] | None:
    """(mean, lo, hi) Student-t interval of the mean of paired differences ``d``; None if n<2."""
    from scipy.stats import t as student_t

    x = np.asarray(d, dtype=float)
    if x.size < 2:
        return None
    mean = float(np.mean(x))
    half = float(student_t.ppf(0.5 + level / 2, x.size - 1) * np.std(x, ddof=1) / np.sqrt(x.size))
    return mean, mean - half, mean + half


def paired_gain(xa: FloatArray, xb: FloatArray, level: float = 0.95) -> dict[str, Any]:
    """Paired statistics of b against a over the same runs (seeds): the difference
    d = a − b (positive: b lower) with its Student-t interval (``paired_interval``), and the
    relative gain g = mean(d)/mean(a) = 1 − mean(b)/mean(a) with a delta-method interval
    (the residuals (d_i − g·a_i)/mean(a) of the per-run pairs, same t quantile).

    Returns ``{"n", "mean_a", "mean_b", "diff", "diff_ci95", "gain", "gain_ci95"}``; the
    intervals are None with fewer than two pairs, everything but ``n`` with none."""
    from scipy.stats import t as student_t

    xa, xb = np.asarray(xa, dtype=float), np.asarray(xb, dtype=float)
    n = int(xa.size)
    out: dict[str, Any] = {"n": n, "mean_a": None, "mean_b": None, "diff": None,
                           "diff_ci95": None, "gain": None, "gain_ci95": None}
    if n == 0:
        return out
    d = xa - xb
    ma = float(xa.mean())
    out.update(mean_a=ma, mean_b=float(xb.mean()), diff=float(d.mean()))
    if ma > 0:
        out["gain"] = float(d.mean() / ma)
    iv = paired_interval(d, level)
    if iv is None:
        return out
    out["diff_ci95"] = [iv[1], iv[2]]
    if ma > 0:
        g = out["gain"]
        tq = float(student_t.ppf(0.5 + level / 2, n - 1))
        gh = tq * float(np.std((d - g * xa) / ma, ddof=1)) / math.sqrt(n)
        out["gain_ci95"] = [g - gh, g + gh]
    return out


def _m(x: float) -> str:
    """A length [m] with the decimals its size needs (3 significant figures, at most 3
    decimals), so that a small difference never prints as 0.00."""
    a = abs(x)
    return f"{x:.1f}" if a >= 10 else (f"{x:.2f}" if a >= 0.1 else f"{x:.3f}")


def _dm(x: float) -> str:
    return ("+" if x >= 0 else "-") + _m(abs(x))


def concentration(d: Sequence[float], share: float = CONCENTRATION) -> int:
    """The fewest paired differences ``d`` whose |d| hold ``share`` of Σ|d| (the blocks an
    excess sits in); 0 for an empty or all-zero ``d``."""
    a = np.sort(np.abs(np.asarray(d, dtype=float)))[::-1]
    total = float(a.sum())
    if total <= 0:
        return 0
    return int(np.searchsorted(np.cumsum(a), share * total - 1e-12 * total) + 1)


def reason(t: Mapping[str, Any], best: str, block_kind: str) -> str:
    """Why an estimator is not resolved from ``best`` (an entry of ``rank_metric``'s
    ``tied``), measured: too few paired blocks, blocks that favour it, an excess that sits in
    a few blocks, or a CI that contains 0."""
    n = t["n_blocks"]
    if t["ci95"] is None or n < MIN_BLOCKS_TO_RANK:
        return f"{n} paired {block_kind}(s), at least {MIN_BLOCKS_TO_RANK} needed"
    lo, hi = t["ci95"]
    if hi < 0:
        return (f"the {block_kind}s favour it (paired 95 % CI [{_dm(lo)}, {_dm(hi)}] m) though "
                f"its RMSE over the run is higher")
    k = t.get("sits_in") or n
    if k <= n // 2:
        return f"its excess over {best} sits in {k} of {n} {block_kind}s"
    return f"the paired 95 % CI [{_dm(lo)}, {_dm(hi)}] m contains 0"


def rank_metric(values: Mapping[str, float | None],
                per_block: Mapping[str, Sequence[float | None]], key: str, label: str,
                block_kind: str) -> dict[str, Any] | None:
    """The headline block of one metric, or None when fewer than two estimators have it.

    ``values``: overall value per estimator (the table's number); ``per_block``: the same
    metric per block, aligned across estimators. Besides best and runner-up, ``tied`` lists
    every other estimator the blocks do not separate from the best (its paired CI includes
    0 or lies below it, or fewer than two paired blocks), and ``resolved`` says whether there
    are ``MIN_BLOCKS_TO_RANK`` paired blocks or more.
    """
    have = sorted(((v, n) for n, v in values.items() if v is not None and np.isfinite(v)))
    if len(have) < 2:
        return None
    (best_v, best), (run_v, runner) = have[0], have[1]

    def paired(other: str) -> tuple[list[float], tuple[float, float, float] | None]:
        pb, po = per_block.get(best) or [], per_block.get(other) or []
        d = [o - b for b, o in zip(pb, po, strict=False) if b is not None and o is not None]
        return d, paired_interval(d)

    d, ci = paired(runner)
    diff = run_v - best_v
    rel = 100.0 * diff / run_v if run_v > 0 else None
    if ci is None:
        verdict = "no CI"
    else:
        verdict = "better" if ci[1] > 0 else ("mixed" if ci[2] < 0 else "tied")
    tied = []
    for v, n in have[1:]:
        dn, cin = paired(n)
        if cin is None or cin[1] <= 0:
            tied.append({"name": n, "value": v, "n_blocks": len(dn),
                         "paired_mean": None if cin is None else cin[0],
                         "ci95": None if cin is None else [cin[1], cin[2]],
                         "sits_in": concentration(dn)})
    out = {"metric": key, "best": best, "best_value": best_v, "runner_up": runner,
           "runner_up_value": run_v, "diff": diff, "rel_pct": rel, "n_blocks": len(d),
           "n_blocks_best_lower": int(sum(x > 0 for x in d)),
           "paired_mean": None if ci is None else ci[0],
           "ci95": None if ci is None else [ci[1], ci[2]], "verdict": verdict,
           "tied": tied, "resolved": len(d) >= MIN_BLOCKS_TO_RANK,
           "values": {n: v for v, n in have}}
    for t in tied:
        t["reason"] = reason(t, best, block_kind)
    out["text"] = headline_text(out, label, block_kind)
    out["summary_text"] = people_text(out, label, block_kind)
    return out


def headline_text(h: Mapping[str, Any], label: str, block_kind: str) -> str:
    """The statistical line of ``rank_metric``: each estimator's paired difference from the
    best over the blocks with its 95 % CI (numbers only: ``people_text`` says what they
    resolve); without a CI under ``MIN_BLOCKS_TO_RANK`` blocks."""
    n = h["n_blocks"]
    if not h["resolved"]:
        return (f"{label}: {n} paired {block_kind}(s): no confidence interval (at least "
                f"{MIN_BLOCKS_TO_RANK} are needed).")
    rows = [{"name": h["runner_up"], "value": h["runner_up_value"], "ci95": h["ci95"],
             "paired_mean": h["paired_mean"], "n_blocks": n}]
    rows += [t for t in h.get("tied", []) if t["name"] != h["runner_up"]]
    parts = [f"{t['name']} {_dm(t['paired_mean'])} m [{_dm(t['ci95'][0])}, "
             f"{_dm(t['ci95'][1])}]" for t in rows if t["ci95"] is not None]
    return (f"{label}, paired difference from {h['best']} ({_m(h['best_value'])} m) over {n} "
            f"{block_kind}s, 95 % CI: " + "; ".join(parts)
            + f" ({h['best']} lower than {h['runner_up']} in {h['n_blocks_best_lower']} of "
            f"{n}).")


def _names(names: Sequence[str]) -> str:
    return names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]


def _times(r: float) -> str:
    return f"{r:.0f}×" if r >= 10 else f"{r:.1f}×"


def people_text(h: Mapping[str, Any], label: str, block_kind: str) -> str:
    """The finding of ``rank_metric`` in one sentence for a person: who is best (or which
    estimators the blocks do not resolve from it, and why), and by how much the best of every
    other family trails, e.g. "Altitude RMSE: the smoothers (ekf-rts, graph-batch,
    graph-isam2) at 0.18 m, not resolved from one another, 1.9× better than the best filter
    (ekf 0.34 m) and 12× better than the best loop or observer (observer1d 2.08 m)."."""
    from ..estimators.base import FAMILIES, family_of

    values: dict[str, float] = h["values"]
    best = h["best"]
    if not h["resolved"]:
        return (f"{label}: not resolved: {h['n_blocks']} paired {block_kind}(s) cannot rank "
                f"the estimators (at least {MIN_BLOCKS_TO_RANK} are needed).")
    close = [t["name"] for t in h["tied"] if t["value"] <= (1 + TIE_REL) * h["best_value"]]
    loose = [t for t in h["tied"] if t["name"] not in close]
    top = [best, *close]
    top_v = [values[n] for n in top]
    fams = {family_of(n)[0] for n in top}
    at = (f"{_m(min(top_v))} m" if _m(min(top_v)) == _m(max(top_v))
          else f"{_m(min(top_v))}–{_m(max(top_v))} m")
    if len(top) == 1:  # "best" only when every other one is resolved from it
        who = f"{best} {'lowest' if loose else 'is best'} at {at}"
    else:
        members = next((m for f, _, m in FAMILIES if f in fams), ())
        present = [n for n in members if n in values]
        if len(fams) == 1 and sorted(present) == sorted(top):
            who = f"the {family_of(best)[0]} ({', '.join(present)}) at {at}"
        else:
            who = f"{_names(top)} at {at}"
        who += ", not resolved from one another"
    trail: dict[str, tuple[str, float, str]] = {}
    loose_names = {t["name"] for t in loose}
    for n, v in values.items():
        f, one = family_of(n)
        if f not in fams and (f not in trail or v < trail[f][1]):
            trail[f] = (n, v, one)
    parts = [f"{_times(v / h['best_value'])} better than the best {one} ({n} {_m(v)} m)"
             for n, v, one in sorted(trail.values(), key=lambda x: x[1])
             if h["best_value"] > 0 and n not in loose_names]
    text = f"{label}: {who}" + (", " + " and ".join(parts) if parts else "")
    for t in loose:
        text += (f"; {t['name']} ({_m(t['value'])} m) not resolved from "
                 f"{'it' if len(top) == 1 else 'them'}: {t['reason']}")
    return text + "."


def comparison(estimators: Mapping[str, Mapping[str, Any]],
               per_block: Mapping[str, Sequence[Mapping[str, Any]]], basis: str,
               blocks: Sequence[tuple[float, float]], block_kind: str,
               note: str, remedy: str | None = None) -> dict[str, Any]:
    """``summary["comparison"]``: the headline of each metric and the per-block values it
    used (``per_block``: name → list aligned with ``blocks`` of dicts with the metric keys).

    ``estimators`` are the summary's estimator blocks; failed estimators and missing values
    are left out of the ranking. The headline has one line per message: per metric the
    finding (``summary_text``) and, where the blocks can rank, its numbers (``text``); when no
    metric has ``MIN_BLOCKS_TO_RANK`` paired blocks, one line instead saying so and what would
    resolve it (``remedy``; also in ``comparison["remedy"]``).
    """
    metrics: dict[str, Any] = {}
    for key, label in HEADLINE_METRICS:
        vals = {n: m.get(key) for n, m in estimators.items() if m.get("status") == "ok"}
        pb = {n: [b.get(key) for b in rows] for n, rows in per_block.items()}
        metrics[key] = rank_metric(vals, pb, key, label, block_kind)
    have = [m for m in metrics.values() if m]
    resolved = any(m["resolved"] for m in have)
    if have and not resolved:
        n = max(m["n_blocks"] for m in have)
        headline = [f"Not resolved: {n} paired {block_kind}(s) cannot rank the estimators "
                    f"(at least {MIN_BLOCKS_TO_RANK} are needed), so no confidence interval "
                    "and no ranking is given" + (f"; {remedy}" if remedy else "") + "."]
    else:
        headline = [m["summary_text"] for m in have]
        headline += [m["text"] for m in have if m["resolved"]]
    return {"basis": basis, "block_kind": block_kind, "headline": headline,
            "blocks": [[float(a), float(b)] for a, b in blocks], "note": note,
            "method": "95 % Student-t interval of the paired per-block RMSE difference "
                      "(runner-up − best); not resolved when it includes 0",
            "resolved": resolved, "remedy": None if resolved else remedy,
            "metrics": metrics, "per_block": {n: list(r) for n, r in per_block.items()}}


def can_rank(summary: Mapping[str, Any]) -> bool:
    """Whether a summary's comparison has a metric with enough paired blocks to rank (True
    without a comparison: nothing says otherwise)."""
    comp = summary.get("comparison")
    return not comp or bool(comp.get("resolved", True))


def headline_lines(summary: Mapping[str, Any]) -> list[str]:
    """The headline sentences of a summary (empty when there is nothing to compare)."""
    comp = summary.get("comparison")
    if not comp:
        return []
    lines = list(comp.get("headline") or [m["text"] for m in comp["metrics"].values() if m])
    if lines and comp.get("note"):
        lines.append(comp["note"])
    return lines


def against_baseline(summary: Mapping[str, Any], baseline: str) -> dict[str, Any]:
    """The summary with every estimator put against ``baseline`` (``run --baseline NAME``):
    per metric the paired difference estimator − baseline over the same blocks, its 95 %
    t-interval and a verdict ("better" / "worse" when the interval excludes 0, else "tied";
    "no CI" under two blocks), in ``comparison["baseline"]``, and one headline line per metric
    put first. A baseline without a result (failed, skipped, diverged) is said so instead."""
    import copy

    out = copy.deepcopy(dict(summary))
    comp = out.get("comparison")
    if not comp:
        return out
    ests = out["estimators"]
    kind = comp.get("block_kind", "block")
    lines: list[str] = []
    res: dict[str, Any] = {}
    for key, label in HEADLINE_METRICS:
        vals = {n: m[key] for n, m in ests.items()
                if m.get("status") == "ok" and m.get(key) is not None}
        if baseline not in vals:
            if key == "alt_rmse_m":
                status = ests.get(baseline, {}).get("status", "not run")
                lines.append(f"{label}: the baseline {baseline} has no result ({status}).")
            continue
        pb = {n: [b.get(key) for b in rows] for n, rows in comp.get("per_block", {}).items()}
        base_v, base_b = vals[baseline], pb.get(baseline) or []
        rows: dict[str, Any] = {}
        parts = []
        for n, v in sorted(vals.items(), key=lambda x: x[1]):
            if n == baseline:
                continue
            d = [x - y for x, y in zip(pb.get(n) or [], base_b, strict=False)
                 if x is not None and y is not None]
            ci = paired_interval(d)
            verdict = ("no CI" if ci is None else "better" if ci[2] < 0 else
                       "worse" if ci[1] > 0 else "tied")
            rows[n] = {"value": v, "diff": v - base_v, "n_blocks": len(d),
                       "ci95": None if ci is None else [ci[1], ci[2]], "verdict": verdict}
            if ci is None or len(d) < MIN_BLOCKS_TO_RANK:
                parts.append(f"{n} {_dm(v - base_v)} m (not resolved: {len(d)} paired "
                             f"{kind}(s), at least {MIN_BLOCKS_TO_RANK} needed)")
                continue
            why = verdict if verdict != "tied" else (
                "not resolved: " + reason({"n_blocks": len(d), "ci95": [ci[1], ci[2]],
                                           "sits_in": concentration(d)}, baseline, kind))
            parts.append(f"{n} {_dm(v - base_v)} m [{_dm(ci[1])}, {_dm(ci[2])}] ({why})")
        res[key] = rows
        if parts:
            lines.append(f"{label} against {baseline} ({_m(base_v)} m), paired 95 % CI over "
                         f"the {kind}s: " + ", ".join(parts) + ".")
    comp["baseline"] = {"name": baseline, "metrics": res}
    comp["headline"] = [*lines, *(comp.get("headline") or [])]
    return out


# (block key, label, unit) of the two rankings
RANKING_METRICS = (("alt_rmse_m", "Altitude RMSE", "m"), ("horiz_rmse_m", "Horizontal RMSE", "m"),
                   ("heading_rmse_deg", "Heading RMSE", "deg"),
                   ("heading_known_rmse_deg", "Heading RMSE where its own σ_yaw ≤ 5°", "deg"))


def rankings(estimators: Mapping[str, Mapping[str, Any]]) -> dict[str, Any]:
    """``summary["rankings"]``: the estimators ordered per metric, lowest first, in two lists.

    - ``real_time``: the causal estimates, from each block's ``online`` block (the filters,
      loops and observer, and graph-isam2's online estimate as ``"graph-isam2 (online)"``).
      An estimator that is not in ``base.CAUSAL`` but has an online block is labelled
      ``"<name> (online)"``; each entry has the block's ``from_s`` (its first scored epoch).
    - ``offline``: every estimator's trajectory, from the block itself (the smoothers, and
      graph-isam2's final trajectory as ``"graph-isam2 (final)"``; a filter's trajectory is
      its online estimate and an offline answer too).

    Only estimators with ``status`` ok are ranked; each entry is ``{"name", "estimator",
    "value"}``. A ranking orders values; whether a difference is resolved is the paired
    comparison's job (``comparison``, ``vnav-graph bench``).
    """
    from ..estimators.base import CAUSAL

    def ordered(rows: list[tuple[str, str, Any, Any]]) -> list[dict[str, Any]]:
        have = sorted(((v, label, n, f) for label, n, v, f in rows
                       if v is not None and np.isfinite(v)), key=lambda x: x[:3])
        return [{"name": label, "estimator": n, "value": float(v),
                 **({} if f is None else {"from_s": float(f)})} for v, label, n, f in have]

    ok = {n: m for n, m in estimators.items() if m.get("status") == "ok"}
    out: dict[str, Any] = {"real_time": {}, "offline": {}}
    for key, _, _ in RANKING_METRICS:
        out["real_time"][key] = ordered([
            (n if n in CAUSAL else f"{n} (online)", n, m["online"].get(key),
             m["online"].get("from_s")) for n, m in ok.items() if m.get("online")])
        out["offline"][key] = ordered([
            (f"{n} (final)" if m.get("online") and n not in CAUSAL else n, n, m.get(key), None)
            for n, m in ok.items()])
    return out


def ranked_name(entry: Mapping[str, Any]) -> str:
    """A ranking entry's name, with the start of its scored span when that is not the drive's
    start (the ekf's online estimate starts when it is aligned)."""
    f = entry.get("from_s")
    return entry["name"] + (f" (from {f:.0f} s)" if f is not None and f >= 0.5 else "")


def ranking_lines(summary: Mapping[str, Any]) -> list[str]:
    """The two rankings of a summary as text lines, one per ranking and metric."""
    rk = summary.get("rankings")
    if not rk or not can_rank(summary):  # the headline says it cannot, and what would
        return []
    lines = []
    for kind, title in (("real_time", "REAL TIME (causal estimates)"),
                        ("offline", "OFFLINE (smoothers and final trajectories)")):
        for key, label, unit in RANKING_METRICS:
            rows = rk.get(kind, {}).get(key) or []
            if len(rows) < 2:
                continue
            spec = ".1f" if unit == "deg" else ".2f"
            lines.append(f"{title} {label} [{unit}]: " + " < ".join(
                f"{ranked_name(r)} {format(r['value'], spec)}" for r in rows))
    return lines
