"""The main job: run estimators on one drive, evaluate, write ``summary.json`` and tables.

``run_estimators`` never lets one estimator's failure stop the others: a failed estimator is
reported with ``status: failed`` and its error (docs/design.md).
"""

from __future__ import annotations

import json
import os
import signal
import sys
import threading
import time
import traceback
import warnings
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from .estimators.base import available, create
from .evaluation.metrics import evaluate
from .io.jsonout import dumps_strict
from .jit import CompileTimer, Prewarm, family_of, mark_warm
from .progress import Mode, mode_for, say, steps
from .sharing import Shared, sharing
from .types import Drive, Estimate

SUMMARY_SCHEMA = "vnav_graph.summary/1"


@dataclass(frozen=True)
class RunResult:
    """Outcome of one estimator on one drive: an Estimate, or the error that stopped it.

    ``runtime_s`` excludes ``jit_s``, the time numba spent compiling kernels during this run
    (non-zero only the first time a kernel meets this machine: the compiled code is cached).
    """

    name: str
    estimate: Estimate | None
    error: str | None
    runtime_s: float
    jit_s: float = 0.0


def resolve_estimators(names: Sequence[str] | None) -> list[str]:
    """Validate estimator names (ValueError on an unknown one); None means all available."""
    avail = available()
    if not names:
        return avail
    unknown = [n for n in names if n not in avail]
    if unknown:
        raise ValueError(f"unknown estimator(s) {', '.join(unknown)} "
                         f"(available: {', '.join(avail)})")
    return list(names)


@contextmanager
def interrupt_flag(what: str = "estimator") -> Iterator[list[int]]:
    """Record SIGINT while an estimator runs; the caller stops after it (``run_one``).

    Raising ``KeyboardInterrupt`` from the handler while a numba kernel runs is not safe: it
    surfaced as a ``SystemError`` that passed for an estimator failure (the run then exited 0),
    and sometimes as a segmentation fault. So the first Ctrl-C only sets the flag and says
    so; a second one raises at once. Outside the main thread there is no handler.
    """
    flag: list[int] = []
    if threading.current_thread() is not threading.main_thread():
        yield flag
        return

    def handler(signum: int, frame: Any) -> None:
        if flag:
            raise KeyboardInterrupt
        flag.append(signum)
        print(f"vnav-graph: interrupt: stopping after the current {what} "
              "(Ctrl-C again to stop at once)", file=sys.stderr, flush=True)

    old = signal.signal(signal.SIGINT, handler)
    try:
        yield flag
    finally:
        signal.signal(signal.SIGINT, old)


def run_one(name: str, drive: Drive, config: Any = None, waited_s: float = 0.0,
            shared: Shared | None = None) -> RunResult:
    """Run one estimator; its failure is returned as data, never raised (except interrupts).

    ``waited_s``: time already spent waiting for this estimator's kernels to be compiled by
    another process (counted in ``jit_s``). ``shared``: the run's ``sharing`` block; the
    seconds of the shared results this estimator reused are added to its ``runtime_s``.
    """
    t0 = time.perf_counter()
    with interrupt_flag() as interrupted, CompileTimer() as jit:
        try:
            est = run_captured(name, drive, config)
            err = None
        except Exception as exc:  # an estimator failure is data, not a crash
            if interrupted:
                raise KeyboardInterrupt from exc
            if os.environ.get("VNAV_DEBUG"):
                traceback.print_exc()
            msg = next((ln.strip() for ln in str(exc).splitlines() if ln.strip()), "no message")
            est, err = None, f"{type(exc).__name__}: {msg}"
        if interrupted:
            raise KeyboardInterrupt
    wall = time.perf_counter() - t0
    jit_s = jit.seconds + waited_s
    reused = shared.take() if shared is not None else 0.0
    if est is None:
        return RunResult(name, None, err, max(wall - jit.seconds, 0.0) + reused, jit_s)
    runtime = est.runtime_s if est.runtime_s > 0 else wall
    est = est.replace(runtime_s=max(runtime - jit.seconds, 0.0) + reused)
    return RunResult(name, est, None, est.runtime_s, jit_s)


