"""The command line's arguments: the parser of every ``vnav-graph`` command, its help
texts and the argument types (one line on stderr and exit code 2 on a bad argument)."""

from __future__ import annotations

import argparse

EXIT_BAD_INPUT = 2


def _csv_list(s: str) -> list[str]:
    return [x.strip() for x in s.split(",") if x.strip()]


def _positive_float(s: str) -> float:
    v = float(s)
    if not v > 0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {s}")
    return v


def _export_formats(s: str) -> list[str]:
    from ..export import parse_formats

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


def name_lines(est_title: str, scen_title: str, between: tuple[str, ...] = ()) -> list[str]:
    """The estimators and scenarios of this build, one line each (``list``, ``run --help``);
    ``between``: lines between the two lists."""
    from ..estimators.base import available, describe
    from ..simulation import list_scenarios, scenario_description

    names, scen = available(), list_scenarios()
    w = max(len(n) for n in [*names, *scen]) + 2
    return ([est_title, *(f"  {n:<{w}}{describe(n)}" for n in names), *between, scen_title,
             *(f"  {s:<{w}}{scenario_description(s)}" for s in scen)])


def _names_epilog() -> str:
    """``run --help``'s epilog: the names, the outputs and the exit codes."""
    lines = name_lines("estimators (--estimators a,b; default: all):",
                        "scenarios (--scenario NAME; default: default):", between=("",))
    lines += ["", "outputs in --out: summary.json, summary.txt, report.html, plots/*.png, "
              "estimates/<name>.parquet,", "  estimates/<name>.online.parquet (causal "
              "estimators), drive.json, truth.parquet (simulated),", "  export/ "
              "(with --export)", "", EXIT_CODES]
    return "\n".join(lines)


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="vnav-graph", description=DESCRIPTION, epilog=EXIT_CODES,
                formatter_class=_Help)
    from .. import __version__

    p.add_argument("--version", action="version", version=f"vnav-graph {__version__}")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)

    s = sub.add_parser("simulate", help="simulate a drive and save it (.npz)")
    s.add_argument("--scenario", default="hill-drive", help="scenario name or TOML path")
    s.add_argument("--seed", type=int, default=0)
    s.add_argument("--duration", type=_positive_float, default=None, help="override [s]")
    s.add_argument("-o", "--output", required=True, help="output .npz path")

    _run_parser(sub)

    _export_parser(sub)

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


def _run_parser(sub: argparse._SubParsersAction) -> None:
    """``vnav-graph run``."""
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


def _export_parser(sub: argparse._SubParsersAction) -> None:
    """``vnav-graph export``."""
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
