"""'Did you mean' for a misspelled name (estimator, scenario, export format, config key)."""

from __future__ import annotations

import difflib
from collections.abc import Iterable


def did_you_mean(word: str, choices: Iterable[str]) -> str:
    """``" (did you mean 'ekf-rts'?)"`` for the closest of ``choices``, or "" if none is
    close (difflib's ratio ≥ 0.6)."""
    close = difflib.get_close_matches(word, list(choices), n=1)
    return f" (did you mean {close[0]!r}?)" if close else ""
