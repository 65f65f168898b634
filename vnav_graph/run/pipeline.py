"""The main job: estimators run on one drive (``vnav_graph.run.runner``) are evaluated into
``summary.json``, its table and the per-estimator Parquet files.

A failed estimator is reported with ``status: failed`` and its error (docs/design.md,
``runner.failed_block``). ``RunResult``, ``run_estimators`` and the other runner names are
importable from here too.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from ..evaluation.metrics import causal_view, evaluate
from ..io.jsonout import dumps_strict
from ..types import Drive, Estimate
from ..util.failures import failure_message
from .outputs import ONLINE_SUFFIX
from .progress import Mode
from .runner import (
    RunResult,
    failed_block,
    interrupt_flag,
    resolve_estimators,
    run_captured,
    run_estimators,
    run_holdout,
    run_one,
)

__all__ = ["EXIT_ALL_FAILED", "EXIT_SOME_FAILED", "ONLINE_SUFFIX", "SUMMARY_SCHEMA",
           "RunResult", "apply_holdout", "estimate_table", "failed_block", "format_table",
           "interrupt_flag", "online_table", "reader_repairs", "resolve_estimators",
           "run_captured", "run_estimators", "run_one", "run_status", "score_holdout",
           "summarize", "write_outputs"]

SUMMARY_SCHEMA = "vnav_graph.summary/1"


def reader_repairs(meta: Any) -> list[str]:
    """What the log reader repaired, dropped or noted (``Drive.meta``), one string each.

    Reads the reader's ``notes`` (sentences such as "CLOCK REPAIRED: the boot clock advanced
    0.92315 s per GPS second ..."), ``repaired`` and ``dropped`` (stream → reason → count) and
    ``gaps`` (stream → [[start_s, length_s], ...]). Empty for a simulated drive.

    Each fact is said once: a repair that a note already describes ("CLOCK REPAIRED: ..."
    for the stream ``clock``) and a repair or drop that the input checks already list among
    ``meta["warnings"]`` (the ``input warning:`` lines) are left out.
    """
    notes = [str(n) for n in meta.get("notes") or []]
    said = " ".join(str(w) for w in meta.get("warnings") or [])
    out = list(notes)
    for kind in ("repaired", "dropped"):
        for stream, reasons in (meta.get(kind) or {}).items():
            if kind == "repaired" and any(n.startswith(f"{stream.upper()} REPAIRED")
                                          for n in notes):
                continue
            for reason, count in reasons.items():
                if reason in said:
                    continue
                out.append(f"{stream}: {kind} {count}: {reason}")
    for stream, gaps in (meta.get("gaps") or {}).items():
        if gaps:
            t0, length = max(gaps, key=lambda g: g[1])
            out.append(f"{stream}: {len(gaps)} logging gap(s), longest {length:.1f} s "
                       f"at t = {t0:.1f} s")
    return out


def summarize(drive: Drive, results: Sequence[RunResult]) -> dict[str, Any]:
    """The ``summary.json`` document (docs/design.md schema).

    Additions to the docs/design.md schema: ``version`` (of vnav_graph), ``scenario`` and
    ``seed`` (null for a log), ``repairs`` (``reader_repairs``), ``horiz_rmse_m`` per
    estimator, and ``comparison`` (the headline and its per-block RMS values:
    ``vnav_graph.evaluation.compare``; against truth over time blocks of this run, or null
    until ``apply_holdout`` scores a real log).
    """
    from .. import __version__
    from ..evaluation.compare import (
        BLOCK_MIN_S,
        MIN_BLOCKS_TO_RANK,
        comparison,
        rankings,
        time_blocks,
    )

    blocks = None
    if drive.truth is not None:
        blocks = time_blocks(float(drive.truth.t[0]), float(drive.truth.t[-1]))
    ests: dict[str, Any] = {}
    per_block: dict[str, list[dict[str, Any]]] = {}
    for r in results:
        if r.estimate is None:
            ests[r.name] = failed_block(r.error or "unknown error", r.runtime_s, r.status)
            continue
        try:
            ests[r.name] = evaluate(r.estimate, drive, blocks)
            per_block[r.name] = ests[r.name].pop("per_block", [])
        except Exception as exc:
            ests[r.name] = failed_block(f"evaluation: {type(exc).__name__}: {exc}", r.runtime_s)
    for r in results:  # compile time, apart from runtime_s (first run on a machine only)
        ests[r.name]["jit_s"] = round(r.jit_s, 3)
    comp = None
    if blocks is not None:
        need_s = MIN_BLOCKS_TO_RANK * BLOCK_MIN_S
        ref = drive.meta.get("reference")
        enough = len(blocks) >= MIN_BLOCKS_TO_RANK
        if ref:  # a log scored against a reference file (``run --truth``)
            comp = comparison(
                ests, per_block, f"the reference {ref['file']}", blocks, "time block",
                f"Against the reference {ref['file']}: the CI is over {len(blocks)} "
                "consecutive time blocks of this drive (batch means; blocks are not "
                "independent drives)." if enough
                else f"Against the reference {ref['file']}, split into {len(blocks)} time "
                f"blocks of about {BLOCK_MIN_S:g} s.",
                remedy=f"a drive of at least {need_s:g} s gives {MIN_BLOCKS_TO_RANK} time "
                       "blocks")
        else:
            comp = comparison(
                ests, per_block, "truth", blocks, "time block",
                f"One simulated run: the CI is over {len(blocks)} consecutive time blocks of "
                "this run (batch means; blocks are not independent runs). For an interval "
                "over runs use `vnav-graph bench` with several seeds." if enough
                else f"One simulated run, split into {len(blocks)} time blocks of about "
                f"{BLOCK_MIN_S:g} s. For an interval over runs use `vnav-graph bench` with "
                "several seeds.",
                remedy=f"a drive of at least {need_s:g} s (--duration {need_s:g}) gives "
                       f"{MIN_BLOCKS_TO_RANK} time blocks")
    meta = drive.meta
    head: dict[str, Any] = {"name": drive.name, "source": drive.source,
                            "duration_s": drive.duration_s}
    if meta.get("warnings"):  # additive: what the input checks found (io.sanity)
        head["warnings"] = [str(w) for w in meta["warnings"]]
    out = {
        "schema": SUMMARY_SCHEMA,
        "version": __version__,
        "drive": head,
        "scenario": meta.get("scenario") if drive.source == "simulated" else None,
        "seed": meta.get("seed") if drive.source == "simulated" else None,
        "repairs": reader_repairs(meta),
        "estimators": ests,
        "comparison": comp,
        # the real-time and offline rankings (vnav_graph.evaluation.compare.rankings)
        "rankings": rankings(ests),
    }
    if meta.get("reference"):  # additive: errors against a reference file (run --truth)
        out["reference"] = {**meta["reference"],
                            "basis": f"against the reference {meta['reference']['file']}"}
    return out


def apply_holdout(summary: dict[str, Any], holdout_doc: dict[str, Any]) -> dict[str, Any]:
    """For a real log (no truth): fill the error metrics from a GNSS-outage holdout run.

    docs/design.md: "With a real log the error metrics are against withheld GNSS". The
    trajectories written by ``run`` use all GNSS; ``alt_rmse_m``/``alt_max_abs_m``/
    ``horiz_rmse_m``/``vel_down_rmse_mps`` come from a second run of each estimator with GNSS
    withheld in windows (``vnav_graph.evaluation.holdout``), and the summary says so in
    ``evaluation``; a holdout run that fails its self-check (``holdout.check_run``: an
    answer more than 1 km from the withheld fixes, or diverged from the given ones) marks the
    estimator ``"diverged"``, its errors kept, not ranked (``holdout_error``;
    ``holdout_self_check`` is its check and its flags join ``warnings``); ``comparison`` is
    recomputed over the windows (its ``per_block`` = the holdout ``per_window``). NEES stays
    null (no reference for the full state).
    """
    from ..evaluation.compare import MIN_BLOCKS_TO_RANK, comparison, rankings
    from ..evaluation.selfcheck import DIVERGED

    out = json.loads(json.dumps(summary))
    per_block: dict[str, list[dict[str, Any]]] = {}
    for name, block in out["estimators"].items():
        h = holdout_doc["estimators"].get(name)
        if h is None or block["status"] not in ("ok", "diverged"):
            continue
        for k in ("alt_rmse_m", "alt_max_abs_m", "horiz_rmse_m", "vel_down_rmse_mps",
                  "nees_mean", "nees_dof"):
            block[k] = None
        # the causal and fixed-lag estimates, scored on the same withheld fixes
        block["online"], block["lag"] = h.get("online"), h.get("lag")
        block["holdout_self_check"] = h.get("self_check")
        block["warnings"] = [*block.get("warnings", []),
                             *(f"holdout run: {w}" for w in (h.get("self_check") or {}).get(
                                 "flags", []))]
        scored = ("alt_rmse_m", "alt_max_abs_m", "horiz_rmse_m", "vel_down_rmse_mps")
        if h["status"] != "ok":
            block["holdout_error"] = h.get("error")
            if h["status"] == DIVERGED:  # its errors stay in the row, never ranked
                for k in scored:
                    block[k] = h.get(k)
                if block["status"] == "ok":
                    block["status"], block["error"] = DIVERGED, f"holdout run: {h.get('error')}"
            continue
        for k in scored:
            block[k] = h.get(k)
        per_block[name] = h.get("per_window") or []
    windows = holdout_doc["windows"]
    out["evaluation"] = {
        "basis": "withheld GNSS (holdout)",
        "outage_s": holdout_doc["outage_s"],
        "windows": windows,
        "scoring": holdout_doc["scoring"],
        "gnss_sd_v_median_m": holdout_doc.get("gnss_sd_v_median_m"),
        "onboard": holdout_doc.get("onboard"),
        # additive: the sentence saying a shorter outage was chosen (``auto_outage``)
        "outage_chosen": holdout_doc.get("outage_chosen"),
    }
    out["comparison"] = comparison(
        out["estimators"], per_block, "withheld GNSS (holdout)",
        [(w["t0"], w["t1"]) for w in windows], "holdout window",
        f"Scored against GNSS withheld in {len(windows)} windows of "
        f"{holdout_doc['outage_s']:g} s (a second run of each estimator without those fixes"
        + (f"; {holdout_doc['outage_chosen']}" if holdout_doc.get("outage_chosen") else "")
        + ")" + ("; the CI treats the windows as independent (each is preceded by GNSS)."
                 if len(windows) >= MIN_BLOCKS_TO_RANK else "."),
        remedy=holdout_doc.get("remedy"))
    out["rankings"] = rankings(out["estimators"])
    return out


def score_holdout(summary: dict[str, Any], drive: Drive, names: Sequence[str],
                  progress: bool | Mode = False, configs: Mapping[str, Any] | None = None,
                  outage_s: float | None = None, spacing_s: float | None = None
                  ) -> tuple[dict[str, Any], Any]:
    """The optional holdout scoring of ``run`` (:func:`apply_holdout`), which never sinks the
    run: when the log cannot be scored (GNSS span too short for one outage window, too few
    fixes) the summary keeps its results and says why in ``evaluation.skipped``. ``outage_s``
    and ``spacing_s``: the windows (``run --outage / --spacing``, as ``holdout``'s); without
    ``outage_s``, 60 s, or a shorter outage where 60 s gives fewer than 4 windows and a
    shorter one gives 4 (``holdout.auto_outage``, said in ``evaluation.outage_chosen`` and
    the headline's note).

    Returns the summary and the ``HoldoutResult`` (None when skipped), whose error series the
    report draws."""
    from ..evaluation.holdout import auto_outage

    chosen = None
    if outage_s is None and drive.gnss is not None and len(drive.gnss) >= 2:
        outage_s, chosen = auto_outage(drive.gnss.t, spacing_s)
    try:
        res = run_holdout(drive, list(names), outage_s or 60.0, spacing_s,
                          progress=progress, configs=configs)
    except ValueError as exc:
        out = dict(summary)
        out["evaluation"] = {"basis": None, "skipped": failure_message(exc)}
        return out, None
    if chosen:
        res.doc["outage_chosen"] = chosen
    return apply_holdout(summary, res.doc), res


EXIT_SOME_FAILED = 3
EXIT_ALL_FAILED = 4


def run_status(summary: dict[str, Any]) -> tuple[int, str | None]:
    """Exit code of ``run`` from its summary, and the one line to print on stderr.

    0: every estimator that could run is ok (estimators ``skipped`` for a stream the drive
    lacks are named on the stderr line, not counted as failures); 3 (``EXIT_SOME_FAILED``):
    some failed, results written; 4 (``EXIT_ALL_FAILED``): none produced a scored result
    (every estimator failed in its run or in evaluation, or none could run), summary written
    for diagnosis.
    """
    ests = summary["estimators"]

    def first(names: list[str], default: str) -> str:
        lines = str(ests[names[0]].get("error") or "").splitlines()
        return f"{names[0]}: {lines[0] if lines else default}"

    skipped = [n for n, b in ests.items() if b["status"] == "skipped"]
    failed = [n for n, b in ests.items() if b["status"] == "failed"]
    diverged = [n for n, b in ests.items() if b["status"] == "diverged"]
    note = (f"{len(skipped)} of {len(ests)} estimators skipped ({first(skipped, 'skipped')})"
            if skipped else None)
    if not failed and not diverged:
        if skipped and len(skipped) == len(ests):
            return EXIT_ALL_FAILED, f"no estimator could run on this drive ({first(skipped, '')})"
        return 0, note
    parts = [f"{len(names)} of {len(ests)} estimators {what} ({first(names, 'unknown error')})"
             for what, names in (("failed", failed), ("diverged", diverged)) if names]
    if len(failed) + len(skipped) == len(ests):
        return EXIT_ALL_FAILED, f"every estimator failed ({first(failed, 'unknown error')})"
    if len(failed) + len(diverged) + len(skipped) == len(ests):
        return EXIT_ALL_FAILED, ("no estimator produced a trustworthy result: "
                                 + "; ".join(parts))
    return EXIT_SOME_FAILED, "; ".join(parts)


def _fmt(v: Any, spec: str) -> str:
    return "—" if v is None else format(v, spec)


# (header with unit, width) of the terminal table; every header carries its unit
TABLE_COLUMNS = (("estimator", 15), ("status", 7), ("alt RMSE m", 11), ("alt max m", 10),
                 ("horiz RMSE m", 13), ("vD RMSE m/s", 12), ("NEES/dof", 9),
                 ("scale %", 16), ("latency ms", 12), ("bias m", 13), ("run s", 8),
                 ("x RT", 7))


def format_table(summary: dict[str, Any]) -> str:
    """Plain-text comparison table of a summary: headline, table with units, notes."""
    from ..evaluation.compare import headline_lines, ranking_lines

    def row(cells: Sequence[str]) -> str:
        return "".join(f"{c:<{w}}" if k == 0 else f"{c:>{w}}"
                       for k, (c, (_, w)) in enumerate(zip(cells, TABLE_COLUMNS, strict=True)))

    head = row([h for h, _ in TABLE_COLUMNS])
    d = summary["drive"]
    origin = (f"scenario {summary['scenario']}, seed {summary['seed']}"
              if summary.get("scenario") is not None else d["source"])
    lines = [f"drive {d['name']} ({origin}, {d['duration_s']:.0f} s), "
             f"vnav_graph {summary.get('version', '?')}"]
    lines += [f"HEADLINE {h}" for h in headline_lines(summary)]
    lines += ranking_lines(summary)
    lines += [head, "-" * len(head)]

    def pe(p: dict[str, Any], scale: float, spec: str) -> str:
        if p["est"] is None:
            return "—"
        s = format(p["est"] * scale, spec)
        if p["sd"] is not None:
            s += "±" + format(p["sd"] * scale, spec)
        return s

    from ..estimators.base import family_order

    for name in family_order(list(summary["estimators"])):  # the report's row order
        m = summary["estimators"][name]
        b = m["baro"]
        nees = m["nees_mean"] / m["nees_dof"] if m.get("nees_dof") else None
        lines.append(row([
            name, m["status"], _fmt(m["alt_rmse_m"], ".2f"), _fmt(m["alt_max_abs_m"], ".2f"),
            _fmt(m.get("horiz_rmse_m"), ".2f"), _fmt(m["vel_down_rmse_mps"], ".3f"),
            _fmt(nees, ".2f"), pe(b["scale"], 100, ".3f"), pe(b["latency_s"], 1000, ".0f"),
            pe(b["bias_m"], 1, ".2f"), _fmt(m["runtime_s"], ".2f"),
            _fmt(m["realtime_factor"], ".0f")]))
    ev = summary.get("evaluation")
    ob = ev.get("onboard") if ev else None
    if ob:
        lines.append(row(["onboard*", "ok", _fmt(ob["alt_rmse_m"], ".2f"),
                          _fmt(ob["alt_max_abs_m"], ".2f")] + ["—"] * 8))
        lines.append(f"* onboard = the autopilot's own estimate {ob['name']}: {ob['note']}")
    truth = next(iter(summary["estimators"].values()), {}).get("baro") if summary[
        "estimators"] else None
    if truth and truth["scale"]["truth"] is not None:
        lines.append(
            f"truth: scale {truth['scale']['truth'] * 100:.3f} %, latency "
            f"{truth['latency_s']['truth'] * 1000:.0f} ms, "
            f"mean bias {truth['bias_m']['truth']:.2f} m"
        )
    ev = summary.get("evaluation")
    if summary.get("reference"):
        ref = summary["reference"]
        lines.append(f"errors against the reference {ref['file']} ({ref['epochs']} epochs; "
                     f"{ref['time']}; heights {ref['height']}; lever arm: {ref['lever_arm']});"
                     " NEES/dof: mean NEES per degree of freedom (1.0 = consistent)")
    elif ev and ev.get("skipped"):
        lines.append(f"holdout scoring skipped: {ev['skipped']} (errors are null)")
    elif ev:
        lines.append(f"errors against {ev['basis']}: {len(ev['windows'])} windows of "
                     f"{ev['outage_s']:.0f} s")
    elif summary["drive"]["source"] != "simulated":
        lines.append("errors: none (a log without truth; scores need the holdout run)")
    else:
        lines.append("errors against truth; NEES/dof: mean NEES per degree of freedom "
                     "(1.0 = consistent)")
    lines.append("run s: the estimator's wall time; x RT: drive duration / run s (how many "
                 "times faster than real time)")
    jit = sum(m.get("jit_s") or 0.0 for m in summary["estimators"].values())
    if jit > 0.05:
        lines.append(f"numba compiled kernels for {jit:.1f} s (first run on this machine; "
                     "not in 'run s', and cached for later runs)")
    for w in summary["drive"].get("warnings") or []:
        lines.append(f"input warning: {w}")
    for r in summary.get("repairs") or []:
        lines.append(f"reader: {r}")
    for name, m in summary["estimators"].items():
        if m["status"] in ("failed", "skipped"):
            lines.append(f"{name} {m['status']}: {m['error']}")
        elif m["status"] == "diverged":
            lines.append(f"{name} DIVERGED (kept in the outputs, not ranked): {m['error']}")
        for w in m.get("warnings") or []:
            lines.append(f"{name} warning: {w}")
    return "\n".join(lines)


def estimate_table(est: Estimate, origin_lla: Any = None) -> Any:
    """The Parquet/CSV table of one estimate: ``Estimate.to_dataframe`` (its docstring lists
    the columns and units); ``origin_lla`` adds the tangent-plane position columns."""
    return est.to_dataframe(origin_lla)


def online_table(est: Estimate, origin_lla: Any = None) -> Any:
    """The table of ``est``'s online answer (``estimates/<name>.online.parquet``), or None
    when it has none to score (``metrics.causal_view``: the pure smoothers' forward pass is
    another estimator's row).

    The layout of ``estimate_table``, one row per online epoch (``est.online.t``), the sigmas
    from ``est.online_cov`` (absent without it). The baro scale and latency columns are left
    out: ``Estimate.baro`` is calibrated over the whole drive, not known at an online epoch.
    """
    online = causal_view(est, "online")
    return None if online is None else online.to_dataframe(origin_lla)


# files a run owns in its output directory (removed when a later run does not write them again)
RUN_OUTPUTS = ("summary.json", "summary.txt", "report.html", "estimates/*.parquet",
               "plots/*.png", "drive.json", "truth.parquet", "export/*")


def write_outputs(
    out_dir: Path, summary: dict[str, Any], results: Sequence[RunResult], drive: Drive,
    extra_writers: Sequence[Any] = (),
) -> list[Path]:
    """Write summary.json, the table and per-estimator Parquet files into ``out_dir``:
    ``estimates/<name>.parquet`` (``estimate_table``, the final answer) and, for an estimator
    with a causal estimate, ``estimates/<name>.online.parquet`` (``online_table``).

    Written through ``vnav_graph.run.outputs.publish``: an interrupted run leaves no half-written
    file under a final name, and results of an earlier run in the same directory that this run
    did not produce again (e.g. another estimator's Parquet) are removed.
    """

    from .outputs import publish

    def fill(tmp: Path) -> None:
        (tmp / "summary.json").write_text(dumps_strict(summary) + "\n")
        (tmp / "summary.txt").write_text(format_table(summary) + "\n")
        (tmp / "estimates").mkdir()
        for r in results:
            if r.estimate is not None:
                estimate_table(r.estimate, drive.origin_lla).to_parquet(
                    tmp / "estimates" / f"{r.name}.parquet", index=False)
                online = online_table(r.estimate, drive.origin_lla)
                if online is not None:
                    online.to_parquet(tmp / "estimates" / f"{r.name}{ONLINE_SUFFIX}.parquet",
                                      index=False)
        for w in extra_writers:
            w(tmp, summary, results, drive)

    return publish(out_dir, fill, RUN_OUTPUTS)
