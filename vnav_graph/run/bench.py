"""Monte Carlo bench execution: scenarios × seeds × estimators, local process pool or Dask.

One **task** is ``(scenario, seed, estimator, duration override)``. The worker simulates the
drive itself (a drive is never shipped between processes: a (scenario, seed) pair always gives
the same drive, ``vnav_graph.simulation.simulate``), runs the estimator through
``vnav_graph.run.runner.run_one`` and evaluates it with ``vnav_graph.evaluation.metrics.evaluate``
— the same metric block as ``summary.json``. A task that raises is recorded with
``status: "failed"`` and its error (``runner.failed_block``); it is never dropped.

The statistics over seeds, the ``bench.json`` aggregate and the Markdown table are in
``vnav_graph.evaluation.montecarlo``; ``bench`` here runs the tasks and returns the document.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import CancelledError, ProcessPoolExecutor, as_completed
from dataclasses import asdict, dataclass, is_dataclass
from typing import Any

from ..evaluation.montecarlo import (
    BENCH_SCHEMA,
    CAUSAL_ERRORS_KEY,
    DEFAULT_WORKERS,
    HEADING_ERRORS_KEY,
    aggregate,
    common_heading_blocks,
    common_start_blocks,
    finite,
    shorten_scenario,
)
from ..util.failures import failure_message
from .progress import Counter, Mode, mode_for
from .runner import failed_block, interrupt_flag, run_one


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


def _json_config(config: Any) -> Any:
    """A config object as JSON data (dataclass fields; anything JSON lacks as its str)."""
    data = asdict(config) if is_dataclass(config) and not isinstance(config, type) else config
    return json.loads(json.dumps(finite(data), default=str))


# Estimators already run once in this process (see ``warm_up``).
_WARMED: set[str] = set()
WARMUP_DURATION_S = 20.0


def warm_up(task: BenchTask) -> None:
    """Run the estimator once, untimed, on a short drive of the same scenario the first time
    this process meets it, so that ``runtime_s`` measures the estimator and not numba's JIT
    compilation or first imports (which otherwise land on whichever seed comes first).
    Errors are ignored here: the timed run reports them."""
    if task.estimator in _WARMED:
        return
    _WARMED.add(task.estimator)
    from ..simulation import simulate

    try:
        drive = simulate(shorten_scenario(task.scenario, WARMUP_DURATION_S), task.seed)
    except Exception:
        return
    run_one(task.estimator, drive, task.config, interrupts=False)


def run_task(task: BenchTask) -> dict[str, Any]:
    """Simulate, estimate and evaluate one task (runs inside a worker; never raises).

    Returns the run row of ``bench.json``: task identity, then the metric fields of
    ``summary.json`` (``evaluate``), ``status`` and ``error``. ``runtime_s`` excludes the
    one-time warm-up of the estimator in this process (``warm_up``).
    """
    from ..estimators.base import register
    from ..evaluation.metrics import causal_errors, evaluate, heading_errors
    from ..simulation import simulate

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
        warm_up(task)
        res = run_one(task.estimator, drive, task.config, interrupts=False)
        if res.estimate is None:
            error = res.error if res.skipped else f"estimate: {res.error}"
            row.update(failed_block(error, res.runtime_s, res.status))
            return row
        stage = "evaluate"
        row.update(finite(evaluate(res.estimate, drive)))
        # the causal estimate's errors epoch by epoch, for the real-time pairs scored over
        # their common span (montecarlo.common_start_blocks; removed before the row is kept)
        row[CAUSAL_ERRORS_KEY] = causal_errors(res.estimate, drive, "online")
        # its heading error and σ_yaw, for heading scored where both of a pair know it
        # (montecarlo.common_heading_blocks; removed before the row is kept)
        row[HEADING_ERRORS_KEY] = heading_errors(res.estimate, drive)
        if row["status"] == "ok" and row["alt_rmse_m"] is None and drive.truth is not None:
            row["status"] = "failed"
            row["error"] = "evaluate: non-finite altitude error (estimator diverged)"
    except Exception as exc:  # a failed run is data: recorded with its error, never dropped
        if os.environ.get("VNAV_DEBUG"):
            import traceback

            traceback.print_exc()
        err = f"{stage}: {failure_message(exc, typed=True)}"
        row.update(failed_block(err, time.perf_counter() - t0))
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
    from ..estimators.base import registered_factories

    extra = registered_factories()
    cfg = dict(configs or {})
    return [BenchTask(sc, int(sd), est, duration_s, extra.get(est), cfg.get(est))
            for sc in scenarios for sd in seeds for est in estimators]


def _failed_row(task: BenchTask, error: str) -> dict[str, Any]:
    row: dict[str, Any] = {"scenario": task.scenario, "seed": task.seed,
                           "estimator": task.estimator, "duration_s": task.duration_s}
    row.update(failed_block(error, 0.0))
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
    progress : a ``vnav_graph.run.progress`` mode, or a bool (True: a bar on a terminal, a line
        per finished run otherwise), on stderr

    A task whose worker dies (``BrokenProcessPool``, a lost Dask worker) is recorded as a
    failed row with that error.
    """
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
        raise BenchInterrupted(common_heading_blocks(common_start_blocks(
            [r for r in rows if r is not None])))
    return common_heading_blocks(common_start_blocks(
        [r if r is not None else _failed_row(t, "worker: no result")
         for r, t in zip(rows, tasks, strict=True)]))


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
        raise ValueError(f"cannot connect to Dask scheduler {dask!r}: "
                         f"{failure_message(exc)}") from None
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
