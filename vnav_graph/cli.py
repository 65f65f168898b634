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

EXIT_BAD_INPUT = 2


def _csv_list(s: str) -> list[str]:
    return [x.strip() for x in s.split(",") if x.strip()]


def _positive_float(s: str) -> float:
    v = float(s)
    if not v > 0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {s}")
    return v


def _export_formats(s: str) -> list[str]:
    from .export import parse_formats

    try:
        return parse_formats(s)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _extension_args(p: argparse.ArgumentParser, config: bool = True) -> None:
    """``--plugin`` (and ``--config``): extension estimators and estimator settings."""
    p.add_argument("--plugin", action="append", default=[], metavar="[NAME=]MODULE:CLASS",
                   help="register an extension estimator (repeatable; MODULE may be a .py file)")
    if config:
        p.add_argument("--config", default=None, metavar="FILE.toml",
                       help="estimator settings, one [estimator] table each "
                            "(e.g. [graph-batch] max_iterations = 300)")


def _truth_args(p: argparse.ArgumentParser) -> None:
    """``run``/``holdout``: plain files by a column map, scored against a reference."""
    p.add_argument("--map", default=None, metavar="MAP.toml",
                   help="column map of a folder of plain files (found inside it without)")
    p.add_argument("--height-datum", choices=("msl", "ellipsoid"), default=None,
                   help="height datum of a GNSS or reference file whose header is silent")
    p.add_argument("--truth", default=None, metavar="FILE",
                   help="score against this reference trajectory (RTKLIB .pos or NMEA)")
    p.add_argument("--truth-fix-only", action="store_true", help="score at Q = 1 epochs only")


def _load_extensions(args: argparse.Namespace) -> None:
    """Register ``--plugin`` estimators, then read ``--config`` into ``args.configs``."""
    if getattr(args, "plugin", None):
        from .estimators.base import load_plugin

        for spec in args.plugin:
            load_plugin(spec)
    args.configs = None
    if getattr(args, "config", None):
        from .estimators.configfile import load_configs

        args.configs = load_configs(args.config)


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # one line, exit 2 (argparse's own convention)
        self.exit(EXIT_BAD_INPUT, f"vnav-graph: error: {message}\n")


DESCRIPTION = ("INS / GNSS / barometric-altimeter navigation: a GTSAM factor-graph smoother,\n"
               "a reference EKF + RTS smoother and the classical baro-inertial loops on one\n"
               "set of sensor models, compared on your drive. 'vnav-graph run --help' lists\n"
               "the estimators and scenarios.")

EXIT_CODES = """exit codes:
  0    every estimator that could run is ok (skipped ones are named on stderr)
  2    bad input: one line on stderr, nothing written
  3    some estimators failed or diverged (the others' results are written)
  4    no estimator produced a trustworthy result (summary written for diagnosis)
  130  interrupted (Ctrl-C)"""


class _Help(argparse.RawDescriptionHelpFormatter):
    """Epilogs keep their line breaks (lists of names, exit codes)."""


def _name_lines(est_title: str, scen_title: str, between: tuple[str, ...] = ()) -> list[str]:
    """The estimators and scenarios of this build, one line each (``list``, ``run --help``);
    ``between``: lines between the two lists."""
    from .estimators.base import available, describe
    from .simulation import list_scenarios, scenario_description

    names, scen = available(), list_scenarios()
    w = max(len(n) for n in [*names, *scen]) + 2
    return ([est_title, *(f"  {n:<{w}}{describe(n)}" for n in names), *between, scen_title,
             *(f"  {s:<{w}}{scenario_description(s)}" for s in scen)])


