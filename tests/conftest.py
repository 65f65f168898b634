"""Shared fixtures: deterministic RNGs, short simulated drives, the shared real-data folder."""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parent.parent


def shared_data_dir() -> Path | None:
    """Real logs from $VNAV_DATA or ../shared/data next to the repository, if present."""
    env = os.environ.get("VNAV_DATA")
    for cand in ([Path(env)] if env else []) + [REPO.parent / "shared" / "data"]:
        if cand.is_dir():
            return cand
    return None


def pytest_configure(config: pytest.Config) -> None:
    """Under pytest-xdist with several workers (``addopts``: one per core), each worker's BLAS
    runs one thread, as do the processes the tests start: OpenBLAS's default of one thread
    per core, in every worker, oversubscribes the cores (``estimators/graph/solver/linalg.py``,
    ``single_thread_blas``). Measured on the 2-core machine with its other core busy:
    test_calibration's seed-001 table test (dense Cholesky) 24.9-29.2 s with OpenBLAS's two
    threads, 2.6 s with one."""
    if int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1")) > 1:
        for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
            os.environ.setdefault(var, "1")
        from threadpoolctl import threadpool_limits

        threadpool_limits(limits=1, user_api="blas")


QUICK_LIST = Path(__file__).resolve().parent / "quick.txt"


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """The quick tier (``-m quick``): the tests of the files listed in ``tests/quick.txt``
    that are not marked slow, chosen from measured durations to run in about a minute on 2
    cores (README, "Tests")."""
    listed = {line.split("#")[0].strip() for line in QUICK_LIST.read_text().splitlines()}
    listed.discard("")
    missing = sorted(f for f in listed if not (REPO / f).is_file())
    if missing:
        raise pytest.UsageError(f"tests/quick.txt lists missing files: {', '.join(missing)}")
    for item in items:
        rel = Path(str(item.path)).resolve().relative_to(REPO).as_posix()
        if rel in listed and item.get_closest_marker("slow") is None:
            item.add_marker(pytest.mark.quick)


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(12345)


@pytest.fixture
def data_dir() -> Path:
    d = shared_data_dir()
    if d is None:
        pytest.skip("real logs not found: set VNAV_DATA or place them in ../shared/data")
    return d


@pytest.fixture
def shared_log(data_dir: Path) -> Callable[[str], Path]:
    """The path of one shared log, by its path under the data folder; the test is skipped
    when that log is absent."""
    def path(rel: str) -> Path:
        p = data_dir / rel
        if not p.exists():
            pytest.skip(f"shared log {rel} not present")
        return p
    return path


@pytest.fixture
def registry():
    """``register`` for one test: its registrations are undone afterwards
    (``estimators.base.registry_snapshot``)."""
    from vnav_graph.estimators.base import register, registry_snapshot

    with registry_snapshot():
        yield register
