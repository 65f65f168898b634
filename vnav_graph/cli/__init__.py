"""Command-line front end: ``vnav-graph simulate | run | export | bench | holdout | calibrate-baro |
list``.

Thin: parses arguments and calls library functions. Any bad input ends with one line on
stderr and exit code 2 (no traceback, nothing written half-way); ``VNAV_DEBUG=1`` shows
tracebacks for debugging.
"""

from __future__ import annotations

import argparse
import functools
import os
import sys
import time
import traceback
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from .parser import EXIT_BAD_INPUT, build_parser, name_lines


def _load_extensions(args: argparse.Namespace) -> None:
    """Register ``--plugin`` estimators, then read ``--config`` into ``args.configs``."""
    if getattr(args, "plugin", None):
        from ..estimators.base import load_plugin

        for spec in args.plugin:
            load_plugin(spec)
    args.configs = None
    if getattr(args, "config", None):
        from ..estimators.configfile import load_configs

        args.configs = load_configs(args.config)



def cmd_simulate(args: argparse.Namespace) -> int:
    from ..io import save_npz
    from ..simulation import simulate

    over = {} if args.duration is None else {"duration_s": args.duration}
    out = Path(args.output)
    if out.suffix != ".npz":
        raise ValueError(f"output must end in .npz: {out}")
    if not out.parent.exists():
        raise ValueError(f"output directory does not exist: {out.parent}")
    drive = simulate(args.scenario, args.seed, **over)
    save_npz(drive, out)
    print(f"wrote {out} ({drive.name}, {drive.duration_s:.0f} s, {len(drive.imu)} IMU samples)")
    return 0


def cmd_run(args: argparse.Namespace) -> int:
    from ..io.reference import load_scored
    from ..run.outputs import check_out_dir
    from ..run.pipeline import format_table, summarize
    from ..run.progress import mode_for, stage
    from ..run.runner import resolve_estimators, run_estimators
    from ..simulation import simulate
    from ..util.jit import Prewarm

    t_start = time.perf_counter()
    names = resolve_estimators(args.estimators)  # validate before any work
    if args.baseline is not None and args.baseline not in names:
        from ..util.suggest import did_you_mean

        raise ValueError(f"--baseline {args.baseline!r} is not among the estimators run"
                         f"{did_you_mean(args.baseline, names)} ({', '.join(names)})")
    out = check_out_dir(args.out)
    mode = mode_for(not args.no_progress)
    if args.drive is not None and args.scenario is not None:
        raise ValueError("give either a DRIVE or --scenario, not both")
    if args.drive is None and (args.truth or args.map):
        raise ValueError("--truth and --map need a DRIVE (a log or a folder)")
    # first run on a machine: a second process starts compiling kernels while the drive loads
    pre = Prewarm.start(names)
    try:
        if args.drive is not None:
            with stage(f"reading {Path(args.drive).name}", mode):
                drive = load_scored(args.drive, args.map, args.height_datum, args.truth,
                                    args.truth_fix_only)
        else:
            over = {} if args.duration is None else {"duration_s": args.duration}
            scenario = args.scenario or "default"
            with stage(f"simulating scenario {scenario} (seed {args.seed})", mode):
                drive = simulate(scenario, args.seed, **over)
    except BaseException:
        if pre is not None:
            pre.close()
        raise
    configs = getattr(args, "configs", None)  # --config, read by _load_extensions
    _say_hint(drive, names, drive.truth is None and drive.gnss is not None
              and not args.no_holdout, mode)
    results = run_estimators(drive, names, progress=mode, configs=configs, prewarm=pre)
    summary = summarize(drive, results)
    holdout = None  # a real log's holdout run: its errors are what the report draws
    if drive.truth is None and drive.gnss is not None and not args.no_holdout:
        from ..run.pipeline import score_holdout

        ok = [r.name for r in results if r.estimate is not None]
        if ok:
            with stage("scoring against withheld GNSS (holdout run of every estimator)", mode):
                summary, holdout = score_holdout(summary, drive, ok, progress=mode,
                                                 configs=configs, outage_s=args.outage,
                                                 spacing_s=args.spacing)
    if args.baseline is not None:
        from ..evaluation.compare import against_baseline

        summary = against_baseline(summary, args.baseline)
    from ..run.pipeline import write_outputs

    writers = []
    try:
        from ..report import write_report  # plots + HTML (optional module)

        writers.append(functools.partial(write_report, holdout=holdout))
    except ModuleNotFoundError as exc:
        if exc.name != "vnav_graph.report":
            raise
    from ..export import write_run_info

    writers.append(write_run_info)
    with stage(f"writing results, plots and report to {out}", mode):
        write_outputs(out, summary, results, drive, writers)
    if args.export:
        with stage(f"exporting {','.join(args.export)} to {out / 'export'}", mode):
            exported = _export(out, args.export, None)
    print(format_table(summary))
    # the wall time of the whole command (a first run's compile included): what a user waited
    if args.export:
        _print_export(exported)
    print(f"\nwrote {out / 'summary.json'} (run took {time.perf_counter() - t_start:.1f} s)")
    from ..run.pipeline import run_status

    code, line = run_status(summary)
    if line:
        print(f"vnav-graph: {line}", file=sys.stderr)
    return code


