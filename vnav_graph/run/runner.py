"""The one place that creates, runs, times and catches estimators.

``run`` (``run_estimators``), the GNSS-outage holdout (``run_holdout``), the bench's workers,
local or on Dask (``vnav_graph.run.bench.run_task``), all call :func:`run_one`:

- the estimator name is checked against the registry once (:func:`resolve_estimators`);
- ``create(name, config).run(drive)`` runs with Python warnings captured into the estimate's
  ``info["warnings"]`` (:func:`run_captured`);
- ``runtime_s`` excludes ``jit_s``, the time numba spent compiling kernels (first run on a
  machine only: the compiled code is cached);
- a sensor left out or a re-solve without it (the magnetometer, the baro scale) is a warning
  and an entry of ``fallbacks`` (:func:`flag_sensor_fallbacks`);
- an estimator that raises is returned as data, ``error`` = ``failure_message(exc, typed=True)``
  (never empty), and the others still run (docs/design.md);
- a malformed graph extension (``failures.ExtensionError``) is bad input and propagates (the
  CLI's one-line error, exit 2);
- an estimator that needs a stream the drive lacks (``failures.MissingStream``) is returned
  as skipped, ``error`` = the reason (``"no barometer"``): not a failure;
- the first Ctrl-C stops after the current estimator (:func:`interrupt_flag`).

A failed (or skipped) estimator's block in ``summary.json``, ``holdout.json`` and
``bench.json`` is :func:`failed_block`: every metric null, ``status`` and ``error`` set.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
import time
import traceback
import warnings
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager, nullcontext
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..estimators.base import available, create, with_online
from ..estimators.vertical.ahrs_cache import Shared, sharing
from ..evaluation.blocks import fb_separation_block
from ..evaluation.holdout import (
    HoldoutResult,
    Scored,
    baro_block,
    causal_score,
    check_run,
    choose_windows,
    holdout_doc,
    in_windows,
    score,
    withhold,
)
from ..evaluation.metrics import METRIC_KEYS
from ..evaluation.screening import screen_reference
from ..types import Drive, Estimate
from ..util.failures import ExtensionError, MissingStream, failure_message
from ..util.jit import CompileTimer, Prewarm, family_of, mark_warm
from .progress import Mode, mode_for, say, steps


@dataclass(frozen=True)
class RunResult:
    """Outcome of one estimator on one drive: an Estimate, or the error that stopped it.

    ``runtime_s`` excludes ``jit_s``, the time numba spent compiling kernels during this run
    (non-zero only the first time a kernel meets this machine: the compiled code is cached).
    ``skipped``: the estimator could not run on this drive (a stream it needs is missing);
    ``error`` is then the reason, e.g. ``"no barometer"``.
    """

    name: str
    estimate: Estimate | None
    error: str | None
    runtime_s: float
    jit_s: float = 0.0
    skipped: bool = False

    @property
    def status(self) -> str:
        """``"ok"``, ``"skipped"`` or ``"failed"`` (the ``status`` of its JSON block)."""
        if self.estimate is not None:
            return "ok"
        return "skipped" if self.skipped else "failed"


def resolve_estimators(names: Sequence[str] | None) -> list[str]:
    """Validate estimator names (ValueError on an unknown one); None or empty means all
    available (ValueError when the registry is empty)."""
    avail = available()
    if not avail:
        raise ValueError("no estimators available in this build")
    if not names:
        return avail
    unknown = [n for n in names if n not in avail]
    if unknown:
        from ..util.suggest import did_you_mean

        raise ValueError(f"unknown estimator(s) {', '.join(unknown)}"
                         f"{did_you_mean(unknown[0], avail)} (available: {', '.join(avail)})")
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
            shared: Shared | None = None, interrupts: bool = True) -> RunResult:
    """Run one estimator; its failure is returned as data, never raised (except interrupts).

    ``waited_s``: time already spent waiting for this estimator's kernels to be compiled by
    another process (counted in ``jit_s``). ``shared``: the run's ``sharing`` block; the
    seconds of the shared results this estimator reused are added to its ``runtime_s``.
    ``interrupts=False`` leaves SIGINT to the caller (the bench handles it per task).
    """
    t0 = time.perf_counter()
    flag = interrupt_flag() if interrupts else nullcontext([])
    skipped = False
    with flag as interrupted, CompileTimer() as jit:
        try:
            est = run_captured(name, drive, config)
            err = None
        except MissingStream as exc:  # the drive cannot feed this estimator: not a failure
            est, err, skipped = None, exc.reason, True
        except ExtensionError:  # a malformed user extension is bad input: the run stops
            raise
        except Exception as exc:  # an estimator failure is data, not a crash
            if interrupted:
                raise KeyboardInterrupt from exc
            if os.environ.get("VNAV_DEBUG"):
                traceback.print_exc()
            est, err = None, failure_message(exc, typed=True)
        if interrupted:
            raise KeyboardInterrupt
    wall = time.perf_counter() - t0
    jit_s = jit.seconds + waited_s
    reused = shared.take() if shared is not None else 0.0
    if est is None:
        return RunResult(name, None, err, max(wall - jit.seconds, 0.0) + reused, jit_s,
                         skipped)
    runtime = est.runtime_s if est.runtime_s > 0 else wall
    # the drive's origin travels with the estimate (``Estimate.to_dataframe()``'s NED columns)
    est = est.replace(runtime_s=max(runtime - jit.seconds, 0.0) + reused,
                      origin_lla=drive.origin_lla)
    return RunResult(name, est, None, est.runtime_s, jit_s)


def run_estimators(drive: Drive, names: Sequence[str], progress: bool | Mode = True,
                   configs: Mapping[str, Any] | None = None,
                   desc: str = "estimators", prewarm: Any = "auto") -> list[RunResult]:
    """Run each named estimator on ``drive``; failures are captured, not raised.

    ``progress``: a ``vnav_graph.run.progress`` mode, or a bool (True: bar on a terminal, a line
    per estimator otherwise). ``configs`` maps estimator names to their config objects.
    On a machine where the kernels are not compiled yet, a second process compiles the later
    estimator families meanwhile (``vnav_graph.util.jit.Prewarm``): ``prewarm="auto"`` starts one
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
        with sharing() as shared:  # the vertical filters' AHRS once (vertical.ahrs_cache)
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
    line per distinct message with its count, instead of reaching the terminal unexplained.
    A causal estimator's ``online`` estimate is filled in here (``base.with_online``)."""
    with warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        est = flag_sensor_fallbacks(with_online(name, create(name, config).run(drive)))
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


