"""Memory pages of numpy's large temporaries (``small_pages``), shared by every estimator."""

from __future__ import annotations

import threading
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import numpy as np

_HUGEPAGE_LOCK = threading.Lock()
_HUGEPAGE_USERS = 0
_HUGEPAGE_PREVIOUS = True


def numpy_hugepage_setter() -> Any:
    """numpy's ``_set_madvise_hugepage`` (``numpy._core`` from 2.0, ``numpy.core`` before), or
    None."""
    core = getattr(np, "_core", None)
    if core is None:  # numpy 1.x (np.core is deprecated from 2.0 on: only touched here)
        core = getattr(np, "core", None)
    return getattr(getattr(core, "multiarray", None), "_set_madvise_hugepage", None)


@contextmanager
def small_pages() -> Iterator[None]:
    """Context in which numpy does not ask the kernel for transparent huge pages
    (``madvise(MADV_HUGEPAGE)``, numpy's default for buffers of ≥ 4 MiB on Linux); the
    previous setting comes back when the last nested or concurrent user leaves.

    The solvers allocate tens of fresh arrays of 10–50 MB per Gauss-Newton iteration (rows,
    Jacobians, band storage). Where the kernel defragments on a huge-page fault
    (``/sys/kernel/mm/transparent_hugepage/defrag`` = ``madvise``, the common default), every
    first touch of such an array waits for memory compaction: on this machine the first
    1-hour graph-batch solve in a process took 2.2–2.5 s (0.9 s of it in the kernel) with huge
    pages and 1.6–1.7 s (0.2 s) without; warm, 1.6–1.9 s against 1.5–1.6 s
    (``docs/graph_performance.md``). GTSAM's C++ allocations never ask for huge pages. Every
    estimator runs inside it (the ekf's first 1-hour run: 3.2 → 2.3 s). A no-op where numpy
    has no such switch."""
    global _HUGEPAGE_USERS, _HUGEPAGE_PREVIOUS
    setter = numpy_hugepage_setter()
    if setter is None:
        yield
        return
    with _HUGEPAGE_LOCK:
        if _HUGEPAGE_USERS == 0:
            _HUGEPAGE_PREVIOUS = bool(setter(False))
        _HUGEPAGE_USERS += 1
    try:
        yield
    finally:
        with _HUGEPAGE_LOCK:
            _HUGEPAGE_USERS -= 1
            if _HUGEPAGE_USERS == 0:
                setter(_HUGEPAGE_PREVIOUS)
