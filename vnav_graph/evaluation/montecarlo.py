"""Monte Carlo benchmark: scenarios × seeds × estimators, local process pool or Dask.

One **task** is ``(scenario, seed, estimator, duration override)``. The worker simulates the
drive itself (a drive is never shipped between processes: a (scenario, seed) pair always gives
the same drive, ``vnav_graph.simulation.simulate``), runs the estimator and evaluates it with
``vnav_graph.evaluation.metrics.evaluate`` — the same metric block as ``summary.json``. A task
that raises is recorded with ``status: "failed"`` and its error; it is never dropped.

Aggregation over seeds (per scenario × estimator), for each metric x with n ≥ 2 finite values:

    x̄ = (1/n) Σ x_i,   s² = Σ (x_i − x̄)² / (n − 1),
    CI95 = x̄ ± t_{0.975, n−1} · s / √n          (Student t, e.g. Montgomery & Runger §8.2)

n = 1 gives the mean and ``ci95: null``; n = 0 gives ``mean: null``.

Contents
--------
``BenchTask`` (one unit of work), ``make_tasks``, ``shorten_scenario`` (duration override
that keeps the GNSS outages inside the shortened drive), ``run_task`` (executed in a worker),
``run_tasks`` (local ``ProcessPoolExecutor`` or a Dask ``Client``), ``mean_ci95``,
``aggregate``, ``bench`` (the whole thing → the ``bench.json`` document), ``format_bench_md``,
``write_bench`` and ``cli_bench`` (``vnav-graph bench``).

The ``bench.json`` document (docs/design.md)::

    {"schema": "vnav_graph.bench/1",
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
import sys
import tempfile
import time
import traceback
from collections.abc import Callable, Iterable, Mapping, Sequence
from concurrent.futures import CancelledError, ProcessPoolExecutor, as_completed
from dataclasses import asdict, dataclass, is_dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from ..progress import Counter, Mode, mode_for

BENCH_SCHEMA = "vnav_graph.bench/1"

# Metrics aggregated over seeds (mean and 95 % CI). The first four are the docs/design.md ones;
# the baro parameter errors |est − truth| show the modelling gain of the baro-aware estimators.
AGG_METRICS = (
    "alt_rmse_m", "nees_mean", "runtime_s", "vel_down_rmse_mps", "alt_max_abs_m",
    "nees_per_dof", "realtime_factor", "baro_scale_abs_err", "baro_latency_abs_err_s",
    "baro_bias_abs_err_m", "horiz_rmse_m", "heading_rmse_deg", "heading_known_rmse_deg",
    "heading_known_after_s", "outage_alt_max_m",
    "outage_horiz_max_m", "gnss_rejected",
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


@dataclass(frozen=True)
class BenchTask:
    """One Monte Carlo run.

    Parameters
    ----------
    scenario : scenario name (``vnav_graph/scenarios/<name>.toml``) or TOML path
    seed : simulation seed
    estimator : registry name
    duration_s : drive length override [s] or None for the scenario's own length
    factory : for estimators registered at run time (``base.register``), the factory
        (``"module:attr"`` string or picklable callable) re-registered inside the worker;
        None for the built-in estimators
    config : the estimator's config object (picklable), None for its default
    """

    scenario: str
    seed: int
    estimator: str
    duration_s: float | None = None
    factory: Any = None
    config: Any = None


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


def _finite(x: Any) -> Any:
    """Replace NaN/inf floats by None, recursively (JSON has no NaN; docs/design.md: metrics that
    do not exist are null)."""
    if isinstance(x, dict):
        return {k: _finite(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [_finite(v) for v in x]
    if isinstance(x, float | np.floating):
        return float(x) if math.isfinite(x) else None
    if isinstance(x, np.integer):
        return int(x)
    return x


def _json_config(config: Any) -> Any:
    """A config object as JSON data (dataclass fields; anything JSON lacks as its str)."""
    data = asdict(config) if is_dataclass(config) and not isinstance(config, type) else config
    return json.loads(json.dumps(_finite(data), default=str))


def _null_metrics(error: str, runtime_s: float) -> dict[str, Any]:
    from ..pipeline import failed_block

    return failed_block(error, runtime_s)


# Estimators already run once in this process (see ``_warm_up``).
_WARMED: set[str] = set()
WARMUP_DURATION_S = 20.0


def _warm_up(task: BenchTask) -> None:
    """Run the estimator once, untimed, on a short drive of the same scenario the first time
    this process meets it, so that ``runtime_s`` measures the estimator and not numba's JIT
    compilation or first imports (which otherwise land on whichever seed comes first).
    Errors are ignored here: the timed run reports them."""
    if task.estimator in _WARMED:
        return
    _WARMED.add(task.estimator)
    from ..estimators.base import create
    from ..simulation import simulate

    try:
        drive = simulate(shorten_scenario(task.scenario, WARMUP_DURATION_S), task.seed)
        create(task.estimator, task.config).run(drive)
    except Exception:
        pass


def run_task(task: BenchTask) -> dict[str, Any]:
    """Simulate, estimate and evaluate one task (runs inside a worker; never raises).

    Returns the run row of ``bench.json``: task identity, then the metric fields of
    ``summary.json`` (``evaluate``), ``status`` and ``error``. ``runtime_s`` excludes the
    one-time warm-up of the estimator in this process (``_warm_up``).
    """
    from ..estimators.base import create, register
    from ..simulation import simulate
    from .metrics import evaluate

    row: dict[str, Any] = {"scenario": task.scenario, "seed": int(task.seed),
                           "estimator": task.estimator, "duration_s": task.duration_s}
    t0 = time.perf_counter()
    stage = "simulate"
    try:
        drive = simulate(shorten_scenario(task.scenario, task.duration_s), task.seed)
        row["duration_s"] = drive.duration_s
        row["gnss_outages"] = [list(map(float, w)) for w in drive.meta.get("gnss_outages", [])]
        stage = "estimate"
        if task.factory is not None:
            register(task.estimator, task.factory)
        _warm_up(task)
        t1 = time.perf_counter()
        est = create(task.estimator, task.config).run(drive)
        if est.runtime_s <= 0:
            est = est.replace(runtime_s=time.perf_counter() - t1)
        stage = "evaluate"
        row.update(_finite(evaluate(est, drive)))
        if row["status"] == "ok" and row["alt_rmse_m"] is None and drive.truth is not None:
            row["status"] = "failed"
            row["error"] = "evaluate: non-finite altitude error (estimator diverged)"
    except Exception as exc:  # a failed run is data: recorded with its error, never dropped
        if os.environ.get("VNAV_DEBUG"):
            traceback.print_exc()
        msg = str(exc).splitlines()[0] if str(exc) else ""
        if not msg:  # say at least where it was raised
            tb = traceback.extract_tb(exc.__traceback__)
            if tb:
                msg = f"(no message; raised at {Path(tb[-1].filename).name}:{tb[-1].lineno} " \
                      f"in {tb[-1].name})"
        err = f"{stage}: {type(exc).__name__}: {msg}".rstrip(": ")
        row.update(_null_metrics(err, time.perf_counter() - t0))
    return row


def make_tasks(
    scenarios: Sequence[str], seeds: Sequence[int], estimators: Sequence[str],
    duration_s: float | None = None, configs: Mapping[str, Any] | None = None,
) -> list[BenchTask]:
    """All (scenario, seed, estimator) combinations, in report order.

    Estimators registered at run time (not part of the built-in registry) carry their factory
    so that a worker process that did not inherit the registration can rebuild it; ``configs``
    maps an estimator name to its config object (default: the estimator's own).
    """
    from ..estimators import base

    extra = dict(base._REGISTRY)
    cfg = dict(configs or {})
    return [BenchTask(sc, int(sd), est, duration_s, extra.get(est), cfg.get(est))
            for sc in scenarios for sd in seeds for est in estimators]


def _failed_row(task: BenchTask, error: str) -> dict[str, Any]:
    row: dict[str, Any] = {"scenario": task.scenario, "seed": task.seed,
                           "estimator": task.estimator, "duration_s": task.duration_s}
    row.update(_null_metrics(error, 0.0))
    return row


def _label(task: BenchTask) -> str:
    return f"{task.scenario} seed {task.seed} {task.estimator}"


def run_tasks(
    tasks: Sequence[BenchTask], workers: int = DEFAULT_WORKERS, dask: Any = None,
    progress: bool | Mode = False,
) -> list[dict[str, Any]]:
    """Run ``tasks`` and return their rows in task order.

    Parameters
    ----------
    tasks : the runs
    workers : local process-pool size; ``workers == 1`` runs in this process (no pool)
    dask : None for the local pool, else a ``dask.distributed.Client``, a scheduler
        address (``"tcp://host:8786"``) or ``"local[:N]"`` (a LocalCluster of N worker
        processes) — the same ``run_task`` is submitted to the cluster
    progress : a ``vnav_graph.progress`` mode, or a bool (True: a bar on a terminal, a line
        per finished run otherwise), on stderr

    A task whose worker dies (``BrokenProcessPool``, a lost Dask worker) is recorded as a
    failed row with that error.
    """
    from ..pipeline import interrupt_flag

    rows: list[dict[str, Any] | None] = [None] * len(tasks)
    mode = progress if isinstance(progress, str) else mode_for(bool(progress))
    bar = Counter(len(tasks), "bench", mode)
    interrupted: list[int] = []
    try:
        if dask is not None:
            _run_dask(tasks, dask, rows, bar)
        elif workers <= 1:
            with interrupt_flag("run") as interrupted:
                for i, task in enumerate(tasks):
                    rows[i] = run_task(task)
                    bar.update(_label(task))
                    if interrupted:
                        break
        else:
            with interrupt_flag("run") as interrupted, ProcessPoolExecutor(
                    max_workers=workers, initializer=_ignore_sigint) as pool:
                futs = {pool.submit(run_task, t): i for i, t in enumerate(tasks)}
                for fut in as_completed(futs):
                    i = futs[fut]
                    try:
                        rows[i] = fut.result()
                    except CancelledError:
                        continue
                    except Exception as exc:  # the worker process died
                        rows[i] = _failed_row(tasks[i], f"worker: {type(exc).__name__}: {exc}")
                    bar.update(_label(tasks[i]))
                    if interrupted:  # finish the running tasks, start no new one
                        for f in futs:
                            f.cancel()
    finally:
        bar.close()
    if interrupted:
        raise BenchInterrupted([r for r in rows if r is not None])
    return [r if r is not None else _failed_row(t, "worker: no result")
            for r, t in zip(rows, tasks, strict=True)]


class BenchInterrupted(KeyboardInterrupt):
    """Ctrl-C during a bench: ``rows`` holds the runs that finished (in task order)."""

    def __init__(self, rows: list[dict[str, Any]]) -> None:
        super().__init__()
        self.rows = rows


def _ignore_sigint() -> None:
    """Pool workers ignore Ctrl-C (it reaches the whole process group): the parent decides,
    and an interrupt inside a numba kernel is not safe."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _dask_client(dask: Any) -> tuple[Any, Callable[[], None]]:
    """A Client for ``dask`` (a Client or an address) and a function that releases it."""
    try:
        from dask.distributed import Client
    except ModuleNotFoundError:
        raise ValueError("--dask needs dask.distributed (pip install 'vnav_graph[dask]')") from None
    if isinstance(dask, Client):
        return dask, lambda: None
    if str(dask).startswith("local"):  # "local" or "local:N": a LocalCluster of N processes
        from dask.distributed import LocalCluster

        n = int(str(dask).partition(":")[2] or DEFAULT_WORKERS)
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, dashboard_address=None)
        client = Client(cluster)

        def close() -> None:
            client.close()
            cluster.close()

        return client, close
    try:
        client = Client(str(dask), timeout="20s")
    except (OSError, TimeoutError, ValueError) as exc:
        msg = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise ValueError(f"cannot connect to Dask scheduler {dask!r}: {msg}") from None
    return client, client.close