def _say_hint(drive: Any, names: list[str], holdout: bool, mode: Any) -> None:
    """The predicted runtime when the run will be long (``runtime_estimate.run_hint``)."""
    from ..run.progress import say
    from ..run.runtime_estimate import run_hint

    hint = run_hint(drive, names, holdout)
    if hint:
        say(f"hint: {hint}", mode)


def _write_gains(doc: dict, out: Path) -> list[str]:
    """The paired gains of the graph over the filter (``evaluation.gains``): appended to
    ``bench.md`` as a section and drawn as ``forest.png`` (``report.forest``) beside
    ``bench.json``, when the runs hold a filter and a graph to compare. Returns the section."""
    from ..evaluation.gains import gain_lines, gain_rows
    from ..report.forest import forest_png

    rows = gain_rows(doc["runs"])
    lines = gain_lines(rows)
    if not lines:
        return []
    png = forest_png(rows, "Filter vs graph: paired gains over seeds")
    section = ["## Filter vs graph: paired gains", "",
               "Gain = 1 − mean(graph)/mean(filter) over the seeds, 95 % CI (delta method), "
               "and the win rule's verdict; real time: ekf vs graph-isam2's online estimate, "
               "offline: ekf-rts vs graph-batch.", "", *lines, ""]
    if png is not None:
        (out / "forest.png").write_bytes(png)
        section += ["![paired gains of the graph over the filter](forest.png)", ""]
    with open(out / "bench.md", "a", encoding="utf-8") as fh:
        fh.write("\n" + "\n".join(section))
    return section


def cmd_bench(args: argparse.Namespace) -> int:
    """``vnav-graph bench``: validate arguments, run, write ``bench.json`` and ``bench.md``.

    Bad arguments raise ValueError (exit 2). Returns 1 when any run failed (after writing the
    files, with a one-line summary on stderr), 130 when interrupted, else 0.
    """
    from ..evaluation import montecarlo as mc
    from ..run.bench import bench
    from ..run.outputs import check_out_dir
    from ..run.progress import mode_for
    from ..run.runner import resolve_estimators
    from ..simulation import list_scenarios

    estimators = resolve_estimators(args.estimators)
    scenarios = list(args.scenarios or (mc.QUICK_SCENARIOS if args.quick
                                        else mc.DEFAULT_SCENARIOS))
    known = list_scenarios()
    bad = [s for s in scenarios if s not in known and not s.endswith(".toml")]
    if bad:
        from ..util.suggest import did_you_mean

        raise ValueError(f"unknown scenario(s) {', '.join(bad)}{did_you_mean(bad[0], known)} "
                         f"(known: {', '.join(known)})")
    n_seeds = args.seeds if args.seeds is not None else (mc.QUICK_SEEDS if args.quick
                                                         else mc.DEFAULT_SEEDS)
    if n_seeds < 1:
        raise ValueError(f"--seeds must be >= 1, got {n_seeds}")
    workers = args.workers if args.workers is not None else mc.DEFAULT_WORKERS
    if workers < 1:
        raise ValueError(f"--workers must be >= 1, got {workers}")
    duration = mc.QUICK_DURATION_S if args.quick else None
    for sc in scenarios:  # parse every scenario before any work
        mc.shorten_scenario(sc, duration)
    out = check_out_dir(args.out)
    doc = bench(scenarios, estimators, list(range(n_seeds)), duration_s=duration,
                workers=workers, dask=args.dask, progress=mode_for(not args.no_progress),
                configs=getattr(args, "configs", None))
    mc.write_bench(doc, out)
    gains = _write_gains(doc, out)
    n_ok = sum(r["status"] == "ok" for r in doc["runs"])
    if doc["config"]["interrupted"]:
        print(f"vnav-graph: interrupted: wrote the {len(doc['runs'])} of "
              f"{doc['config']['runs_planned']} runs that finished to {out / 'bench.json'}",
              file=sys.stderr)
        return 130
    print(mc.format_bench_md(doc))
    print("\n".join(gains))
    print(f"wrote {out / 'bench.json'} and {out / 'bench.md'}: {n_ok}/{len(doc['runs'])} runs "
          f"ok in {doc['config']['wall_s']:.1f} s")
    msg = mc.failure_summary(doc)
    if msg:
        print(f"vnav-graph bench: {msg}", file=sys.stderr)
        return 1
    return 0