def run_estimators(drive: Drive, names: Sequence[str], progress: bool | Mode = True,
                   configs: Mapping[str, Any] | None = None,
                   desc: str = "estimators", prewarm: Any = "auto") -> list[RunResult]:
    """Run each named estimator on ``drive``; failures are captured, not raised.

    ``progress``: a ``vnav_graph.progress`` mode, or a bool (True: bar on a terminal, a line
    per estimator otherwise). ``configs`` maps estimator names to their config objects.
    On a machine where the kernels are not compiled yet, a second process compiles the later
    estimator families meanwhile (``vnav_graph.jit.Prewarm``): ``prewarm="auto"`` starts one
    here, or pass one started earlier (``cli.cmd_run`` starts it before reading the drive) or
    None. It is closed here.
    """
    mode = progress if isinstance(progress, str) else mode_for(bool(progress))
    configs = configs or {}
    pre = Prewarm.start(list(names)) if prewarm == "auto" else prewarm
    if pre is not None:
        say(f"first run on this machine: compiling kernels (cached for later runs; "
            f"{', '.join(pre.families)} in a second process)", mode)
    order = list(range(len(names)))
    if pre is not None:
        # the child's families last: this process compiles and runs everything else first
        # instead of waiting for the child half-way (jit.py: the first run of the default
        # drive); the results keep the requested order
        order = ([i for i, n in enumerate(names) if family_of(n) not in pre.families]
                 + [i for i, n in enumerate(names) if family_of(n) in pre.families])
    results: dict[int, RunResult] = {}
    try:
        with sharing() as shared:  # the vertical filters' AHRS once (vnav_graph.sharing)
            for i in steps(order, desc, mode, label=lambda i: names[i]):
                name = names[i]
                waited = pre.wait(name) if pre is not None else 0.0
                results[i] = run_one(name, drive, configs.get(name), waited, shared)
    finally:
        if pre is not None:
            pre.close()
    out = [results[i] for i in sorted(results)]
    mark_warm([r.name for r in out if r.estimate is not None])
    return out


def run_captured(name: str, drive: Drive, config: Any = None) -> Estimate:
    """``create(name).run(drive)`` with Python warnings (numpy RuntimeWarnings: overflow,
    invalid value, ...) captured and appended to the estimate's ``info["warnings"]`` as one
    line per distinct message with its count, instead of reaching the terminal unexplained."""
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        est = create(name, config).run(drive)
    if not rec:
        return est
    counts: dict[str, int] = {}
    for w in rec:
        where = f" ({Path(w.filename).name}:{w.lineno})" if w.filename else ""
        key = f"{w.category.__name__}: {w.message}{where}"
        counts[key] = counts.get(key, 0) + 1
    lines = [f"{k} x{n}" if n > 1 else k for k, n in counts.items()]
    info = dict(est.info)
    info["warnings"] = [*list(info.get("warnings") or []), *lines]
    return est.replace(info=info)


def failed_block(error: str, runtime_s: float) -> dict[str, Any]:
    null_param = {"est": None, "sd": None, "truth": None}
    return {
        "status": "failed", "error": error, "alt_rmse_m": None, "alt_max_abs_m": None,
        "horiz_rmse_m": None, "heading_rmse_deg": None, "heading_known_rmse_deg": None,
        "heading_known_after_s": None, "outage_alt_max_m": None,
        "outage_horiz_max_m": None, "vel_down_rmse_mps": None, "nees_mean": None,
        "nees_dof": None, "runtime_s": runtime_s,
        "realtime_factor": None, "gnss_rejected": None, "warnings": [],
        "baro": {"scale": dict(null_param), "latency_s": dict(null_param),
                 "bias_m": dict(null_param)},
    }