# ``info`` notes of a sensor left out or a re-solve without (or with less of) a sensor: the
# magnetometer not used (``sensors.magnetometer``: its field strength varies beyond the
# hard-iron model, or its hard iron contradicted the prior and the estimator solved again
# without it), the baro scale held at 0 after an implausible one (``sensors.baro``) and the
# GNSS velocity σ raised above the receiver's (``sensors.gnss_consistency``)
SENSOR_FALLBACK_NOTES = ("mag_note", "baro_scale_note", "gnss_vel_note")


def flag_sensor_fallbacks(est: Estimate) -> Estimate:
    """Every sensor fallback of ``est`` (``SENSOR_FALLBACK_NOTES``) as a warning and an entry
    of ``info["fallbacks"]`` (``summary.json`` and bench rows), each once. A ``mag_note``
    that only says the drive has no date (the field's year assumed) is not a fallback."""
    notes = [str(est.info[k]) for k in SENSOR_FALLBACK_NOTES if est.info.get(k)]
    notes = [n for n in notes if not n.startswith("drive has no date")]
    if not notes:
        return est
    warned = [str(w) for w in est.info.get("warnings") or []]
    fell = [str(f) for f in est.info.get("fallbacks") or []]
    info = dict(est.info)
    info["warnings"] = warned + [n for n in notes if n not in warned]
    info["fallbacks"] = fell + [n for n in notes if n not in fell]
    return est.replace(info=info)


def failed_block(error: str, runtime_s: float, status: str = "failed",
                 **extra: Any) -> dict[str, Any]:
    """The block of an estimator without a result: ``status`` (``"failed"``, or ``"skipped"``
    when the drive lacks a stream it needs), ``error`` (the error, or the reason it was
    skipped), every metric of the ``summary.json`` block null; ``extra`` adds
    document-specific keys (the holdout's ``alt_offset_m``, ``n_scored``, ``per_window``)."""
    null_param = {"est": None, "sd": None, "truth": None}
    return {
        "status": status, "error": error, **dict.fromkeys(METRIC_KEYS), "runtime_s": runtime_s,
        "realtime_factor": None, "gnss_rejected": None, "gnss_forced": None, "zupt_intervals": None,
        "warnings": [],
        "fallbacks": [],
        "solver": None, "isam2_final": None, "extensions": None, "self_check": None,
        "online": None, "lag": None,
        "fb_separation": None, "gnss_gm_auto": None, "real_time_pass": None,
        "baro": {"scale": dict(null_param), "latency_s": dict(null_param),
                 "bias_m": dict(null_param)},
        **extra,
    }


