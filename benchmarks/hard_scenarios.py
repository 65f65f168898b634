"""Where a smoother should beat a filter: the EKF-vs-graph study on the hard scenarios.

Usage
-----
The study (Monte Carlo, then the representative-seed plots and the error attribution)::

    python benchmarks/hard_scenarios.py --seeds 20 --out bench-results/hard

``benchmarks/make_results.py --run`` runs it and puts its section in ``docs/results.md``;
``--quick`` runs 3 seeds of shortened drives (a smoke test, not a result).

Writes into ``--out``: ``bench.json`` / ``bench.md`` (the ``vnav-graph bench`` document of
the scenarios below), ``study.json`` (the paired statistics and win-rule verdicts),
``attribution.json`` (attribution and ablation) and ``hard-<scenario>.png``.

What it measures
----------------
- The scenarios: ``cold-start`` (no static alignment, unknown heading), its position-only
  variant, ``urban`` (multipath bursts, correlated GNSS errors, short outages, understated
  receiver σ), ``long-outage`` (MEMS IMU, three 180 s outages) and ``hot-baro`` (0.3 s
  latency, ISA + 15 K, a fast 10 m Gauss-Markov bias); their TOML files give the rationale.
- Both approaches at their best, with one configuration over every scenario
  (``benchmarks/hard_scenarios.toml``): both families with a Huber loss on the GNSS fixes,
  weighted by their residuals against the smoothed answer (the graphs' IRLS, ekf-rts's
  ``post_huber_rounds``), and a gate that removes the fixes the smoothed answer does not fit
  (the graphs' post-solve gate, ekf-rts's post-smoothing gate); ekf-rts carries an
  acquired heading back to the start; both carry the Gauss-Markov GNSS error state where
  the drive's GNSS residuals are correlated (``gnss_gm_auto``: on urban, off on the
  white-error scenarios), and the EKF forces a fix in only after 30 s of refusals
  (``max_rejected_s``).
- Per scenario, its primary metrics (``PRIMARY``); per pair of estimators the paired 95 %
  Student-t interval over seeds of the difference and of the ratio b/a; the goal of the
  study (graph-batch ≥ 20 % better than ekf-rts with the paired CI excluding zero) is checked
  per metric.
- The win rule (``vnav_graph.evaluation.winrule.WIN_RULE``): a paired difference over seeds
  whose 95 % CI excludes zero is a win; each estimator's NEES/dof on the metric's own axes is
  reported beside it; the only veto is a winner whose NEES/dof exceeds 2 and the loser's
  ("bought by overconfidence"); heading is compared where both report σ_yaw ≤ 5°; seeds
  without a metric are named; worst seed and 95th percentile of the error beside the mean.
  The goal needs a counted win.
- Where and why, measured: on the representative seed of each scenario (the seed whose
  paired ekf-rts − graph-batch difference of the first primary metric is the median) both
  estimators are re-run and the difference of their summed squared errors is split over the
  parts of the drive — the first 60 s (alignment), GNSS outages, multipath bursts and the
  rest — and an ablation (``ABLATION``: graph-batch with its GNSS loss off, its post-solve
  gates off, both off; ekf-rts; ekf, i.e. smoothing off) is run on the same drive. The page
  prints these numbers; it carries no explanation written in advance.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parent.parent
if str(REPO) not in sys.path:  # this checkout's package, not another installed one
    sys.path.insert(0, str(REPO))

from vnav_graph.evaluation.winrule import (  # noqa: E402
    NEES_MAX,
    WIN_RULE,
    describe,
    paired_values,
    win_rule,
)

CONFIG = REPO / "benchmarks" / "hard_scenarios.toml"
SCENARIOS = ("cold-start", "cold-start-posonly", "cold-start-phone", "urban", "long-outage",
             "hot-baro")
ESTIMATORS = ("ekf", "ekf-rts", "graph-batch", "graph-isam2")
# scenario → its primary metrics (bench.json run keys; lower is better)
PRIMARY = {
    "cold-start": ("heading_rmse_deg", "horiz_rmse_m"),
    "cold-start-posonly": ("horiz_rmse_m", "heading_rmse_deg"),
    "cold-start-phone": ("baro_latency_abs_err_s", "alt_rmse_m"),
    "urban": ("horiz_rmse_m", "alt_rmse_m"),
    "long-outage": ("outage_alt_max_m", "outage_horiz_max_m"),
    "hot-baro": ("alt_rmse_m", "baro_scale_abs_err", "baro_latency_abs_err_s"),
}
# key → (label, unit, display scale, format)
LABELS = {
    "alt_rmse_m": ("altitude RMSE", "m", 1.0, ".3f"),
    "horiz_rmse_m": ("horizontal RMSE", "m", 1.0, ".2f"),
    "heading_rmse_deg": ("heading RMSE", "deg", 1.0, ".2f"),
    "outage_alt_max_m": ("max |altitude error| in outages", "m", 1.0, ".2f"),
    "outage_horiz_max_m": ("max horizontal error in outages", "m", 1.0, ".1f"),
    "baro_scale_abs_err": ("|baro scale error|", "%", 100.0, ".3f"),
    "baro_latency_abs_err_s": ("|baro latency error|", "ms", 1000.0, ".1f"),
    "nees_per_dof": ("NEES/dof", "", 1.0, ".2f"),
}
# the chain of the study: (a, b) pairs, d = a − b (positive: b better)
CHAIN = (("ekf", "ekf-rts"), ("ekf-rts", "graph-batch"), ("ekf-rts", "graph-isam2"))
GOAL_REL = 0.20
QUICK_SEEDS, QUICK_DURATION_S = 3, 240.0
START_S = 60.0


def paired_stats(xa: np.ndarray, xb: np.ndarray) -> dict[str, Any]:
    """Paired difference d = a − b and relative gain 1 − mean(b)/mean(a) with Student-t and
    (for the ratio) delta-method 95 % intervals (``vnav_graph.evaluation.compare.paired_gain``)."""
    from vnav_graph.evaluation.compare import paired_gain

    return paired_gain(xa, xb)


def study(doc: dict[str, Any]) -> dict[str, Any]:
    """Per scenario × pair × metric: ``paired_stats`` (over the seeds the win rule compares:
    heading at the common known epochs), ``significant``, ``win`` (``win_rule``),
    ``overconfident`` (the win is bought by overconfidence) and the goal verdict."""
    out: dict[str, Any] = {}
    for sc in doc["aggregate"]:
        prim = PRIMARY.get(sc, ("alt_rmse_m",))
        keys = list(prim) + [k for k in ("alt_rmse_m", "horiz_rmse_m", "heading_rmse_deg",
                                         "nees_per_dof") if k not in prim]
        out[sc] = {}
        for a, b in CHAIN:
            if a not in doc["aggregate"][sc] or b not in doc["aggregate"][sc]:
                continue  # an estimator left out of the run (--estimators)
            for key in keys:
                w = win_rule(doc["runs"], sc, a, b, key)
                s = dict(w["stats"])
                s["win"] = w
                s["significant"] = w["winner"] is not None
                s["overconfident"] = w["verdict"] == "bought by overconfidence"
                # the goal is about the graphs against ekf-rts; other pairs are context
                s["goal_met"] = bool(a == "ekf-rts" and key in prim and w["counts"]
                                     and w["winner"] == b and s["gain"] is not None
                                     and s["gain"] >= GOAL_REL)
                out[sc][f"{a}|{b}|{key}"] = s
    return out


# ---------------------------------------------------------------- attribution and plots
def _segments(drive: Any, t: np.ndarray) -> dict[str, np.ndarray]:
    """Boolean masks of the parts of a drive: start, outages, bursts, rest (disjoint, in
    that order of precedence)."""
    used = np.zeros(t.size, dtype=bool)
    out = {}
    start = t < t[0] + START_S
    out["first 60 s"] = start
    used |= start
    for name, key in (("GNSS outages", "gnss_outages"), ("multipath bursts",
                                                         "gnss_burst_windows")):
        m = np.zeros(t.size, dtype=bool)
        for a, b in drive.meta.get(key) or []:
            m |= (t >= a) & (t < b)
        m &= ~used
        out[name] = m
        used |= m
    out["rest"] = ~used
    return out


def attribute(drive: Any, ests: dict[str, Any]) -> dict[str, Any]:
    """Split Σ(e²_ekf-rts − e²_graph-batch) over the parts of the drive, per error kind.

    Both errors are sampled at the graph's output epochs (truth interpolated there), so the
    shares add up to the whole-drive difference of mean squared errors."""
    from vnav_graph.evaluation.metrics import errors_vs_truth

    ea = errors_vs_truth(ests["ekf-rts"], drive)
    eb = errors_vs_truth(ests["graph-batch"], drive)
    t = eb.t
    res: dict[str, Any] = {}
    for kind in ("alt", "horiz", "heading"):
        xa, xb = getattr(ea, kind), getattr(eb, kind)
        if xa is None or xb is None:
            continue
        xa = np.interp(t, ea.t, xa)
        diff = xa**2 - xb**2
        total = float(np.sum(diff))
        parts = {}
        for name, m in _segments(drive, t).items():
            parts[name] = {"share_of_time": float(m.mean()),
                           "share_of_difference": float(np.sum(diff[m]) / total)
                           if total != 0 else None,
                           "rms_ekf_rts": float(np.sqrt(np.mean(xa[m] ** 2))) if m.any()
                           else None,
                           "rms_graph_batch": float(np.sqrt(np.mean(xb[m] ** 2))) if m.any()
                           else None}
        res[kind] = {"mse_difference": total / t.size, "parts": parts}
    return res


def plot(drive: Any, ests: dict[str, Any], path: Path, title: str) -> None:
    """Altitude, horizontal and heading error and the NEES/dof of position and velocity
    against time, outages and bursts shaded."""
    from vnav_graph.evaluation.metrics import errors_vs_truth, nees
    from vnav_graph.report import canvas

    errs = {n: errors_vs_truth(e, drive) for n, e in ests.items()}
    kinds = [k for k in ("alt", "horiz", "heading")
             if all(getattr(e, k) is not None for e in errs.values())]
    ne = {n: nees(e, drive) for n, e in ests.items()}
    panels = kinds + (["nees"] if all(v is not None for v in ne.values()) else [])
    fig = canvas.figure(9.0, 2.2 * len(panels) + 0.6, left=0.09)
    axes = fig.subplots(len(panels), 1, sharex=True)
    axes = np.atleast_1d(axes)
    units = {"alt": "altitude error [m]", "horiz": "horizontal error [m]",
             "heading": "heading error [deg]"}
    for ax in axes:
        for a, b in drive.meta.get("gnss_outages") or []:
            ax.axvspan(a, b, color="0.85", lw=0)
        for a, b in drive.meta.get("gnss_burst_windows") or []:
            ax.axvspan(a, b, color="#f6d8ae", lw=0)
    if "nees" in panels:
        ax = axes[-1]
        for (name, (val, dof)), col in zip(ne.items(), ("C0", "C3"), strict=False):
            t_c = ests[name].t_cov[(ests[name].t_cov >= drive.truth.t[0])
                                   & (ests[name].t_cov <= drive.truth.t[-1])]
            ax.semilogy(t_c, np.maximum(val / dof, 1e-3), color=col, lw=0.8,
                        label=f"{name} (mean {np.mean(val) / dof:.3g})")
        ax.axhline(1.0, color="0.4", lw=0.6, ls="--")
        ax.set_ylabel("NEES/dof")
        ax.grid(alpha=0.3)
        ax.legend(loc="upper right", fontsize=8)
    for ax, kind in zip(axes, kinds, strict=False):
        for (name, e), col in zip(errs.items(), ("C0", "C3"), strict=False):
            s = canvas.decimate(e.t.size, 3000)
            y = getattr(e, kind)
            ax.plot(e.t[s], y[s], color=col, lw=0.8,
                    label=f"{name} (RMS {np.sqrt(np.mean(y**2)):.3g})")
        ax.set_ylabel(units[kind])
        if kind == "heading":
            lim = np.nanpercentile(np.abs(np.concatenate(
                [getattr(e, kind) for e in errs.values()])), 99.5)
            ax.set_ylim(-1.1 * lim - 0.1, 1.1 * lim + 0.1)
        ax.grid(alpha=0.3)
        ax.legend(loc="upper right", fontsize=8)
    axes[0].set_title(title + " — grey: GNSS outages, orange: multipath bursts", fontsize=9)
    axes[-1].set_xlabel("time [s]")
    path.write_bytes(canvas.png(fig))


def representative_seed(doc: dict[str, Any], sc: str) -> int:
    key = PRIMARY.get(sc, ("alt_rmse_m",))[0]
    xa, xb, seeds = paired_values(doc["runs"], sc, "ekf-rts", "graph-batch", key)
    if not seeds:
        return 0
    d = xa - xb
    return seeds[int(np.argsort(d)[len(d) // 2])]


# (label, estimator, GraphConfig / EkfConfig changes) of the ablation on the representative seed
ABLATION = (
    ("graph-batch as configured", "graph-batch", {}),
    ("graph-batch, GNSS loss off", "graph-batch",
     {"loss_gnss_pos": "none", "loss_gnss_vel": "none"}),
    ("graph-batch, post-solve GNSS gates off", "graph-batch", {"gnss_gate_prob": 0.0}),
    ("graph-batch, loss and gates off", "graph-batch",
     {"loss_gnss_pos": "none", "loss_gnss_vel": "none", "gnss_gate_prob": 0.0}),
    ("ekf-rts as configured", "ekf-rts", {}),
    ("ekf (smoothing off)", "ekf", {}),
)


def ablation(drive: Any, configs: dict[str, Any]) -> dict[str, Any]:
    """Each ``ABLATION`` variant run on ``drive`` and scored (``evaluate``): what changes when
    one part is switched off, measured on this drive. Keys: the variant labels; values: the
    metric keys of ``LABELS`` (null where a run failed, with its ``error``)."""
    from dataclasses import replace

    from vnav_graph.estimators.base import create
    from vnav_graph.evaluation.metrics import evaluate
    from vnav_graph.evaluation.montecarlo import derived_metrics
    from vnav_graph.run.runner import run_one

    out: dict[str, Any] = {}
    for label, name, change in ABLATION:
        cfg = configs.get(name) or create(name).config
        r = run_one(name, drive, replace(cfg, **change) if change else cfg, interrupts=False)
        if r.estimate is None:
            out[label] = {"error": r.error, **dict.fromkeys(LABELS)}
            continue
        row = evaluate(r.estimate, drive)
        row |= derived_metrics(row)
        out[label] = {k: row.get(k) for k in LABELS}
    return out


def explain(doc: dict[str, Any], out: Path, configs: dict[str, Any],
            duration_s: float | None) -> dict[str, Any]:
    """On each scenario's representative seed: the error attribution, the ablation and the
    plot."""
    from vnav_graph.estimators.base import create
    from vnav_graph.evaluation.montecarlo import shorten_scenario
    from vnav_graph.simulation.scenario import simulate

    res: dict[str, Any] = {}
    for sc in doc["aggregate"]:
        seed = representative_seed(doc, sc)
        drive = simulate(shorten_scenario(sc, duration_s), seed)
        ests = {}
        for name in ("ekf-rts", "graph-batch"):
            ests[name] = create(name, configs.get(name)).run(drive)
        res[sc] = {"seed": seed, **attribute(drive, ests),
                   "ablation": ablation(drive, configs)}
        plot(drive, ests, out / f"hard-{sc}.png", f"{sc}, seed {seed}")
        print(f"hard_scenarios: {sc} seed {seed}: attribution, ablation and plot written",
              file=sys.stderr)
    return res


# ---------------------------------------------------------------- the page section
def _f(x: float | None, scale: float, spec: str) -> str:
    return "—" if x is None else format(x * scale, spec)


def _ci(iv: list[float] | None, scale: float, spec: str) -> str:
    return "" if iv is None else f" [{format(iv[0] * scale, spec)}, {format(iv[1] * scale, spec)}]"


def _config_text() -> str:
    """The study's configuration as read from ``CONFIG``: each section's keys."""
    import tomllib

    doc = tomllib.loads(CONFIG.read_text())
    parts = [f"{name}: " + ", ".join(f"{k} = {v}" for k, v in keys.items())
             for name, keys in doc.items()]
    return "; ".join(parts) or "every estimator at its defaults"


def _verdict(s: dict[str, Any], a: str, b: str, key: str) -> str:
    """The words of one paired line: the win rule's verdict (``winrule.describe``), and the
    goal where it is met."""
    _, unit, scale, spec = LABELS[key]
    text = describe(s["win"], a, b, unit, scale, spec)
    return text + ("; **goal met**" if s["goal_met"] else "")


def _ablation_lines(sc: str, a_sc: dict[str, Any], prim: tuple[str, ...]) -> list[str]:
    abl = a_sc.get("ablation")
    if not abl:
        return []
    keys = [k for k in (*prim, "horiz_rmse_m", "alt_rmse_m", "heading_rmse_deg")
            if k in LABELS]
    keys = list(dict.fromkeys(keys))
    lines = ["", f"Ablation on seed {a_sc['seed']} (one run per row, the same drive; each row "
             "switches one part off):", "",
             "| variant | " + " | ".join(f"{LABELS[k][0]} [{LABELS[k][1]}]" for k in keys)
             + " |", "| --- | " + " | ".join("---" for _ in keys) + " |"]
    for label, row in abl.items():
        cells = [_f(row.get(k), LABELS[k][2], LABELS[k][3]) for k in keys]
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    return lines


def render_section(results: Path) -> list[str]:
    """The results-page section from ``results/bench.json`` (+ attribution, plots). Every
    statement about why one estimator beats another is a number measured in this run (the
    paired statistics, the attribution over the parts of the drive, the ablation); none is
    written in advance."""
    doc = json.loads((results / "bench.json").read_text())
    st = study(doc)
    attr_path = results / "attribution.json"
    attr = json.loads(attr_path.read_text()) if attr_path.is_file() else {}
    cfg = doc["config"]
    lines = ["## Where a smoother should beat a filter: the hard scenarios", "",
             f"`python benchmarks/hard_scenarios.py --seeds {len(cfg['seeds'])}` — "
             f"{len(cfg['seeds'])} seeds, {len(doc['runs'])} runs, drive length "
             f"{'scenario default' if cfg['duration_s'] is None else cfg['duration_s']}, "
             f"configuration `benchmarks/hard_scenarios.toml` ({_config_text()}; everything "
             "else at its defaults). Goal of the study: a win of graph-batch over ekf-rts "
             f"under the win rule below, at least {GOAL_REL:.0%} (gain = 1 − mean(b)/mean(a), "
             "with a delta-method 95 % CI over the paired seeds), on a scenario's primary metric: "
             "the paired 95 % CI of the difference excludes zero, and the win is not bought "
             "by overconfidence.", "",
             f"**Win rule:** {WIN_RULE.format(n=NEES_MAX)}.", ""]
    for sc, by_est in doc["aggregate"].items():
        prim = PRIMARY.get(sc, ("alt_rmse_m",))
        lines += [f"### `{sc}`", "", "| estimator | ok/runs | " + " | ".join(
            f"{LABELS[k][0]} [{LABELS[k][1]}]" if LABELS[k][1] else LABELS[k][0]
            for k in LABELS) + " | GNSS rejected |",
            "| --- | --- | " + " | ".join("---" for _ in LABELS) + " | --- |"]
        for est, c in by_est.items():
            cells = []
            for k, (_, _, scale, spec) in LABELS.items():
                m = c.get(k) or {}
                cells.append(_f(m.get("mean"), scale, spec) + _ci(m.get("ci95"), scale, spec))
            rej = (c.get("gnss_rejected") or {}).get("mean")
            lines.append(f"| {est} | {c['n_ok']}/{c['n_runs']} | " + " | ".join(cells)
                         + f" | {_f(rej, 1, '.0f')} |")
        lines += ["", "Paired over seeds (d = a − b > 0: b better; gain = 1 − b/a):", ""]
        for a, b in CHAIN:
            parts = []
            for key in prim:
                s = st[sc].get(f"{a}|{b}|{key}")
                if not s or s["n"] == 0:
                    continue
                parts.append(f"  - {LABELS[key][0]}: {_verdict(s, a, b, key)}.")
            if parts:
                lines += [f"- {a} → {b}:", *parts]
        a_sc = attr.get(sc)
        if a_sc:
            lines += ["", f"Where the ekf-rts − graph-batch difference lies (seed "
                      f"{a_sc['seed']}, the median seed on {LABELS[prim[0]][0]}; share of "
                      "the difference of summed squared errors, RMS of each in that part):",
                      "", "| error | part | share of time | share of difference | "
                      "ekf-rts RMS | graph-batch RMS |", "| --- | --- | --- | --- | --- | --- |"]
            for kind, blk in a_sc.items():
                if kind in ("seed", "ablation"):
                    continue
                for part, p in blk["parts"].items():
                    if p["share_of_time"] == 0:
                        continue
                    lines.append(f"| {kind} | {part} | {p['share_of_time']:.0%} | "
                                 f"{_f(p['share_of_difference'], 100, '.0f')} % | "
                                 f"{_f(p['rms_ekf_rts'], 1, '.3g')} | "
                                 f"{_f(p['rms_graph_batch'], 1, '.3g')} |")
            lines += _ablation_lines(sc, a_sc, prim)
        if (results / f"hard-{sc}.png").is_file():
            lines += ["", f"![{sc}: error against time](img/hard-{sc}.png)"]
        lines.append("")
    met = sorted({sc for sc, d in st.items() for k, s in d.items()
                  if k.startswith("ekf-rts|graph-batch|") and s["goal_met"]})
    wins = sorted({f"{sc} ({k.split('|')[2]})" for sc, d in st.items() for k, s in d.items()
                   if k.startswith("ekf-rts|graph-") and (s.get("win") or {}).get("counts")
                   and (s["win"]["winner"] or "").startswith("graph")})
    vetoed = sorted({f"{sc} ({k.split('|')[2]})" for sc, d in st.items()
                     for k, s in d.items() if k.startswith("ekf-rts|graph-")
                     and s["overconfident"] and (s["win"]["winner"] or "").startswith("graph")})
    lines += [f"**Goal** (a win of graph-batch over ekf-rts under the win rule, at least "
              f"{GOAL_REL:.0%}, on a primary metric; wanted on two scenarios): met on "
              f"{len(met)} ({', '.join(met) or 'none'}).", "",
              "**Graph wins over ekf-rts under the win rule** (any size, primary and context "
              "metrics): " + (", ".join(wins) if wins else
                              "none: no difference in the graphs' favour is resolved") + ".",
              *([f"**Graph gains bought by overconfidence** (not counted): "
                 f"{', '.join(vetoed)}.", ""] if vetoed else [""])]
    return lines


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--quick", action="store_true", help="3 seeds of 240 s drives (smoke)")
    ap.add_argument("--scenarios", default=",".join(SCENARIOS))
    ap.add_argument("--estimators", default=",".join(ESTIMATORS),
                    help="a subset of " + ", ".join(ESTIMATORS) + " (the pairs of the study "
                    "that need a missing one are left out)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--no-explain", action="store_true", help="skip plots and attribution")
    ap.add_argument("--explain-only", action="store_true",
                    help="plots, attribution and page section from an existing bench.json")
    ap.add_argument("--out", required=True)
    a = ap.parse_args(argv)
    from vnav_graph.estimators.configfile import load_configs
    from vnav_graph.evaluation.montecarlo import write_bench
    from vnav_graph.run.bench import bench

    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    seeds = QUICK_SEEDS if a.quick else a.seeds
    duration = QUICK_DURATION_S if a.quick else None
    configs = load_configs(CONFIG)
    scenarios = [s for s in a.scenarios.split(",") if s]
    estimators = [e for e in a.estimators.split(",") if e]
    unknown = sorted(set(estimators) - set(ESTIMATORS))
    if unknown or not estimators:
        print(f"hard_scenarios: --estimators: unknown {', '.join(unknown) or '(none given)'} "
              f"(choose from {', '.join(ESTIMATORS)})", file=sys.stderr)
        return 2
    if a.explain_only:
        doc = json.loads((out / "bench.json").read_text())
        duration = doc["config"]["duration_s"]
    else:
        doc = bench(scenarios, estimators, list(range(seeds)), duration_s=duration,
                    workers=a.workers, progress=True, configs=configs)
        write_bench(doc, out)
    (out / "study.json").write_text(json.dumps(study(doc), indent=1) + "\n")
    if not a.no_explain:
        attr = explain(doc, out, configs, duration)
        (out / "attribution.json").write_text(json.dumps(attr, indent=1) + "\n")
    print("\n".join(render_section(out)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
