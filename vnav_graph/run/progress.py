"""Progress on stderr for every step that can take more than a couple of seconds.

Three modes (``mode_for``): ``"bar"`` — a tqdm bar when stderr is a terminal; ``"lines"`` —
one plain, flushed line per step when it is not (CI logs, ``nohup``, pipes), so a long run is
never silent; ``"off"`` — nothing (``--no-progress``). Results still go to stdout; progress
never does.
"""

from __future__ import annotations

import os
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from typing import Any, Literal, TypeVar

Mode = Literal["bar", "lines", "off"]
T = TypeVar("T")


def mode_for(enabled: bool = True, stream: Any = None) -> Mode:
    """``"off"`` when disabled, ``"bar"`` on a terminal, else ``"lines"``."""
    if not enabled:
        return "off"
    stream = sys.stderr if stream is None else stream
    isatty = getattr(stream, "isatty", None)
    return "bar" if isatty is not None and isatty() else "lines"


def say(msg: str, mode: Mode, stream: Any = None) -> None:
    """One progress line (``vnav-graph: msg``) unless progress is off (to ``stream``, default
    ``sys.stderr``)."""
    if mode != "off":
        print(f"vnav-graph: {msg}", file=sys.stderr if stream is None else stream, flush=True)


def _terminal_stderr() -> Any:
    """A writer on a duplicate of the current standard-error descriptor, or None when stderr
    has no descriptor (a test's capture object). A step's delayed announcement is written
    there, so that it reaches the terminal even when the step itself captures descriptors 1
    and 2 (``io.quiet`` around a log reader) and is never counted as the reader's output."""
    try:
        return os.fdopen(os.dup(sys.stderr.fileno()), "w", buffering=1)
    except (OSError, ValueError, AttributeError):
        return None


@contextmanager
def stage(msg: str, mode: Mode, announce_after_s: float = 1.0) -> Iterator[None]:
    """Announce a step (``msg ...``) once it has run ``announce_after_s`` and, then, how long it
    took. Steps that end sooner stay silent, so a bad input fails with its one error line."""
    if mode == "off":
        yield
        return
    t0 = time.perf_counter()
    out = _terminal_stderr()
    timer = threading.Timer(announce_after_s, say, (f"{msg} ...", mode, out))
    timer.daemon = True
    timer.start()
    try:
        yield
    finally:
        timer.cancel()
        timer.join()
        if out is not None:
            out.close()
    if time.perf_counter() - t0 >= announce_after_s:
        say(f"{msg}: done in {time.perf_counter() - t0:.1f} s", mode)


def steps(items: Iterable[T], desc: str, mode: Mode, total: int | None = None,
          label: Callable[[T], str] = str) -> Iterator[T]:
    """Iterate ``items`` with a bar (``"bar"``), a line per item (``"lines"``) or silently."""
    seq = list(items)
    n = len(seq) if total is None else total
    if mode == "bar":
        from tqdm import tqdm

        bar = tqdm(seq, desc=desc, total=n, unit="step", leave=False, file=sys.stderr)
        for item in bar:
            bar.set_postfix_str(label(item))
            yield item
        bar.close()
        return
    t0 = time.perf_counter()
    for k, item in enumerate(seq, 1):
        say(f"{desc} [{k}/{n}] {label(item)} (elapsed {time.perf_counter() - t0:.0f} s)", mode)
        yield item


class Counter:
    """Progress over ``total`` units completed out of order (pool futures): ``update(label)``."""

    def __init__(self, total: int, desc: str, mode: Mode) -> None:
        self.total, self.desc, self.mode, self.done = total, desc, mode, 0
        self._t0 = time.perf_counter()
        self._bar = None
        if mode == "bar":
            from tqdm import tqdm

            self._bar = tqdm(total=total, desc=desc, unit="run", leave=False, file=sys.stderr)

    def update(self, label: str = "") -> None:
        self.done += 1
        if self._bar is not None:
            self._bar.update(1)
        else:
            say(f"{self.desc} [{self.done}/{self.total}] {label} "
                f"(elapsed {time.perf_counter() - self._t0:.0f} s)", self.mode)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()