def reader_repairs(meta: Any) -> list[str]:
    """What the log reader repaired, dropped or noted (``Drive.meta``), one string each.

    Reads the reader's ``notes`` (sentences such as "CLOCK REPAIRED: the boot clock advanced
    0.92315 s per GPS second ..."), ``repaired`` and ``dropped`` (stream → reason → count) and
    ``gaps`` (stream → [[start_s, length_s], ...]). Empty for a simulated drive.
    """
    out = [str(n) for n in meta.get("notes") or []]
    for kind in ("repaired", "dropped"):
        for stream, reasons in (meta.get(kind) or {}).items():
            for reason, count in reasons.items():
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
    from . import __version__
    from .evaluation.compare import comparison, time_blocks

    blocks = None
    if drive.truth is not None:
        blocks = time_blocks(float(drive.truth.t[0]), float(drive.truth.t[-1]))
    ests: dict[str, Any] = {}
    per_block: dict[str, list[dict[str, Any]]] = {}
    for r in results:
        if r.estimate is None:
            ests[r.name] = failed_block(r.error or "unknown error", r.runtime_s)
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
        comp = comparison(
            ests, per_block, "truth", blocks, "time block",
            f"One simulated run: the CI is over {len(blocks)} consecutive time blocks of this "
            "run (batch means; blocks are not independent runs). For an interval over runs "
            "use `vnav-graph bench` with several seeds.")
    meta = drive.meta
    head: dict[str, Any] = {"name": drive.name, "source": drive.source,
                            "duration_s": drive.duration_s}
    if meta.get("warnings"):  # additive: what the input checks found (io.sanity)
        head["warnings"] = [str(w) for w in meta["warnings"]]
    return {
        "schema": SUMMARY_SCHEMA,
        "version": __version__,
        "drive": head,
        "scenario": meta.get("scenario") if drive.source == "simulated" else None,
        "seed": meta.get("seed") if drive.source == "simulated" else None,
        "repairs": reader_repairs(meta),
        "estimators": ests,
        "comparison": comp,
    }


def apply_holdout(summary: dict[str, Any], holdout_doc: dict[str, Any]) -> dict[str, Any]:
    """For a real log (no truth): fill the error metrics from a GNSS-outage holdout run.

    docs/design.md: "With a real log the error metrics are against withheld GNSS". The
    trajectories written by ``run`` use all GNSS; ``alt_rmse_m``/``alt_max_abs_m``/
    ``horiz_rmse_m``/``vel_down_rmse_mps`` come from a second run of each estimator with GNSS
    withheld in windows (``vnav_graph.evaluation.holdout``), and the summary says so in
    ``evaluation``; ``comparison`` is recomputed over the windows (its ``per_block`` = the
    holdout ``per_window``). NEES stays null (no reference for the full state).
    """
    from .evaluation.compare import comparison

    out = json.loads(json.dumps(summary))
    per_block: dict[str, list[dict[str, Any]]] = {}
    for name, block in out["estimators"].items():
        h = holdout_doc["estimators"].get(name)
        if h is None or block["status"] != "ok":
            continue
        for k in ("alt_rmse_m", "alt_max_abs_m", "horiz_rmse_m", "vel_down_rmse_mps",
                  "nees_mean", "nees_dof"):
            block[k] = None
        if h["status"] != "ok":
            block["holdout_error"] = h.get("error")
            continue
        for k in ("alt_rmse_m", "alt_max_abs_m", "horiz_rmse_m", "vel_down_rmse_mps"):
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
    }
    out["comparison"] = comparison(
        out["estimators"], per_block, "withheld GNSS (holdout)",
        [(w["t0"], w["t1"]) for w in windows], "holdout window",
        f"Scored against GNSS withheld in {len(windows)} windows of "
        f"{holdout_doc['outage_s']:g} s (a second run of each estimator without those fixes); "
        "the CI treats the windows as independent (each is preceded by GNSS).")
    return out


