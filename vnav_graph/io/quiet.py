"""Run a reader with the parsing libraries' chatter captured, counted and summarised.

pymavlink prints "bad header" once per damaged record (345,555 lines on one corrupt log),
partly from its C index builder straight to file descriptor 1, and numpy, pandas and
dateutil warn on odd values. :func:`quietly` captures, while the call runs, file descriptors
1 and 2 (C and Python output alike; C stdio buffers are flushed before they are restored),
Python-level ``sys.stdout``/``sys.stderr`` and every ``warnings`` message; the caller turns
the count and the first distinct messages into one ``meta["warnings"]`` line.
"""

from __future__ import annotations

import contextlib
import io
import os
import sys
import tempfile
import warnings
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any, TypeVar

T = TypeVar("T")
MAX_EXAMPLES = 3


@dataclass
class Captured:
    """What a call printed or warned: total count and the first distinct messages."""

    count: int = 0
    examples: list[str] = field(default_factory=list)

    def add(self, msg: str) -> None:
        msg = msg.strip()
        if not msg:
            return
        self.count += 1
        if len(self.examples) < MAX_EXAMPLES and msg[:120] not in self.examples:
            self.examples.append(msg[:120])

    def summary(self) -> str:
        ex = "; ".join(repr(e) for e in self.examples)
        return (f"reader: {self.count} message(s) from the parsing libraries suppressed "
                f"(e.g. {ex})")


def _flush_c_stdio() -> None:
    try:
        import ctypes

        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError, TypeError):  # no libc handle (Windows): nothing buffered
        pass


@contextlib.contextmanager
def _fd_capture() -> Iterator[Any]:
    """Point file descriptors 1 and 2 at a temporary file for the duration."""
    for s in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            s.flush()
    _flush_c_stdio()
    tmp = tempfile.TemporaryFile()
    saved = {}
    done = False
    try:
        for fd in (1, 2):
            try:
                saved[fd] = os.dup(fd)
            except OSError:  # descriptor closed (daemonised caller): leave it alone
                continue
            os.dup2(tmp.fileno(), fd)
        yield tmp
        done = True
    finally:
        _flush_c_stdio()
        for fd, old in saved.items():
            os.dup2(old, fd)
            os.close(old)
        if not done:
            # the caller reads and closes it on success; after an exception nobody would, and
            # the garbage collector's "ResourceWarning: unclosed file" then landed in the
            # warnings of whatever ran next (an estimator's info["warnings"])
            tmp.close()


def quietly(fn: Callable[..., T], *args: Any, **kwargs: Any) -> tuple[T, Captured]:
    """``fn(*args, **kwargs)`` with printed output and warnings captured (see module doc).

    Exceptions propagate unchanged; what was captured before one is discarded.
    """
    out, err = io.StringIO(), io.StringIO()
    cap = Captured()
    with _fd_capture() as raw, warnings.catch_warnings(record=True) as rec, \
            contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        warnings.simplefilter("always")
        result = fn(*args, **kwargs)
    raw.seek(0)
    text = raw.read().decode("utf-8", errors="replace")
    raw.close()
    for line in (text + "\n" + out.getvalue() + "\n" + err.getvalue()).splitlines():
        cap.add(line)
    for w in rec:
        cap.add(f"{w.category.__name__}: {w.message}")
    return result, cap
