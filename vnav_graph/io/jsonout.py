"""Strict JSON for every file the package writes (summary.json, holdout.json).

``json.dumps`` writes ``NaN`` and ``Infinity`` by default, which are not JSON: a NaN in a
drive's truth once made ``summary.json`` unreadable by strict parsers. Non-finite numbers
become ``null`` (docs/design.md: metrics that do not apply are null).
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np


def strict_json(obj: Any) -> Any:
    """``obj`` with every non-finite float (NaN, ±inf; numpy scalars too) replaced by None,
    numpy scalars and arrays turned into Python values, so that
    ``json.dumps(..., allow_nan=False)`` writes strict JSON (NaN is not a JSON literal)."""
    if isinstance(obj, dict):
        return {str(k): strict_json(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [strict_json(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return strict_json(obj.tolist())
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        return float(obj) if np.isfinite(obj) else None
    return obj


def dumps_strict(obj: Any, indent: int | None = 2) -> str:
    """Strict JSON text of ``obj`` (:func:`strict_json`; ValueError on anything left over)."""
    return json.dumps(strict_json(obj), indent=indent, allow_nan=False)
