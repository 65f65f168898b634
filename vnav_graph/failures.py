"""One line that says why an exception was raised (``failure_message``).

Every place that turns an exception into text for a user — an estimator's ``error`` in
``summary.json``, a bench row, the CLI's one-line error — uses this, so that no message is
empty: an exception raised without text (``RuntimeError()``) is named by its type and the
place it was raised.
"""

from __future__ import annotations

import traceback
from pathlib import Path


def failure_message(exc: BaseException, typed: bool = False) -> str:
    """The first non-blank line of ``str(exc)``; ``typed`` puts the exception type in front
    (``"RuntimeError: solver stalled"``).

    When ``str(exc)`` has no text, the exception type and the innermost frame of its
    traceback: ``"RuntimeError (no message; raised at solve.py:120 in step)"``. Never empty.
    """
    kind = type(exc).__name__
    for line in str(exc).splitlines():
        if line.strip():
            return f"{kind}: {line}" if typed else line
    where = ""
    frames = traceback.extract_tb(exc.__traceback__) if exc.__traceback__ else []
    if frames:
        f = frames[-1]
        where = f"; raised at {Path(f.filename).name}:{f.lineno} in {f.name}"
    return f"{kind} (no message{where})"
