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
from .jit import CompileTimer, Prewarm, mark_warm
from .progress import Mode, mode_for, say, steps
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
def interrupt_flag() -> Iterator[list[int]]:
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
        print("vnav-graph: interrupt: stopping after the current estimator "
              "(Ctrl-C again to stop at once)", file=sys.stderr, flush=True)

    old = signal.signal(signal.SIGINT, handler)
    try:
        yield flag
    finally:
        signal.signal(signal.SIGINT, old)


def run_one(name: str, drive: Drive, config: Any = None, waited_s: float = 0.0) -> RunResult:
    """Run one estimator; its failure is returned as data, never raised (except interrupts).

    ``waited_s``: time already spent waiting for this estimator's kernels to be compiled by
    another process (counted in ``jit_s``).
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
            msg = str(exc).splitlines()[0] if str(exc) else ""
            est, err = None, f"{type(exc).__name__}: {msg}"
        if interrupted:
            raise KeyboardInterrupt
    wall = time.perf_counter() - t0
    jit_s = jit.seconds + waited_s
    if est is None:
        return RunResult(name, None, err, max(wall - jit.seconds, 0.0), jit_s)
    runtime = est.runtime_s if est.runtime_s > 0 else wall
    est = est.replace(runtime_s=max(runtime - jit.seconds, 0.0))
    return RunResult(name, est, None, est.runtime_s, jit_s)


def run_estimators(drive: Drive, names: Sequence[str], progress: bool | Mode = True,
                   configs: Mapping[str, Any] | None = None,
                   desc: str = "estimators") -> list[RunResult]:
    """Run each named estimator on ``drive``; failures are captured, not raised.

    ``progress``: a ``vnav_graph.progress`` mode, or a bool (True: bar on a terminal, a line
    per estimator otherwise). ``configs`` maps estimator names to their config objects.
    On a machine where the kernels are not compiled yet, a second process compiles the later
    estimator families meanwhile (``vnav_graph.jit.Prewarm``).
    """
    mode = progress if isinstance(progress, str) else mode_for(bool(progress))
    configs = configs or {}
    pre = Prewarm.start(list(names))
    if pre is not None:
        say(f"first run on this machine: compiling kernels (cached for later runs; "
            f"{', '.join(pre.families)} in a second process)", mode)
    results = []
    try:
        for name in steps(names, desc, mode):
            waited = pre.wait(name) if pre is not None else 0.0
            results.append(run_one(name, drive, configs.get(name), waited))
    finally:
        if pre is not None:
            pre.close()
    mark_warm([r.name for r in results if r.estimate is not None])
    return results


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
        "vel_down_rmse_mps": None, "nees_mean": None, "nees_dof": None, "runtime_s": runtime_s,
        "realtime_factor": None, "gnss_rejected": None, "warnings": [],
        "baro": {"scale": dict(null_param), "latency_s": dict(null_param),
                 "bias_m": dict(null_param)},
    }


def summarize(drive: Drive, results: Sequence[RunResult]) -> dict[str, Any]:
    """The ``summary.json`` document (docs/design.md schema)."""
    ests: dict[str, Any] = {}
    for r in results:
        if r.estimate is None:
            ests[r.name] = failed_block(r.error or "unknown error", r.runtime_s)
            continue
        try:
            ests[r.name] = evaluate(r.estimate, drive)
        except Exception as exc:
            ests[r.name] = failed_block(f"evaluation: {type(exc).__name__}: {exc}", r.runtime_s)
    for r in results:  # compile time, apart from runtime_s (first run on a machine only)
        ests[r.name]["jit_s"] = round(r.jit_s, 3)
    head: dict[str, Any] = {"name": drive.name, "source": drive.source,
                            "duration_s": drive.duration_s}
    if drive.meta.get("warnings"):  # additive: what the input checks found (io.sanity)
        head["warnings"] = [str(w) for w in drive.meta["warnings"]]
    return {"schema": SUMMARY_SCHEMA, "drive": head, "estimators": ests}


def apply_holdout(summary: dict[str, Any], holdout_doc: dict[str, Any]) -> dict[str, Any]:
    """For a real log (no truth): fill the error metrics from a GNSS-outage holdout run.

    docs/design.md: "With a real log the error metrics are against withheld GNSS". The trajectories
    written by ``run`` use all GNSS; ``alt_rmse_m``/``alt_max_abs_m`` come from a second run of
    each estimator with GNSS withheld in windows (``vnav_graph.evaluation.holdout``), and the
    summary says so in ``evaluation``. ``vel_down_rmse_mps`` and NEES stay null (no reference).
    """
    out = json.loads(json.dumps(summary))
    for name, block in out["estimators"].items():
        h = holdout_doc["estimators"].get(name)
        if h is None or block["status"] != "ok":
            continue
        if h["status"] != "ok":
            block["holdout_error"] = h.get("error")
            continue
        block["alt_rmse_m"] = h["alt_rmse_m"]
        block["alt_max_abs_m"] = h["alt_max_abs_m"]
        block["horiz_rmse_m"] = h.get("horiz_rmse_m")
        for k in ("vel_down_rmse_mps", "nees_mean", "nees_dof"):
            block[k] = None
    out["evaluation"] = {
        "basis": "withheld GNSS (holdout)",
        "outage_s": holdout_doc["outage_s"],
        "windows": holdout_doc["windows"],
        "scoring": holdout_doc["scoring"],
        "onboard": holdout_doc.get("onboard"),
    }
    return out


def score_holdout(summary: dict[str, Any], drive: Drive, names: Sequence[str],
                  progress: bool | Mode = False, configs: Mapping[str, Any] | None = None
                  ) -> dict[str, Any]:
    """The optional holdout scoring of ``run`` (:func:`apply_holdout`), which never sinks the
    run: when the log cannot be scored (GNSS span too short for one outage window, too few
    fixes) the summary keeps its results and says why in ``evaluation.skipped``."""
    from .evaluation.holdout import run_holdout

    try:
        doc = run_holdout(drive, list(names), progress=progress, configs=configs).doc
    except ValueError as exc:
        out = dict(summary)
        out["evaluation"] = {"basis": None, "skipped": str(exc).splitlines()[0]}
        return out
    return apply_holdout(summary, doc)


EXIT_SOME_FAILED = 3
EXIT_ALL_FAILED = 4


def run_status(summary: dict[str, Any]) -> tuple[int, str | None]:
    """Exit code of ``run`` from its summary, and the one line to print on stderr.

    0: every estimator ok; 3 (``EXIT_SOME_FAILED``): some failed, results written;
    4 (``EXIT_ALL_FAILED``): none produced a scored result (every estimator failed in its
    run or in evaluation), summary written for diagnosis.
    """
    ests = summary["estimators"]
    failed = [n for n, b in ests.items() if b["status"] != "ok"]
    if not failed:
        return 0, None
    first = str(ests[failed[0]].get("error") or "").splitlines()
    detail = f"{failed[0]}: {first[0] if first else 'unknown error'}"
    if len(failed) == len(ests):
        return EXIT_ALL_FAILED, f"every estimator failed ({detail})"
    return EXIT_SOME_FAILED, f"{len(failed)} of {len(ests)} estimators failed ({detail})"


def _fmt(v: Any, spec: str) -> str:
    return "—" if v is None else format(v, spec)


def format_table(summary: dict[str, Any]) -> str:
    """Plain-text comparison table of a summary."""
    head = (f"{'estimator':<15}{'status':>7}{'alt RMSE':>10}{'alt max':>9}{'vD RMSE':>9}"
            f"{'NEES':>8}{'scale %':>16}{'latency ms':>16}{'bias m':>15}{'run s':>8}{'x RT':>8}")
    lines = [f"drive {summary['drive']['name']} ({summary['drive']['source']}, "
             f"{summary['drive']['duration_s']:.0f} s)", head, "-" * len(head)]

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
        lines.append(
            f"{name:<15}{m['status']:>7}{_fmt(m['alt_rmse_m'], '.2f'):>10}"
            f"{_fmt(m['alt_max_abs_m'], '.2f'):>9}{_fmt(m['vel_down_rmse_mps'], '.3f'):>9}"
            f"{_fmt(nees, '.2f'):>8}{pe(b['scale'], 100, '.3f'):>16}"
            f"{pe(b['latency_s'], 1000, '.0f'):>16}{pe(b['bias_m'], 1, '.2f'):>15}"
            f"{m['runtime_s']:>8.2f}{_fmt(m['realtime_factor'], '.0f'):>8}"
        )
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
        ob = ev.get("onboard")
        if ob:
            lines.append(f"onboard estimate {ob['name']}: alt RMSE {ob['alt_rmse_m']:.2f} m, "
                         f"max {ob['alt_max_abs_m']:.2f} m ({ob['note']})")
    else:
        lines.append("NEES column: mean NEES per degree of freedom (1.0 = consistent)")
    jit = sum(m.get("jit_s") or 0.0 for m in summary["estimators"].values())
    if jit > 0.05:
        lines.append(f"numba compiled kernels for {jit:.1f} s (first run on this machine; "
                     "not in 'run s', and cached for later runs)")
    for w in summary["drive"].get("warnings") or []:
        lines.append(f"input warning: {w}")
    for name, m in summary["estimators"].items():
        if m["status"] == "failed":
            lines.append(f"{name} failed: {m['error']}")
        for w in m.get("warnings") or []:
            lines.append(f"{name} warning: {w}")
    return "\n".join(lines)


def estimate_table(est: Estimate, origin_lla: Any = None) -> Any:
    """The Parquet/CSV table of one estimate: ``Estimate.to_dataframe`` (its docstring lists
    the columns and units); ``origin_lla`` adds the tangent-plane position columns."""
    return est.to_dataframe(origin_lla)


# files a run owns in its output directory (removed when a later run does not write them again)
RUN_OUTPUTS = ("summary.json", "summary.txt", "report.html", "estimates/*.parquet",
               "plots/*.png")


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
