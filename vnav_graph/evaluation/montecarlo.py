"""Monte Carlo bench scoring: aggregation over seeds, the ``bench.json`` tables.

The runs themselves are made by ``vnav_graph.run.bench`` (local process pool or Dask); each run
row carries the metric block of ``summary.json`` (``vnav_graph.evaluation.metrics.evaluate``).

Aggregation over seeds (per scenario × estimator), for each metric x with n ≥ 2 finite values:

    x̄ = (1/n) Σ x_i,   s² = Σ (x_i − x̄)² / (n − 1),
    CI95 = x̄ ± t_{0.975, n−1} · s / √n          (Student t, e.g. Montgomery & Runger §8.2)

n = 1 gives the mean and ``ci95: null``; n = 0 gives ``mean: null``.

Contents
--------
``shorten_scenario`` (duration override that keeps the GNSS outages inside the shortened
drive), ``finite`` (NaN/inf to null), ``mean_ci95``, ``derived_metrics``, ``aggregate``,
``format_bench_md``, ``write_bench`` and ``failure_summary``.

The ``bench.json`` document (docs/design.md)::

    {"schema": "vnav_graph.run.bench/1",
     "config": {...},
     "runs": [{"scenario", "seed", "estimator", "duration_s", "status", "error",
               <metric fields of summary.json>}],
     "aggregate": {"<scenario>": {"<estimator>": {"n_runs", "n_ok", "n_failed",
                   "alt_rmse_m": {"mean", "ci95": [lo, hi], "sd", "n"}, ...}}}}
"""

from __future__ import annotations

import json
import math
import os
import tempfile
from collections.abc import Callable, Iterable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

BENCH_SCHEMA = "vnav_graph.run.bench/1"

# Metrics aggregated over seeds (mean and 95 % CI). The first four are the docs/design.md ones;
# the baro parameter errors |est − truth| show the modelling gain of the baro-aware estimators.
AGG_METRICS = (
    "alt_rmse_m", "nees_mean", "runtime_s", "vel_down_rmse_mps", "alt_max_abs_m",
    "nees_per_dof", "realtime_factor", "baro_scale_abs_err", "baro_latency_abs_err_s",
    "baro_bias_abs_err_m", "horiz_rmse_m", "heading_rmse_deg", "heading_known_rmse_deg",
    "heading_known_after_s", "outage_alt_max_m",
    "outage_horiz_max_m", "gnss_rejected",
    # the causal estimate's and graph-isam2's fixed-lag estimate's (the online / lag blocks)
    "online_alt_rmse_m", "online_horiz_rmse_m", "online_heading_rmse_deg",
    "online_nees_per_dof", "online_heading_known_rmse_deg", "online_heading_known_after_s",
    "lag_alt_rmse_m", "lag_horiz_rmse_m",
)

# `bench --quick`: CI-sized. Short drives, two scenarios, three seeds (the smallest number
# for which a t-interval is not absurdly wide: t_0.975,2 = 4.3 vs 12.7 for two), every
# available estimator. Measured: 60 runs in ≈ 30 s on 2 cores.
QUICK_SCENARIOS = ("hill-drive", "sortie")
QUICK_SEEDS = 3
QUICK_DURATION_S = 180.0
DEFAULT_SCENARIOS = ("hill-drive", "sortie")
DEFAULT_SEEDS = 5
DEFAULT_WORKERS = 2
# A shortened drive keeps each GNSS outage at the same relative position, no longer than this
# fraction of the drive (so that GNSS is present before and after it).
MAX_OUTAGE_FRACTION = 0.25


def shorten_scenario(scenario: str, duration_s: float | None) -> Any:
    """ScenarioConfig of ``scenario`` with its duration overridden.

    GNSS outage windows keep their relative position in the drive: a window (a, b) of a
    drive of length D becomes (a·D'/D, a·D'/D + min(b − a, 0.25·D')) in the drive of length
    D'. Without this rule a 150 s version of a scenario whose outages lie after 300 s would
    have no outage at all and the bench would not exercise the baro-inertial channel.
    """
    from ..simulation import load_scenario

    cfg = load_scenario(scenario)
    if duration_s is None or duration_s == cfg.duration_s:
        return cfg
    ratio = duration_s / cfg.duration_s
    outages = []
    for a, b in cfg.gnss.outages:
        a2 = a * ratio
        outages.append((a2, a2 + min(b - a, MAX_OUTAGE_FRACTION * duration_s)))
    return replace(cfg, duration_s=float(duration_s),
                   gnss=replace(cfg.gnss, outages=tuple(outages)))