def score_holdout(summary: dict[str, Any], drive: Drive, names: Sequence[str],
                  progress: bool | Mode = False, configs: Mapping[str, Any] | None = None
                  ) -> tuple[dict[str, Any], Any]:
    """The optional holdout scoring of ``run`` (:func:`apply_holdout`), which never sinks the
    run: when the log cannot be scored (GNSS span too short for one outage window, too few
    fixes) the summary keeps its results and says why in ``evaluation.skipped``.

    Returns the summary and the ``HoldoutResult`` (None when skipped), whose error series the
    report draws."""
    from .evaluation.holdout import run_holdout

    try:
        res = run_holdout(drive, list(names), progress=progress, configs=configs)
    except ValueError as exc:
        out = dict(summary)
        out["evaluation"] = {"basis": None, "skipped": str(exc).splitlines()[0]}
        return out, None
    return apply_holdout(summary, res.doc), res


EXIT_SOME_FAILED = 3
EXIT_ALL_FAILED = 4


def run_status(summary: dict[str, Any]) -> tuple[int, str | None]:
    """Exit code of ``run`` from its summary, and the one line to print on stderr.

    0: every estimator ok; 3 (``EXIT_SOME_FAILED``): some failed, results written;
    4 (``EXIT_ALL_FAILED``): none produced a scored result (every estimator failed in its
    run or in evaluation), summary written for diagnosis.
    """
    ests = summary["estimators"]
    failed = [n for n, b in ests.items() if b["status"] == "failed"]
    diverged = [n for n, b in ests.items() if b["status"] == "diverged"]
    if not failed and not diverged:
        return 0, None
    parts = []
    for what, names in (("failed", failed), ("diverged", diverged)):
        if names:
            first = str(ests[names[0]].get("error") or "").splitlines()
            parts.append(f"{len(names)} of {len(ests)} estimators {what} ({names[0]}: "
                         f"{first[0] if first else 'unknown error'})")
    if len(failed) == len(ests):
        return EXIT_ALL_FAILED, "every estimator failed" + parts[0][parts[0].index(" ("):]
    if len(failed) + len(diverged) == len(ests):
        return EXIT_ALL_FAILED, "no estimator produced a trustworthy result: " + "; ".join(
            parts)
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
    from .evaluation.compare import headline_lines

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
    lines += [head, "-" * len(head)]

    def pe(p: dict[str, Any], scale: float, spec: str) -> str:
        if p["est"] is None:
            return "—"
        s = format(p["est"] * scale, spec)
        if p["sd"] is not None:
            s += "±" + format(p["sd"] * scale, spec)
        return s

    for name, m in summary["estimators"].items():
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
    if ev and ev.get("skipped"):
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
        if m["status"] == "failed":
            lines.append(f"{name} failed: {m['error']}")
        elif m["status"] == "diverged":
            lines.append(f"{name} DIVERGED (kept in the outputs, not ranked): {m['error']}")
        for w in m.get("warnings") or []:
            lines.append(f"{name} warning: {w}")
    return "\n".join(lines)


def estimate_table(est: Estimate, origin_lla: Any = None) -> Any:
    """The Parquet/CSV table of one estimate: ``Estimate.to_dataframe`` (its docstring lists
    the columns and units); ``origin_lla`` adds the tangent-plane position columns."""
    return est.to_dataframe(origin_lla)


# files a run owns in its output directory (removed when a later run does not write them again)
RUN_OUTPUTS = ("summary.json", "summary.txt", "report.html", "estimates/*.parquet",
               "plots/*.png", "drive.json", "truth.parquet", "export/*")


def write_outputs(
    out_dir: Path, summary: dict[str, Any], results: Sequence[RunResult], drive: Drive,
    extra_writers: Sequence[Any] = (),
) -> list[Path]:
    """Write summary.json, the table and per-estimator Parquet files into ``out_dir``.

    Written through ``vnav_graph.outputs.publish``: an interrupted run leaves no half-written
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
        for w in extra_writers:
            w(tmp, summary, results, drive)

    return publish(out_dir, fill, RUN_OUTPUTS)
