"""One computation shared by the estimators of one run, with its time charged to each.

The six vertical estimators all start from the same GNSS-aided AHRS
(``estimators.vertical.inputs.vertical_inputs``): same drive, same default ``AhrsConfig``.
Inside ``runner.run_estimators`` it is computed once (:func:`sharing` block) and handed to
the others; its arrays are made read-only so that no estimator can change what another reads.

Runtimes stay honest: every estimator that reuses a result is charged the seconds that result
took to compute (compilation excluded), as if it had computed it itself. :meth:`Shared.take`
returns the seconds charged since the last call; ``runner.run_one`` adds them to the
estimator's ``runtime_s``. Python warnings raised while computing are raised again at every
reuse, so each estimator's ``info["warnings"]`` is the same as without sharing.

Outside a :func:`sharing` block (``create(name).run(drive)`` from Python) nothing is shared.
"""

from __future__ import annotations

import dataclasses
import time
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any, TypeVar

import numpy as np

from ...util.jit import CompileTimer

T = TypeVar("T")


@dataclasses.dataclass
class _Entry:
    tag: str
    drive: Any
    config: Any
    value: Any
    seconds: float
    warned: list[warnings.WarningMessage]


class Shared:
    """The results computed inside one :func:`sharing` block and the time charged for reuse."""

    def __init__(self) -> None:
        self.entries: list[_Entry] = []
        self.hits = 0
        self._charged = 0.0

    def take(self) -> float:
        """Seconds charged for reused results since the last call (then reset)."""
        s, self._charged = self._charged, 0.0
        return s


_active: Shared | None = None


@contextmanager
def sharing() -> Iterator[Shared]:
    """Within the block, :func:`shared_call` computes each (tag, drive, config) once."""
    global _active
    prev, _active = _active, Shared()
    try:
        yield _active
    finally:
        _active = prev


def _freeze(value: Any) -> None:
    """Make the array fields of a dataclass result read-only (shared between estimators)."""
    if dataclasses.is_dataclass(value):
        for f in dataclasses.fields(value):
            arr = getattr(value, f.name)
            if isinstance(arr, np.ndarray):
                arr.flags.writeable = False


def _replay(warned: list[warnings.WarningMessage]) -> None:
    for w in warned:
        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)


def shared_call(tag: str, drive: Any, config: Any, compute: Callable[[], T]) -> T:
    """``compute()``, or inside a :func:`sharing` block the result of the first call with the
    same ``tag``, the same ``drive`` object and an equal ``config`` (see module docstring)."""
    box = _active
    if box is None:
        return compute()
    for e in box.entries:
        if e.tag == tag and e.drive is drive and e.config == config:
            box.hits += 1
            box._charged += e.seconds
            _replay(e.warned)
            return e.value  # type: ignore[no-any-return]
    t0 = time.perf_counter()
    with CompileTimer() as jit, warnings.catch_warnings(record=True) as rec:
        warnings.simplefilter("always")
        value = compute()
    seconds = max(time.perf_counter() - t0 - jit.seconds, 0.0)
    _replay(rec)
    _freeze(value)
    box.entries.append(_Entry(tag, drive, config, value, seconds, list(rec)))
    return value