def finite(x: Any) -> Any:
    """Replace NaN/inf floats by None, recursively (JSON has no NaN; docs/design.md: metrics that
    do not exist are null)."""
    if isinstance(x, dict):
        return {k: finite(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [finite(v) for v in x]
    if isinstance(x, float | np.floating):
        return float(x) if math.isfinite(x) else None
    if isinstance(x, np.integer):
        return int(x)
    return x


def mean_ci95(values: Iterable[float | None]) -> dict[str, Any]:
    """Mean, sample sd and Student-t 95 % confidence interval of the finite values.

    Returns ``{"mean", "ci95": [lo, hi], "sd", "n"}``; ``ci95`` and ``sd`` are None for
    n < 2, ``mean`` is None for n = 0.
    """
    from scipy.stats import t as student_t

    x = np.array([v for v in values if v is not None and math.isfinite(v)], dtype=float)
    n = int(x.size)
    if n == 0:
        return {"mean": None, "ci95": None, "sd": None, "n": 0}
    mean = float(np.mean(x))
    if n == 1:
        return {"mean": mean, "ci95": None, "sd": None, "n": 1}
    sd = float(np.std(x, ddof=1))
    half = float(student_t.ppf(0.975, n - 1)) * sd / math.sqrt(n)
    return {"mean": mean, "ci95": [mean - half, mean + half], "sd": sd, "n": n}


def derived_metrics(row: dict[str, Any]) -> dict[str, float | None]:
    """Per-run metrics derived from the summary block (NEES per dof, baro parameter errors)."""
    out: dict[str, float | None] = {}
    nm, nd = row.get("nees_mean"), row.get("nees_dof")
    out["nees_per_dof"] = nm / nd if nm is not None and nd else None
    baro = row.get("baro") or {}
    for key, name in (("scale", "baro_scale_abs_err"), ("latency_s", "baro_latency_abs_err_s"),
                      ("bias_m", "baro_bias_abs_err_m")):
        p = baro.get(key) or {}
        est, tru = p.get("est"), p.get("truth")
        out[name] = abs(est - tru) if est is not None and tru is not None else None
    for block in ("online", "lag"):  # flattened: online_alt_rmse_m, ...
        b = row.get(block) or {}
        for k in ("alt_rmse_m", "horiz_rmse_m", "heading_rmse_deg", "heading_known_rmse_deg",
                  "heading_known_after_s"):
            out[f"{block}_{k}"] = b.get(k)
        nm, nd = b.get("nees_mean"), b.get("nees_dof")
        out[f"{block}_nees_per_dof"] = nm / nd if nm is not None and nd else None
    return out


# A run row's private field (never written): the causal estimate's errors epoch by epoch
# (``metrics.CausalErrors``), read by ``common_start_blocks``
CAUSAL_ERRORS_KEY = "_causal_errors"


def common_start_blocks(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The rows with ``online_common`` added and ``CAUSAL_ERRORS_KEY`` removed.

    A real-time comparison scores both estimates over their common span, from the later of
    their two first epochs: per (scenario, seed), a row whose causal estimate starts before
    another's (the ekf's starts when it is aligned, graph-isam2's at the drive's start) gets
    ``online_common[<other>]``, its online block (``metrics.causal_metrics``) over its epochs
    from the other's ``from_s``, with that ``from_s``. The later one's common score is its own
    ``online`` block. Rows without a causal estimate get ``online_common: null``."""
    from .metrics import causal_metrics

    return _pairwise(rows, CAUSAL_ERRORS_KEY, "online_common", lambda ce, oe: (
        finite({"from_s": oe.from_s, **causal_metrics(ce, oe.from_s)})
        if oe.from_s > ce.from_s else None))


def _pairwise(rows: list[dict[str, Any]], key: str, out_key: str,
              score: Callable[[Any, Any], dict[str, Any] | None]) -> list[dict[str, Any]]:
    """Per (scenario, seed): each ok row with the private field ``key`` gets ``out_key``, the
    ``score(its value, the other's)`` of every other such row (None: no entry), by estimator;
    the rows without it get ``out_key: null``. ``key`` is removed from every row."""
    groups: dict[tuple[Any, Any], list[dict[str, Any]]] = {}
    for r in rows:
        groups.setdefault((r.get("scenario"), r.get("seed")), []).append(r)
    for group in groups.values():
        have = [(r, r.get(key)) for r in group]
        have = [(r, x) for r, x in have if x is not None and r.get("status") == "ok"]
        for r in group:
            x = r.pop(key, None)
            if x is None or r.get("status") != "ok":
                r[out_key] = None
                continue
            scores = ((o, score(x, ox)) for o, ox in have if o is not r)
            r[out_key] = {str(o["estimator"]): sc for o, sc in scores if sc is not None}
    return rows


# A run row's private field (never written): its heading error and σ_yaw epoch by epoch,
# ``(t, heading_deg, heading_sd_deg)``, read by ``common_heading_blocks``
HEADING_ERRORS_KEY = "_heading_errors"


def common_heading_blocks(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The rows with ``heading_common`` added and ``HEADING_ERRORS_KEY`` removed.

    Heading is compared where both estimators know it: per (scenario, seed), a row with a
    heading error and σ_yaw gets ``heading_common[<other>]`` for every other such row, its
    RMS heading error at the epochs where both report σ_yaw ≤ 5° (``metrics.heading_common``:
    ``{"rmse_deg", "n_epochs", "known_s"}``). Rows without them get ``heading_common: null``."""
    from .metrics import heading_common

    return _pairwise(rows, HEADING_ERRORS_KEY, "heading_common", lambda h, oh: finite(
        heading_common(h[0], h[1], h[2], oh[0], oh[2])))


def aggregate(runs: Sequence[dict[str, Any]]) -> dict[str, dict[str, dict[str, Any]]]:
    """Per scenario × estimator: run counts and ``mean_ci95`` of each metric in
    ``AGG_METRICS`` over the successful runs (failed runs are counted, not averaged)."""
    groups: dict[str, dict[str, list[dict[str, Any]]]] = {}
    for r in runs:
        groups.setdefault(r["scenario"], {}).setdefault(r["estimator"], []).append(r)
    out: dict[str, dict[str, dict[str, Any]]] = {}
    for sc, by_est in groups.items():
        out[sc] = {}
        for est, rows in by_est.items():
            ok = [r | derived_metrics(r) for r in rows if r["status"] == "ok"]
            cell: dict[str, Any] = {"n_runs": len(rows), "n_ok": len(ok),
                                    "n_failed": len(rows) - len(ok)}
            for m in AGG_METRICS:
                cell[m] = mean_ci95(r.get(m) for r in ok)
            dofs = sorted({r["nees_dof"] for r in ok if r.get("nees_dof")})
            cell["nees_dof"] = dofs[0] if len(dofs) == 1 else (dofs or None)
            out[sc][est] = cell
    return out


def _fmt_ci(m: dict[str, Any], spec: str, scale: float = 1.0) -> str:
    if m["mean"] is None:
        return "—"
    s = format(m["mean"] * scale, spec)
    if m["ci95"] is not None:
        lo, hi = m["ci95"]
        s += f" [{format(lo * scale, spec)}, {format(hi * scale, spec)}]"
    return s


def format_bench_md(doc: dict[str, Any]) -> str:
    """Markdown tables of the aggregate (mean [95 % CI] over seeds) and the failures."""
    cfg = doc["config"]
    dur = "scenario default" if cfg["duration_s"] is None else f"{cfg['duration_s']:g} s"
    lines = [
        "# vnav-graph bench", "",
        f"Scenarios {', '.join(cfg['scenarios'])}; seeds {cfg['seeds']}; drive length {dur}; "
        f"executor {cfg['executor']}; wall time {cfg['wall_s']:.1f} s.",
        "Cells: mean [95 % CI over seeds, Student t]. NEES/dof: 1 = consistent. "
        "Baro errors are |estimate − truth|.", "",
    ]
    for sc, by_est in doc["aggregate"].items():
        lines += [f"## {sc}", "",
                  "| estimator | ok/runs | alt RMSE [m] | alt max [m] | horiz RMSE [m] | "
                  "heading RMSE [deg] | vD RMSE [m/s] | "
                  "NEES/dof | scale err [%] | latency err [ms] | bias err [m] | runtime [s] |",
                  "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
        for est, c in by_est.items():
            lines.append(
                f"| {est} | {c['n_ok']}/{c['n_runs']} | {_fmt_ci(c['alt_rmse_m'], '.2f')} | "
                f"{_fmt_ci(c['alt_max_abs_m'], '.2f')} | "
                f"{_fmt_ci(c['horiz_rmse_m'], '.2f')} | "
                f"{_fmt_ci(c['heading_rmse_deg'], '.2f')} | "
                f"{_fmt_ci(c['vel_down_rmse_mps'], '.3f')} | "
                f"{_fmt_ci(c['nees_per_dof'], '.2f')} | "
                f"{_fmt_ci(c['baro_scale_abs_err'], '.3f', 100)} | "
                f"{_fmt_ci(c['baro_latency_abs_err_s'], '.0f', 1000)} | "
                f"{_fmt_ci(c['baro_bias_abs_err_m'], '.2f')} | "
                f"{_fmt_ci(c['runtime_s'], '.2f')} |")
        lines.append("")
        online = {e: c for e, c in by_est.items()
                  if (c.get("online_alt_rmse_m") or {}).get("mean") is not None}
        if online:
            lines += [f"Real time ({sc}): the causal estimates (online blocks, each over its "
                      "own epochs)", "",
                      "| estimator | alt RMSE [m] | horiz RMSE [m] | heading RMSE [deg] | "
                      "heading where σ_yaw ≤ 5° [deg] | σ_yaw ≤ 5° from [s] | NEES/dof |",
                      "| --- | --- | --- | --- | --- | --- | --- |"]
            lines += [f"| {e} | {_fmt_ci(c['online_alt_rmse_m'], '.2f')} | "
                      f"{_fmt_ci(c['online_horiz_rmse_m'], '.2f')} | "
                      f"{_fmt_ci(c['online_heading_rmse_deg'], '.2f')} | "
                      f"{_fmt_ci(c['online_heading_known_rmse_deg'], '.2f')} | "
                      f"{_fmt_ci(c['online_heading_known_after_s'], '.1f')} | "
                      f"{_fmt_ci(c['online_nees_per_dof'], '.2f')} |"
                      for e, c in online.items()]
            lines.append("")
    for status, title, what in (("failed", "Failed runs", "error"),
                                ("skipped", "Skipped runs (a stream the drive lacks)", "reason")):
        rows = [r for r in doc["runs"] if (r["status"] == "skipped") == (status == "skipped")
                and r["status"] != "ok"]
        if rows:
            lines += [f"## {title}", "", f"| scenario | seed | estimator | {what} |",
                      "| --- | --- | --- | --- |"]
            lines += [f"| {r['scenario']} | {r['seed']} | {r['estimator']} | "
                      f"{str(r['error']).replace('|', '/')} |" for r in rows]
            lines.append("")
    return "\n".join(lines)


def write_bench(doc: dict[str, Any], out_dir: str | Path) -> list[Path]:
    """Write ``bench.json`` and ``bench.md`` into ``out_dir`` (each written to a temporary
    file and renamed, so an interrupted run never leaves a half-written file)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for name, text in (("bench.json", json.dumps(doc, indent=1, allow_nan=False) + "\n"),
                       ("bench.md", format_bench_md(doc))):
        fd, tmp = tempfile.mkstemp(prefix=f".{name}.", dir=out)
        with os.fdopen(fd, "w") as fh:
            fh.write(text)
        os.replace(tmp, out / name)
        written.append(out / name)
    return written


def failure_summary(doc: dict[str, Any]) -> str | None:
    """One line naming the failed runs, or None when every run succeeded or was skipped (the
    drive lacks a stream the estimator needs)."""
    failed = [r for r in doc["runs"] if r["status"] not in ("ok", "skipped")]
    if not failed:
        return None
    first = failed[0]
    by_est = sorted({r["estimator"] for r in failed})
    return (f"{len(failed)} of {len(doc['runs'])} runs failed ({', '.join(by_est)}); first: "
            f"{first['estimator']} on {first['scenario']} seed {first['seed']}: {first['error']}")


__all__ = ["AGG_METRICS", "BENCH_SCHEMA", "aggregate", "common_heading_blocks",
           "derived_metrics", "failure_summary",
           "finite", "format_bench_md", "mean_ci95", "shorten_scenario", "write_bench"]
