"""Generate ``docs/results.md`` from benchmark output — never edit that page by hand.

Everything (bench, seed reproductions, graph performance, hard study, online accuracy; 20
seeds unless ``--seeds`` says otherwise; the RTK-referenced recordings against the peer
filter), then the page::

    python benchmarks/make_results.py --run [--quick] [--seeds N] --out bench-results

Only the page, from output that already exists: ``make_results.py bench-results``.

Inputs, from the results directory: ``bench.json`` (``vnav-graph bench``, required),
``reproductions.json``, ``graph_perf.json``, ``hard/`` (``hard_scenarios.py``; its plots go to
``docs/img/``), ``online_accuracy.json``, ``truth_logs.json`` (``truth_logs.py``) and
``provenance.json`` (each step's command, commit and times: ``provenance.py``), each
optional. Every section is stamped with its provenance and JSON (committed under
``docs/results_data/`` when small, else named by sha256).

What the page says is computed, not written: for each pair of approaches that isolates one
effect, the per-seed **paired** differences of each metric give mean(d) and its Student-t
95 % CI, judged by the accuracy win rule (``vnav_graph.evaluation.winrule.WIN_RULE``), stated
on the page. Like for like: the forward ekf against graph-isam2's online estimate (real
time), ekf-rts against graph-batch and graph-isam2's final trajectory (offline), summed up
in one forest plot (``vnav_graph.report.forest``). The page names no mechanism it did not
measure.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import json
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

from vnav_graph.evaluation.gains import real_time_rows
from vnav_graph.evaluation.winrule import NEES_MAX, WIN_RULE, describe, win_rule

REPO = Path(__file__).resolve().parent.parent

# (a, b, what differs between them): pairs that isolate one difference. The page reports the
# measured paired differences only; it names no mechanism it did not measure.
PAIRS = (
    ("ekf", "ekf-rts", "smoothing"),
    ("loop3", "vekf7", "fixed gains vs a 7-state Kalman filter"),
    ("vkf4", "vekf7", "baro scale/latency states"),
    ("vekf7", "ekf", "vertical channel vs full INS"),
)
# like for like: the real-time estimates (online blocks) and the offline trajectories
REAL_TIME_PAIRS = (("ekf", "graph-isam2", "forward ekf vs online graph-isam2"),)
OFFLINE_PAIRS = (("ekf-rts", "graph-batch", "ekf-rts vs graph-batch"),
                 ("ekf-rts", "graph-isam2", "ekf-rts vs final graph-isam2"),
                 ("graph-batch", "graph-isam2", "graph-batch vs final graph-isam2"))
ONLINE_METRICS = (
    ("alt_rmse_m", "altitude RMSE", "m", 1.0, ".3f"),
    ("horiz_rmse_m", "horizontal RMSE", "m", 1.0, ".3f"),
    # the win rule compares heading where both know it (the whole-drive score beside it)
    ("heading_rmse_deg", "heading RMSE", "deg", 1.0, ".2f"),
    ("vel_down_rmse_mps", "vertical-velocity RMSE", "m/s", 1.0, ".4f"),
)
# metric key in bench rows, label, unit, display scale, format
METRICS = (
    ("alt_rmse_m", "altitude RMSE", "m", 1.0, ".3f"),
    ("alt_max_abs_m", "max |altitude error|", "m", 1.0, ".2f"),
    ("vel_down_rmse_mps", "vertical-velocity RMSE", "m/s", 1.0, ".4f"),
    ("baro_scale_abs_err", "|baro scale error|", "%", 100.0, ".3f"),
    ("baro_latency_abs_err_s", "|baro latency error|", "ms", 1000.0, ".1f"),
    ("runtime_s", "runtime", "s", 1.0, ".2f"),
)
# Numbers read from the seed papers (titles in README.md). Where the extracted
# text is ambiguous the note says so.
PAPER = {
    "seed003_steady_sd_m": (1.2, "seed 003: steady altitude deviation 'near 1.2 m'"),
    "seed003_gps_only_sd_m": (2.0, "seed 003: GPS only, var 4 m²"),
    "seed003_settling_s": (50.0, "seed 003: 'around 50 samples' at T = 1 s"),
    "seed001_rmse_m.vekf7": (5.7, "seed 001 §4.1 simulation, Kalman filter (order of the two "
                                  "RMS values as extracted from the text)"),
    "seed001_rmse_m.loop3": (11.3, "seed 001 §4.1 simulation, 3rd-order loop"),
    "seed004_outage_alt_rmse_m": (15.24, "seed 004 §6.2: baro-inertial altitude error at most "
                                         "50 ft (a maximum, not an RMS)"),
}
SEED001_TABLE1 = "dSF −0.35 … −2.52 %, Td −0.035 … +0.080 s, B −10.8 … −28.0 ft (7 flights)"


def _fmt(m: dict[str, Any] | None, scale: float, spec: str) -> str:
    if not m or m.get("mean") is None:
        return "—"
    s = format(m["mean"] * scale, spec)
    if m.get("ci95"):
        lo, hi = m["ci95"]
        s += f" [{format(lo * scale, spec)}, {format(hi * scale, spec)}]"
    return s


def bench_module(name: str) -> Any:
    """``benchmarks/<name>.py`` as a module (the scripts are not a package)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(name, REPO / "benchmarks" / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def hard_module() -> Any:
    """``benchmarks/hard_scenarios.py`` as a module (its win rule and page section)."""
    return bench_module("hard_scenarios")


def provenance_module() -> Any:
    """``benchmarks/provenance.py``: the run records and section stamps."""
    return bench_module("provenance")


def real_time_span(runs: list[dict[str, Any]], scenario: str, a: str, b: str) -> str:
    """The sentence on the span of a real-time pair: each one's first epoch, the common start
    (or that the rows have no ``online_common`` and each is scored over its own epochs), and
    the time from which each one's online σ_yaw stays ≤ 5°; means over the seeds."""
    def rows(name: str, which: list[dict[str, Any]]) -> list[dict[str, Any]]:
        return [r["online"] for r in which if r["scenario"] == scenario and
                r["estimator"] == name and r.get("status") == "ok" and r.get("online")]

    def mean(name: str, key: str, which: list[dict[str, Any]]) -> float | None:
        v = [o[key] for o in rows(name, which) if o.get(key) is not None]
        return sum(v) / len(v) if v else None

    own = {n: mean(n, "from_s", runs) for n in (a, b)}
    starts = {n: mean(n, "from_s", real_time_rows(runs, a, b)) for n in (a, b)}
    text = "mean first epoch: " + ", ".join(f"{n} from {v:.1f} s" for n, v in own.items()
                                             if v is not None)
    if None not in starts.values() and abs(starts[a] - starts[b]) < 0.05:
        text = (f"both over their common span, from the later of their two first epochs "
                f"({text}; both scored from {starts[a]:.1f} s)")
    else:
        text = f"each over its own epochs ({text}; these bench rows have no `online_common`)"

    def known(n: str) -> str:
        if not any("heading_known_after_s" in o for o in rows(n, runs)):
            return f"{n} not recorded"
        v = mean(n, "heading_known_after_s", runs)
        return f"{n} {'never' if v is None else format(v, '.1f') + ' s'}"

    return (f"{text}. Heading known (its own σ_yaw ≤ 5° from then on, mean s after the "
            f"drive's start, over its own epochs): {known(a)}, {known(b)}.")


def comparison_section(doc: dict[str, Any], scenario: str, pairs: Any = PAIRS,
                       runs: list[dict[str, Any]] | None = None,
                       metrics: Any = None) -> list[str]:
    """Per pair, the paired difference of every metric with its verdict (win rule applied);
    ``runs``: the rows to compare (default the bench rows; ``real_time_rows`` for real time)."""
    runs = doc["runs"] if runs is None else runs
    have = {r["estimator"] for r in runs if r["scenario"] == scenario}
    lines = []
    for a, b, effect in pairs:
        if a not in have or b not in have:
            continue
        lines += [f"**{a} → {b} ({effect}).**", ""]
        for key, label, unit, scale, spec in metrics or METRICS:
            w = win_rule(runs, scenario, a, b, key)
            if w["stats"]["n"] == 0:  # neither or only one of them has it: not compared
                continue
            lines.append(f"- {label}: {describe(w, a, b, unit, scale, spec)}.")
        lines.append("")
    return lines


def like_for_like(doc: dict[str, Any], scenario: str) -> list[str]:
    """The two like-for-like sections of a scenario: real time (forward ekf against online
    graph-isam2, from the ``online`` blocks over their common span: ``real_time_rows``) and
    offline (ekf-rts, graph-batch, final graph-isam2)."""
    out = []
    for a, b, effect in REAL_TIME_PAIRS:
        rt = comparison_section(doc, scenario, ((a, b, effect),),
                                real_time_rows(doc["runs"], a, b), ONLINE_METRICS)
        if not rt:
            continue
        out += [f"### Real time: {effect}", "",
                "Each scored by its `online` block (the causal estimate, every epoch from "
                "data up to it; the ekf is online once its alignment has read its data), "
                + real_time_span(doc["runs"], scenario, a, b), ""] + rt
    off = comparison_section(doc, scenario, OFFLINE_PAIRS, None, (*METRICS[:3], *[
        m for m in ONLINE_METRICS if m[0] in ("horiz_rmse_m", "heading_rmse_deg")]))
    if off:
        out += ["### Offline: ekf-rts vs graph-batch vs final graph-isam2", ""] + off
    return out


def online_goal_section(results_dir: Path) -> list[str]:
    """graph-isam2's accuracy goals from ``online_accuracy.json``, when present."""
    p = results_dir / "online_accuracy.json"
    if not p.is_file():
        return []
    mod = bench_module("online_accuracy")
    doc = json.loads(p.read_text())
    cfg = doc["config"]
    return ["## graph-isam2's accuracy goals: online and fixed lag", "",
            f"`python benchmarks/online_accuracy.py --seeds {cfg['seeds']}` (drive length "
            f"{'scenario default' if cfg.get('duration_s') is None else cfg['duration_s']}, "
            f"configuration `{cfg['configuration']}`): online graph-isam2 against the "
            "forward ekf and graph-isam2's fixed-lag estimate against graph-batch, each pair "
            "scored at its common epochs; gain = 1 − mean(b)/mean(a) with its paired 95 % CI.", "",
            *[f"- {line}" for line in mod.goal_lines(doc["goals"])], ""]


def scenario_table(doc: dict[str, Any], scenario: str) -> list[str]:
    agg = doc["aggregate"][scenario]
    lines = ["| estimator | ok/runs | alt RMSE [m] | alt max [m] | vD RMSE [m/s] | NEES/dof | "
             "scale err [%] | latency err [ms] | bias err [m] | runtime [s] |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for est, c in agg.items():
        lines.append(
            f"| {est} | {c['n_ok']}/{c['n_runs']} | {_fmt(c['alt_rmse_m'], 1, '.3f')} | "
            f"{_fmt(c.get('alt_max_abs_m'), 1, '.2f')} | "
            f"{_fmt(c['vel_down_rmse_mps'], 1, '.4f')} | "
            f"{_fmt(c.get('nees_per_dof'), 1, '.2f')} | "
            f"{_fmt(c.get('baro_scale_abs_err'), 100, '.3f')} | "
            f"{_fmt(c.get('baro_latency_abs_err_s'), 1000, '.1f')} | "
            f"{_fmt(c.get('baro_bias_abs_err_m'), 1, '.2f')} | "
            f"{_fmt(c['runtime_s'], 1, '.3f')} |")
    return lines


def best_section(doc: dict[str, Any], scenario: str) -> list[str]:
    """Per metric: the estimator with the lowest mean, and the win rule's verdict against the
    runner-up (d = runner-up − best over the paired seeds)."""
    agg = doc["aggregate"][scenario]
    lines = []
    for key, label, unit, scale, spec in METRICS:
        vals = [(c[key]["mean"], e) for e, c in agg.items()
                if c.get(key) and c[key]["mean"] is not None]
        if len(vals) < 2:
            continue
        vals.sort()
        (m1, e1), (_, e2) = vals[0], vals[1]
        w = win_rule(doc["runs"], scenario, e2, e1, key)
        lines.append(f"- {label}: lowest mean **{e1}** ({format(m1 * scale, spec)} {unit}); "
                     f"against {e2}: {describe(w, e2, e1, unit, scale, spec)}.")
    return lines


def reproductions_section(rep: dict[str, Any]) -> list[str]:
    paper = {**{k: v for k, (v, _) in PAPER.items()}, **rep.get("paper", {})}
    notes = {k: n for k, (_, n) in PAPER.items()}
    lines = ["| quantity | vnav_graph | paper | source |", "| --- | --- | --- | --- |"]
    flat: dict[str, Any] = {}
    for k, v in rep.items():
        if k in ("paper", "seed001_calibration", "config") or isinstance(v, bool | str):
            continue
        if isinstance(v, dict):
            for kk, vv in v.items():
                flat[f"{k}.{kk}"] = vv
        else:
            flat[k] = v
    for k, v in flat.items():
        pv = paper.get(k, paper.get(k.split(".")[0]))
        note = notes.get(k, notes.get(k.split(".")[0], ""))
        vs = "—" if v is None else (f"{v:.3g}" if isinstance(v, float) else str(v))
        ps = "—" if pv is None or isinstance(pv, dict) else f"{pv:.3g}"
        lines.append(f"| `{k}` | {vs} | {ps} | {note} |")
    cal = rep.get("seed001_calibration")
    if cal:
        lines += ["", f"Seed 001 calibration (paper Table 1, real flights: {SEED001_TABLE1}); "
                  "simulated flights, truth vs estimate ± σ:", "",
                  "| flight | dSF truth [%] | dSF est [%] | Td truth [s] | Td est [s] | "
                  "B truth [m] | B est [m] |", "| --- | --- | --- | --- | --- | --- | --- |"]
        for i, c in enumerate(cal, 1):
            def tri(v: Any, sc: float, spec: str) -> tuple[str, str]:
                if not v:
                    return "—", "—"
                t, e, s = (list(v) + [None, None, None])[:3]
                ts = "—" if t is None else format(t * sc, spec)
                es = "—" if e is None else format(e * sc, spec)
                if s is not None and e is not None:
                    es += f" ± {format(s * sc, spec)}"
                return ts, es
            d, t, b = tri(c.get("dSF"), 100, ".3f"), tri(c.get("Td"), 1, ".4f"), tri(
                c.get("B"), 1, ".2f")
            lines.append(f"| {i} | {d[0]} | {d[1]} | {t[0]} | {t[1]} | {b[0]} | {b[1]} |")
    return lines


def perf_section(perf: dict[str, Any]) -> list[str]:
    lines = ["| quantity | value |", "| --- | --- |"]
    for k, v in perf.items():
        if isinstance(v, dict):  # peak_rss_mb_by_stage: stage → MB
            v = ", ".join(f"{name} {x:.0f}" for name, x in v.items())
        lines.append(f"| `{k}` | {v:.4g} |" if isinstance(v, float) else f"| `{k}` | {v} |")
    return lines


def _estimators(doc: dict[str, Any]) -> str:
    return ", ".join(dict.fromkeys(r["estimator"] for r in doc.get("runs", [])))


def forest_section(results_dir: Path, img_dir: Path | None) -> list[str]:
    """The paired gains of the graph over the filter in every scenario of the bench and the
    hard study (``evaluation.gains``), drawn as ``img/results-forest.png`` (``report.forest``)
    when ``img_dir`` is given."""
    from vnav_graph.evaluation.gains import gain_lines, gain_rows
    from vnav_graph.report.forest import forest_png

    rows = []
    for path in (results_dir / "bench.json", results_dir / "hard" / "bench.json"):
        if path.is_file():
            rows += gain_rows(json.loads(path.read_text())["runs"])
    lines = gain_lines(rows)
    if not lines:
        return []
    out = ["## Filter vs graph at a glance", "",
           "Paired gains g = 1 − mean(graph)/mean(filter) over the seeds with their 95 % CI "
           "(delta method), per scenario and metric: real time is the forward ekf against "
           "graph-isam2's online estimate, offline is ekf-rts against graph-batch; filled: a "
           "win the rule counts. The default scenarios come from the bench, the others from "
           "the hard study (its configuration below).", ""]
    png = forest_png(rows, "Filter vs graph: paired gains over seeds")
    if png is not None and img_dir is not None:
        img_dir.mkdir(parents=True, exist_ok=True)
        (img_dir / "results-forest.png").write_bytes(png)
        out += ["![paired gains of the graph over the filter](img/results-forest.png)", ""]
    return out + ["<details><summary>the numbers</summary>", "", *lines, "", "</details>", ""]


def render(results_dir: Path, docs_dir: Path | None = None) -> str:
    """The whole results page from the files in ``results_dir``; with ``docs_dir`` the forest
    figure goes to ``docs_dir/img`` and the small JSON files to ``docs_dir/results_data``."""
    prov = provenance_module()
    data = None if docs_dir is None else docs_dir / "results_data"

    def stamp(step: str, path: Path, name: str, what: str) -> list[str]:
        kept = (prov.keep(path, data, name) if data is not None
                else f"JSON `{path.name}` sha256 `{prov.sha256(path)}`")
        return [prov.stamp(results_dir, step, kept, what), ""]

    bench_path = results_dir / "bench.json"
    if not bench_path.is_file():
        raise ValueError(f"no bench.json in {results_dir} (run `vnav-graph bench --out "
                         f"{results_dir}` or use --run)")
    doc = json.loads(bench_path.read_text())
    if doc.get("schema") != "vnav_graph.run.bench/1":
        raise ValueError(f"{bench_path}: not a vnav_graph.run.bench/1 document")
    cfg = doc["config"]
    dur = "scenario default" if cfg.get("duration_s") is None else f"{cfg['duration_s']:g} s"
    n_fail = sum(r["status"] != "ok" for r in doc["runs"])
    out = [
        "# Results: EKF vs factor graph vs classical baro-inertial estimators", "",
        "<!-- GENERATED FILE: do not edit. Regenerate with one command: -->",
        "<!--   python benchmarks/make_results.py --run --out bench-results -->",
        "Generated by `python benchmarks/make_results.py --run --out bench-results` (runs "
        "the bench, the seed reproductions, the graph performance, the hard study, the "
        "online accuracy study and the real-truth comparison, then writes this page; "
        "`--quick` for the CI-sized version; "
        "each section names its command, commit and JSON).", "",
        f"Generated {_dt.date.today().isoformat()} from vnav_graph "
        f"{cfg.get('vnav_graph_version', '?')}: scenarios {', '.join(cfg['scenarios'])}, "
        f"seeds {cfg['seeds']}, drive length {dur}, {len(doc['runs'])} runs "
        f"({n_fail} failed), executor {cfg.get('executor')}, wall time "
        f"{cfg.get('wall_s', float('nan')):.0f} s. Runtimes are wall times of runs that "
        "shared the machine with each other (and with whatever else ran on it): compare them "
        "within this page only.", "",
        "Cells are mean [95 % CI over seeds, Student t]; errors are against the simulator's "
        "truth; NEES/dof = 1 means the covariance is consistent; baro errors are "
        "|estimate − truth| (bias: time mean of b(t)). Pairwise statements use paired "
        "differences d = a − b over the same seeds (d > 0: b lower). "
        f"**Win rule:** {WIN_RULE.format(n=NEES_MAX)}. The page names no "
        "mechanism it did not measure.", "",
        *stamp("bench", bench_path, "bench.json",
               f"estimators {_estimators(doc)}; scenarios {', '.join(cfg['scenarios'])}; "
               f"seeds {len(cfg['seeds'])}; configuration: every estimator at its defaults"),
        *forest_section(results_dir, None if docs_dir is None else docs_dir / "img"),
    ]
    for sc in doc["aggregate"]:
        out += [f"## Scenario `{sc}`", ""] + scenario_table(doc, sc) + [""]
        best = best_section(doc, sc)
        if best:
            out += ["### Where each approach wins", ""] + best + [""]
        comp = comparison_section(doc, sc)
        if comp:
            out += ["### Effect by effect (paired over seeds)", ""] + comp
        out += like_for_like(doc, sc)
    failed = [r for r in doc["runs"] if r["status"] != "ok"]
    if failed:
        out += ["## Failed runs", "", "| scenario | seed | estimator | error |",
                "| --- | --- | --- | --- |"]
        out += [f"| {r['scenario']} | {r['seed']} | {r['estimator']} | "
                f"{str(r['error']).replace('|', '/')} |" for r in failed] + [""]
    rep = results_dir / "reproductions.json"
    out += ["## Seed-paper reproductions", ""]
    if rep.is_file():
        rep_doc = json.loads(rep.read_text())
        if rep_doc.get("quick"):
            out += ["`python benchmarks/reproduce_seeds.py --quick` (CI-sized: shortened runs).",
                    ""]
        out += stamp("reproductions", rep, "reproductions.json", "the seed papers' cases")
        out += reproductions_section(rep_doc) + [""]
    else:
        out += ["Not generated in this run (`benchmarks/reproduce_seeds.py` output "
                "`reproductions.json` missing).", ""]
    hard = results_dir / "hard"
    if (hard / "bench.json").is_file():
        sec = hard_module().render_section(hard)
        hdoc = json.loads((hard / "bench.json").read_text())
        out += sec[:2] + stamp("hard", hard / "bench.json", "hard_bench.json",
                               f"estimators {_estimators(hdoc)}; seeds "
                               f"{len(hdoc['config']['seeds'])}; configuration "
                               "`benchmarks/hard_scenarios.toml`") + sec[2:]
    oa = online_goal_section(results_dir)
    if oa:
        p = results_dir / "online_accuracy.json"
        out += oa[:2] + stamp("online_accuracy", p, "online_accuracy.json",
                              "estimators ekf, graph-isam2 (online and lag), graph-batch") + oa[2:]
    tl = results_dir / "truth_logs.json"
    if tl.is_file():
        tdoc = json.loads(tl.read_text())
        if tdoc.get("peer"):
            sec = bench_module("truth_logs").render_peer(tdoc["peer"], tdoc["estimators"])
            out += sec[:2] + stamp("truth_logs", tl, "truth_logs.json",
                                   f"estimators {', '.join(tdoc['estimators'])}; the two "
                                   "RTK-referenced recordings; configuration: defaults") + sec[2:]
    perf = results_dir / "graph_perf.json"
    out += ["## Factor-graph performance", ""]
    if perf.is_file():
        perf_doc = json.loads(perf.read_text())
        out += stamp("graph_perf", perf, "graph_perf.json", "graph-batch and graph-isam2")
        dur = perf_doc.get("drive_duration_s")
        if dur is not None:
            out += [f"`python benchmarks/bench_graph.py` on a {dur / 60:.0f}-minute hill-drive"
                    f"{' (`--quick`: the CI-sized drive)' if dur < 3600 else ''}.", ""]
        out += perf_section(perf_doc) + [""]
    else:
        out += ["Not generated in this run (`benchmarks/bench_graph.py` output "
                "`graph_perf.json` missing).", ""]
    return "\n".join(out)


STEPS = ("bench", "hard", "online_accuracy", "reproductions", "graph_perf", "truth_logs")


def run_all(out: Path, quick: bool, seeds: int | None, steps: tuple[str, ...] = STEPS) -> None:
    """Run the bench, the hard study, the online accuracy study, the seed reproductions and
    the graph performance (those of ``steps``), each recorded in ``provenance.json``
    (command, commit, times); a step left out keeps its earlier output in ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    py = sys.executable
    prov = provenance_module()
    n = str(seeds or 20)
    bench = [py, "-m", "vnav_graph", "bench", "--out", str(out)]
    hard = [py, str(REPO / "benchmarks" / "hard_scenarios.py"), "--out", str(out / "hard")]
    oa = [py, str(REPO / "benchmarks" / "online_accuracy.py"), "--out", str(out)]
    cmds = {"bench": bench + (["--quick"] if quick else ["--seeds", n]),
            "hard": hard + (["--quick"] if quick else ["--seeds", n]),
            "online_accuracy": oa + (["--seeds", "2", "--duration", "240"] if quick
                                     else ["--seeds", n])}
    for name, script in (("reproductions", "reproduce_seeds.py"), ("graph_perf", "bench_graph.py")):
        cmds[name] = [py, str(REPO / "benchmarks" / script), *(["--quick"] if quick else []),
                      "--out", str(out)]
    # the real recordings with an RTK reference (the shared data; exit 2 and no section
    # without them)
    cmds["truth_logs"] = [py, str(REPO / "benchmarks" / "truth_logs.py"), "--out", str(out)]
    for name in steps:
        cmd = cmds[name]
        rc = prov.record(out, name, cmd, lambda c=cmd: subprocess.run(c).returncode)
        if name == "bench" and rc not in (0, 1):  # 1: some runs failed, shown on the page
            raise SystemExit(f"make_results: bench failed with exit code {rc}")
        if name != "bench" and rc != 0:
            print(f"make_results: {name} failed; its section is omitted", file=sys.stderr)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("results_dir", nargs="?", help="directory with bench.json (+ others)")
    ap.add_argument("--run", action="store_true", help="run the benchmarks first")
    ap.add_argument("--quick", action="store_true", help="with --run: CI-sized benchmarks")
    ap.add_argument("--seeds", type=int, default=None,
                    help="with --run: seeds of the bench, hard study and online study (20)")
    ap.add_argument("--out", default=None, help="with --run: results directory")
    ap.add_argument("--steps", default=",".join(STEPS),
                    help=f"with --run: the steps to run, of {', '.join(STEPS)} (default all)")
    ap.add_argument("-o", "--output", default=str(REPO / "docs" / "results.md"))
    a = ap.parse_args(argv)
    if a.run:
        if not a.out:
            ap.error("--run needs --out DIR")
        steps = tuple(x.strip() for x in a.steps.split(",") if x.strip())
        bad = [x for x in steps if x not in STEPS]
        if bad:
            ap.error(f"unknown step(s) {', '.join(bad)} (steps: {', '.join(STEPS)})")
        run_all(Path(a.out), a.quick, a.seeds, steps)
        results = Path(a.out)
    elif a.results_dir:
        results = Path(a.results_dir)
    else:
        ap.error("give RESULTS_DIR or --run --out DIR")
    try:
        page = render(results, Path(a.output).parent)
    except ValueError as exc:
        print(f"make_results: error: {exc}", file=sys.stderr)
        return 2
    Path(a.output).parent.mkdir(parents=True, exist_ok=True)
    Path(a.output).write_text(page + "\n", encoding="utf-8")
    img = Path(a.output).parent / "img"
    for png in sorted((results / "hard").glob("hard-*.png")):
        img.mkdir(exist_ok=True)
        shutil.copyfile(png, img / png.name)
    print(f"wrote {a.output}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
