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


class MissingStream(ValueError):
    """An estimator needs a stream the drive does not have (e.g. no barometer).

    Not a failure: a vehicle without a barometer is a valid input, the estimators that need
    one cannot run on it. ``vnav_graph.run.runner`` reports them with ``status: "skipped"`` and
    ``reason`` (``"no barometer"``) instead of ``"failed"``. A ``ValueError``, so that a
    direct ``estimator.run(drive)`` caller sees the same exception type as before.
    """

    def __init__(self, stream: str, message: str) -> None:
        super().__init__(message)
        self.stream = stream

    @property
    def reason(self) -> str:
        return f"no {self.stream}"


class ExtensionError(ValueError):
    """A graph extension (user code handed to a smoother) is malformed: a factor on an unknown
    key, a reserved letter, a Jacobian of the wrong shape, ... The message names the
    extension.

    Bad input, not an estimator failure: ``vnav_graph.run.runner`` lets it through, so ``run`` and
    ``holdout`` stop with the one-line error and exit 2 instead of reporting the variant
    ``failed`` (or, for a wrong Jacobian shape, GTSAM crashing the process). A bench worker
    never raises: its row is ``failed`` with this error.
    """