def cmd_holdout(args: argparse.Namespace) -> int:
    """``vnav-graph holdout LOG``: writes ``holdout.json``, ``holdout.md`` (also printed) and
    ``holdout.png`` (``vnav_graph.report.error_plots``, grouped like the run report)."""
    from ..evaluation.holdout import format_markdown
    from ..io.jsonout import dumps_strict
    from ..io.reference import load_scored
    from ..report.error_plots import plot_holdout_errors
    from ..run.outputs import check_out_dir, publish
    from ..run.progress import mode_for, stage
    from ..run.runner import resolve_estimators, run_holdout

    out = check_out_dir(args.out)
    mode = mode_for(not args.no_progress)
    with stage(f"reading {Path(args.log).name}", mode):
        drive = load_scored(args.log, args.map, args.height_datum, args.truth,
                            args.truth_fix_only)
    _say_hint(drive, resolve_estimators(args.estimators), False, mode)
    res = run_holdout(drive, args.estimators, args.outage, args.spacing, progress=mode,
                      configs=getattr(args, "configs", None))
    md = format_markdown(res.doc)

    def fill(tmp: Path) -> None:
        (tmp / "holdout.json").write_text(dumps_strict(res.doc))
        (tmp / "holdout.md").write_text(md)
        png = plot_holdout_errors(res)
        if png is not None:
            (tmp / "holdout.png").write_bytes(png.png)

    publish(out, fill)
    print(md, end="")
    return 0


def cmd_calibrate_baro(args: argparse.Namespace) -> int:
    """``vnav-graph calibrate-baro DRIVE``: the least-squares baro calibration's table."""
    from ..estimators.vertical.calibration import calibrate_baro, format_calibration
    from ..io import load_drive

    print(format_calibration(calibrate_baro(load_drive(args.drive))))
    return 0


def _export(out: Path, formats: list[str] | None, estimators: list[str] | None,
            online: bool = False, full_rate: bool = False) -> Any:
    from ..export import FORMATS, export_run

    return export_run(out, formats or FORMATS, estimators, online, full_rate)


def _print_export(res: Any) -> None:
    skipped = res.skipped_line()
    if skipped:
        print(f"export: skipped {skipped}")
    folders = sorted({str(p.parent) for p in res.written})
    print(f"export: wrote {len(res.written)} file(s) to {', '.join(folders) or '(nothing)'}")


def cmd_export(args: argparse.Namespace) -> int:
    _print_export(_export(Path(args.run_dir), args.formats, args.estimators, args.online,
                          args.full_rate))
    return 0


def cmd_list(args: argparse.Namespace) -> int:
    print("\n".join(name_lines("estimators (vnav-graph run --estimators a,b):",
                                "scenarios (vnav-graph run --scenario NAME):")))
    return 0


COMMANDS = {
    "simulate": cmd_simulate,
    "run": cmd_run,
    "export": cmd_export,
    "list": cmd_list,
    "bench": cmd_bench,
    "holdout": cmd_holdout,
    "calibrate-baro": cmd_calibrate_baro,
}


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        _load_extensions(args)
        return COMMANDS[args.command](args)
    except (ValueError, FileNotFoundError, IsADirectoryError, PermissionError) as exc:
        if os.environ.get("VNAV_DEBUG"):
            traceback.print_exc()
        from ..util.failures import failure_message

        print(f"vnav-graph: error: {failure_message(exc)}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("vnav-graph: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # `vnav-graph run | head`: the reader left; results are written
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())  # no second error when Python flushes at exit
        return 141


def entry() -> None:
    """The ``vnav-graph`` command: ``main()``, then leave without the interpreter's teardown.

    After a run, Python's finalisation (freeing gtsam, numba and matplotlib state module by
    module) took 0.9 s warm and 1.7 s cold on the default drive: a fifteenth of a warm run,
    for nothing. Every output is written and closed when ``main`` returns (the prewarm child
    is closed too), so the streams are flushed and the process exits with ``os._exit``.
    ``main()`` itself returns normally, for callers that embed it."""
    rc = main()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (BrokenPipeError, OSError, ValueError):
            pass
    os._exit(rc)


if __name__ == "__main__":
    entry()