def _names_epilog() -> str:
    """``run --help``'s epilog: the names, the outputs and the exit codes."""
    lines = _name_lines("estimators (--estimators a,b; default: all):",
                        "scenarios (--scenario NAME; default: default):", between=("",))
    lines += ["", "outputs in --out: summary.json, summary.txt, report.html, plots/*.png, "
              "estimates/<name>.parquet,", "  estimates/<name>.online.parquet (causal "
              "estimators), drive.json, truth.parquet (simulated),", "  export/ "
              "(with --export)", "", EXIT_CODES]
    return "\n".join(lines)


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="vnav-graph", description=DESCRIPTION, epilog=EXIT_CODES,
                formatter_class=_Help)
    from . import __version__

    p.add_argument("--version", action="version", version=f"vnav-graph {__version__}")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)

    s = sub.add_parser("simulate", help="simulate a drive and save it (.npz)")
    s.add_argument("--scenario", default="hill-drive", help="scenario name or TOML path")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--duration", type=_positive_float, default=None, help="override [s]")
    s.add_argument("-o", "--output", required=True, help="output .npz path")

    r = sub.add_parser("run", help="run estimators on a drive and compare them",
                       description="Run estimators on a drive (a .npz, a real log, or a\n"
                                   "simulated scenario), print the comparison and write the\n"
                                   "results, plots and an HTML report.",
                       epilog=_names_epilog(), formatter_class=_Help)
    r.add_argument("drive", nargs="?", default=None,
                   help="drive .npz or real log; default: simulated scenario")
    r.add_argument("--scenario", default=None, help="scenario to simulate (default: default)")
    r.add_argument("--seed", type=int, default=0,
                   help="seed of the simulated scenario's noise and errors (default 0)")
    r.add_argument("--duration", type=_positive_float, default=None,
                   help="shorten or lengthen the simulated scenario [s]")
    r.add_argument("--estimators", type=_csv_list, default=None,
                   help="comma-separated names (default: all; listed below)")
    r.add_argument("--out", default="vnav-graph-out",
                   help="output directory (default: vnav-graph-out)")
    r.add_argument("--no-progress", action="store_true",
                   help="no progress on stderr (default: a bar on a terminal, else a line per "
                        "step)")
    r.add_argument("--no-holdout", action="store_true",
                   help="real logs: skip the withheld-GNSS scoring run (metrics become null)")
    r.add_argument("--baseline", default=None, metavar="NAME",
                   help="put every estimator against NAME in the headline (paired CI per "
                        "metric), e.g. your variant against the estimator it extends")
    r.add_argument("--outage", type=_positive_float, default=None,
                   help="real logs: length of each withheld-GNSS window [s] (default 60, or "
                        "the longest of 45, 30, 20, 15, 10 that gives the 4 windows a "
                        "ranking needs where 60 gives fewer; the summary says which)")
    r.add_argument("--spacing", type=_positive_float, default=None,
                   help="real logs: spacing of the windows [s] (default: as holdout)")
    r.add_argument("--export", type=_export_formats, default=None, metavar="FORMATS",
                   help="also export the trajectories at the end: comma-separated "
                        "csv,kml,gpx,tum (into OUT/export/; see 'vnav-graph export')")
    _truth_args(r)
    _extension_args(r)

    x = sub.add_parser(
        "export", help="export a finished run's trajectories as CSV, KML, GPX or TUM",
        description="Write OUT_DIR/export/<estimator>.<format> (each estimator's final "
                    "answer; truth.<format> where the drive has a truth, and all.kml with "
                    "every track) from the folder a 'vnav-graph run --out OUT_DIR' wrote; "
                    "with --online the causal estimators' online answers as "
                    "<estimator>.online.<format>. csv: one header row, units in the column "
                    "names, angles in degrees, the rest in <file>.csv-metadata.json; kml: "
                    "tracks (absolute altitude) and the GNSS windows; gpx: track with "
                    "elevation, UTC time where the drive has one; tum: 'timestamp x y z qx "
                    "qy qz qw' in local NED (evo). Rows: the epochs on the 20 Hz grid of "
                    "the drive clock (--full-rate: every epoch). Vertical-only estimators "
                    "export as CSV only.")
    x.add_argument("run_dir", metavar="OUT_DIR", help="output folder of 'vnav-graph run'")
    x.add_argument("--format", dest="formats", type=_export_formats, default=None,
                   metavar="FORMATS", help="comma-separated: csv,kml,gpx,tum (default: all)")
    x.add_argument("--estimators", type=_csv_list, default=None,
                   help="comma-separated names (default: every estimate in OUT_DIR, and "
                        "truth)")
    x.add_argument("--online", action="store_true",
                   help="export the online (real-time) answers of the causal estimators "
                        "(estimates/<name>.online.parquet) as <name>.online.<format>")
    x.add_argument("--full-rate", action="store_true",
                   help="every epoch of each trajectory (default: the epochs at multiples "
                        "of 0.05 s, 20 Hz, the graph smoothers' output rate; the truth and "
                        "the vertical filters are at the IMU rate)")

    b = sub.add_parser("bench", help="Monte Carlo over scenarios x seeds x estimators")
    b.add_argument("--quick", action="store_true")
    b.add_argument("--scenarios", type=_csv_list, default=None)
    b.add_argument("--estimators", type=_csv_list, default=None)
    b.add_argument("--seeds", type=int, default=None)
    b.add_argument("--dask", default=None, metavar="ADDRESS", help="Dask scheduler address")
    b.add_argument("--workers", type=int, default=None, help="local process pool size")
    b.add_argument("--out", required=True)
    b.add_argument("--no-progress", action="store_true")
    _extension_args(b)

    h = sub.add_parser("holdout", help="score estimators against withheld GNSS on a real log")
    h.add_argument("log")
    h.add_argument("--outage", type=_positive_float, default=60.0, help="window length [s]")
    h.add_argument("--spacing", type=_positive_float, default=None, help="window spacing [s]")
    h.add_argument("--estimators", type=_csv_list, default=None)
    h.add_argument("--out", required=True)
    h.add_argument("--no-progress", action="store_true")
    _truth_args(h)
    _extension_args(h)

    c = sub.add_parser("calibrate-baro", help="least-squares baro scale/latency/bias vs GNSS")
    c.add_argument("drive")

    _extension_args(sub.add_parser("list", help="list available estimators and scenarios"),
                    config=False)
    return p