def holdout_failed(error: str, runtime_s: float, status: str = "failed") -> dict[str, Any]:
    """``failed_block`` with the holdout's own keys."""
    return failed_block(error, runtime_s, status, alt_offset_m=None, n_scored=0,
                        per_window=[])


def run_holdout(drive: Drive, estimators: Sequence[str] | None = None, outage_s: float = 60.0,
                spacing_s: float | None = None, progress: bool | Mode = False,
                configs: Mapping[str, Any] | None = None) -> HoldoutResult:
    """Withhold GNSS in windows, run the estimators, score them
    (``vnav_graph.evaluation.holdout``: windows, scoring, document).

    An estimator that raises is reported ``status: failed`` with its error; the others still
    run. ``progress``: a ``vnav_graph.run.progress`` mode or a bool; ``configs``: estimator
    configs by name.
    """
    if drive.gnss is None or len(drive.gnss) < 10:
        raise ValueError("holdout needs a drive with GNSS (fewer than 10 fixes)")
    names = resolve_estimators(estimators)
    windows = choose_windows(drive.gnss.t, outage_s, spacing_s)
    withheld = in_windows(drive.gnss.t, windows)
    reference, screen = screen_reference(drive, withheld)
    held = withhold(drive, windows)
    results: dict[str, dict[str, Any]] = {}
    series: dict[str, Scored] = {}
    tracks: dict[str, Any] = {}
    for r in run_estimators(held, names, progress, configs, desc="holdout run"):
        if r.estimate is None:
            results[r.name] = holdout_failed(r.error or "unknown error", r.runtime_s, r.status)
            continue
        try:
            s = score(r.estimate, drive, reference, windows, given=~withheld)
            info = r.estimate.info or {}
            s.block["warnings"] = [str(x) for x in info.get("warnings") or []]
            s.block["fallbacks"] = [str(x) for x in info.get("fallbacks") or []]
            # graph-isam2: whose answer the trajectory is, "isam2" or "batch" (null elsewhere)
            s.block["isam2_final"] = info.get("isam2_final")
            # of those, the baro calibration's prior conflicts (sensors.baro): data, not solver
            s.block["baro_prior_conflict"] = [str(x) for x in
                                              info.get("baro_prior_conflict") or []]
            s.block["baro"] = baro_block(r.estimate)
            s.block["online"] = causal_score(r.estimate, drive, reference, "online",
                                             given=~withheld)
            s.block["lag"] = causal_score(r.estimate, drive, reference, "lag", given=~withheld)
            s.block["fb_separation"] = fb_separation_block(info.get("fb_separation"))
            # gnss_gm_auto: the residual autocorrelations and the decision (null without it)
            s.block["gnss_gm_auto"] = info.get("gnss_gm_auto")
            s.block["real_time_pass"] = info.get("real_time_pass")
            if drive.truth is not None:  # holdout --truth: the windows against the reference
                from ..evaluation.reference_score import reference_block

                s.block["reference"] = reference_block(r.estimate, drive, windows)
            check_run(s, r.estimate, held, drive, reference, ~withheld)
            results[r.name], series[r.name] = s.block, s
            if "pos_h" in r.estimate.provides:
                tracks[r.name] = r.estimate.trajectory
        except Exception as exc:  # one estimator's failure is data, not a crash
            if os.environ.get("VNAV_DEBUG"):
                traceback.print_exc()
            results[r.name] = holdout_failed(failure_message(exc, typed=True), r.runtime_s)
    doc = holdout_doc(drive, windows, withheld, reference, screen, outage_s, results)
    if drive.meta.get("reference"):  # additive: what the ``reference`` blocks are against
        ref = drive.meta["reference"]
        doc["reference"] = {**ref, "basis": f"against the reference {ref['file']}"}
    return HoldoutResult(doc, windows, series, tracks)