def _run_dask(tasks: Sequence[BenchTask], dask: Any, rows: list[Any], bar: Any) -> None:
    from dask.distributed import as_completed as dask_as_completed

    client, release = _dask_client(dask)
    try:
        futs = [client.submit(run_task, t, pure=False, key=f"vnav-bench-{i}-{os.getpid()}-"
                              f"{time.time_ns()}") for i, t in enumerate(tasks)]
        index = {f.key: i for i, f in enumerate(futs)}
        for fut in dask_as_completed(futs):
            i = index[fut.key]
            try:
                rows[i] = fut.result()
            except Exception as exc:  # a lost worker or a serialisation error
                rows[i] = _failed_row(tasks[i], f"dask: {type(exc).__name__}: {exc}")
            bar.update(_label(tasks[i]))
    finally:
        release()


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
    return out


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


def bench(
    scenarios: Sequence[str], estimators: Sequence[str], seeds: Sequence[int],
    duration_s: float | None = None, workers: int = DEFAULT_WORKERS, dask: Any = None,
    progress: bool | Mode = False, configs: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """Run the Monte Carlo and return the ``bench.json`` document (docs/design.md schema).
    ``configs``: estimator name → config object (``--config``), echoed in ``config``."""
    tasks = make_tasks(scenarios, seeds, estimators, duration_s, configs)
    t0 = time.perf_counter()
    interrupted = False
    try:
        runs = run_tasks(tasks, workers=workers, dask=dask, progress=progress)
    except BenchInterrupted as exc:  # Ctrl-C: the document of the runs that finished
        runs, interrupted = exc.rows, True
    wall = time.perf_counter() - t0
    from .. import __version__

    return {
        "schema": BENCH_SCHEMA,
        "config": {"scenarios": list(scenarios), "estimators": list(estimators),
                   "seeds": [int(s) for s in seeds], "duration_s": duration_s,
                   "executor": "dask" if dask is not None else
                   ("local" if workers <= 1 else f"process-pool({workers})"),
                   "wall_s": wall, "vnav_graph_version": __version__,
                   "interrupted": interrupted, "runs_planned": len(tasks),
                   "estimator_configs": {n: _json_config(c) for n, c in
                                         (configs or {}).items() if n in estimators}},
        "runs": runs,
        "aggregate": aggregate(runs),
    }


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
    failed = [r for r in doc["runs"] if r["status"] != "ok"]
    if failed:
        lines += ["## Failed runs", "", "| scenario | seed | estimator | error |",
                  "| --- | --- | --- | --- |"]
        lines += [f"| {r['scenario']} | {r['seed']} | {r['estimator']} | "
                  f"{str(r['error']).replace('|', '/')} |" for r in failed]
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
    """One line naming the failed runs, or None when every run succeeded."""
    failed = [r for r in doc["runs"] if r["status"] != "ok"]
    if not failed:
        return None
    first = failed[0]
    by_est = sorted({r["estimator"] for r in failed})
    return (f"{len(failed)} of {len(doc['runs'])} runs failed ({', '.join(by_est)}); first: "
            f"{first['estimator']} on {first['scenario']} seed {first['seed']}: {first['error']}")


def cli_bench(args: Any) -> int:
    """``vnav-graph bench``: validate arguments, run, write ``bench.json`` and ``bench.md``.

    Bad arguments raise ValueError (exit 2 through the CLI). Returns 1 when any run failed
    (after writing the files, with a one-line summary on stderr), else 0.
    """
    from ..outputs import check_out_dir
    from ..pipeline import resolve_estimators
    from ..simulation import list_scenarios

    estimators = resolve_estimators(args.estimators)
    if not estimators:
        raise ValueError("no estimators available in this build")
    scenarios = list(args.scenarios or (QUICK_SCENARIOS if args.quick else DEFAULT_SCENARIOS))
    known = list_scenarios()
    bad = [s for s in scenarios if s not in known and not s.endswith(".toml")]
    if bad:
        raise ValueError(f"unknown scenario(s) {', '.join(bad)} (known: {', '.join(known)})")
    n_seeds = args.seeds if args.seeds is not None else (QUICK_SEEDS if args.quick
                                                         else DEFAULT_SEEDS)
    if n_seeds < 1:
        raise ValueError(f"--seeds must be >= 1, got {n_seeds}")
    workers = args.workers if args.workers is not None else DEFAULT_WORKERS
    if workers < 1:
        raise ValueError(f"--workers must be >= 1, got {workers}")
    for sc in scenarios:  # parse every scenario before any work
        shorten_scenario(sc, QUICK_DURATION_S if args.quick else None)
    out = check_out_dir(args.out)
    progress = mode_for(not getattr(args, "no_progress", False))
    doc = bench(scenarios, estimators, list(range(n_seeds)),
                duration_s=QUICK_DURATION_S if args.quick else None, workers=workers,
                dask=args.dask, progress=progress, configs=getattr(args, "configs", None))
    write_bench(doc, out)
    n_ok = sum(r["status"] == "ok" for r in doc["runs"])
    if doc["config"]["interrupted"]:
        print(f"vnav-graph: interrupted: wrote the {len(doc['runs'])} of "
              f"{doc['config']['runs_planned']} runs that finished to {out / 'bench.json'}",
              file=sys.stderr)
        return 130
    print(format_bench_md(doc))
    print(f"wrote {out / 'bench.json'} and {out / 'bench.md'}: {n_ok}/{len(doc['runs'])} runs "
          f"ok in {doc['config']['wall_s']:.1f} s")
    msg = failure_summary(doc)
    if msg:
        print(f"vnav-graph bench: {msg}", file=sys.stderr)
        return 1
    return 0


__all__ = ["BENCH_SCHEMA", "BenchTask", "aggregate", "bench", "cli_bench", "derived_metrics",
           "format_bench_md",
           "make_tasks", "mean_ci95", "run_task", "run_tasks", "shorten_scenario", "write_bench"]