def cmd_simulate(args: argparse.Namespace) -> int:
    from .io import save_npz
    from .simulation import simulate

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
    from .io.reference import load_scored
    from .jit import Prewarm
    from .outputs import check_out_dir
    from .pipeline import format_table, summarize
    from .progress import mode_for, stage
    from .runner import resolve_estimators, run_estimators
    from .simulation import simulate

    t_start = time.perf_counter()
    names = resolve_estimators(args.estimators)  # validate before any work
    if args.baseline is not None and args.baseline not in names:
        from .suggest import did_you_mean

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
        from .pipeline import score_holdout

        ok = [r.name for r in results if r.estimate is not None]
        if ok:
            with stage("scoring against withheld GNSS (holdout run of every estimator)", mode):
                summary, holdout = score_holdout(summary, drive, ok, progress=mode,
                                                 configs=configs, outage_s=args.outage,
                                                 spacing_s=args.spacing)
    if args.baseline is not None:
        from .evaluation.compare import against_baseline

        summary = against_baseline(summary, args.baseline)
    from .pipeline import write_outputs

    writers = []
    try:
        from .report import write_report  # plots + HTML (optional module)

        writers.append(functools.partial(write_report, holdout=holdout))
    except ModuleNotFoundError as exc:
        if exc.name != "vnav_graph.report":
            raise
    from .export import write_run_info

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
    from .pipeline import run_status

    code, line = run_status(summary)
    if line:
        print(f"vnav-graph: {line}", file=sys.stderr)
    return code


def _say_hint(drive: Any, names: list[str], holdout: bool, mode: Any) -> None:
    """The predicted runtime when the run will be long (``runtime_estimate.run_hint``)."""
    from .progress import say
    from .runtime_estimate import run_hint

    hint = run_hint(drive, names, holdout)
    if hint:
        say(f"hint: {hint}", mode)


def cmd_bench(args: argparse.Namespace) -> int:
    """``vnav-graph bench``: validate arguments, run, write ``bench.json`` and ``bench.md``.

    Bad arguments raise ValueError (exit 2). Returns 1 when any run failed (after writing the
    files, with a one-line summary on stderr), 130 when interrupted, else 0.
    """
    from .bench import bench
    from .evaluation import montecarlo as mc
    from .outputs import check_out_dir
    from .progress import mode_for
    from .runner import resolve_estimators
    from .simulation import list_scenarios

    estimators = resolve_estimators(args.estimators)
    scenarios = list(args.scenarios or (mc.QUICK_SCENARIOS if args.quick
                                        else mc.DEFAULT_SCENARIOS))
    known = list_scenarios()
    bad = [s for s in scenarios if s not in known and not s.endswith(".toml")]
    if bad:
        from .suggest import did_you_mean

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
    n_ok = sum(r["status"] == "ok" for r in doc["runs"])
    if doc["config"]["interrupted"]:
        print(f"vnav-graph: interrupted: wrote the {len(doc['runs'])} of "
              f"{doc['config']['runs_planned']} runs that finished to {out / 'bench.json'}",
              file=sys.stderr)
        return 130
    print(mc.format_bench_md(doc))
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
    from .evaluation.holdout import format_markdown
    from .io.jsonout import dumps_strict
    from .io.reference import load_scored
    from .outputs import check_out_dir, publish
    from .progress import mode_for, stage
    from .report.error_plots import plot_holdout_errors
    from .runner import resolve_estimators, run_holdout

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
    from .calibration import calibrate_baro, format_calibration
    from .io import load_drive

    print(format_calibration(calibrate_baro(load_drive(args.drive))))
    return 0


def _export(out: Path, formats: list[str] | None, estimators: list[str] | None,
            online: bool = False, full_rate: bool = False) -> Any:
    from .export import FORMATS, export_run

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
    print("\n".join(_name_lines("estimators (vnav-graph run --estimators a,b):",
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
        from .failures import failure_message

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
