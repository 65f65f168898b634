"""Deterministic test-drive simulator.

``SCENARIO_DIR`` and ``list_scenarios`` need no numerics; ``simulate`` and ``load_scenario``
(``vnav_graph.simulation.scenario``) are imported on first use, so that listing scenarios
does not pull in scipy.
"""

from __future__ import annotations

import importlib
from pathlib import Path
from typing import Any

SCENARIO_DIR = Path(__file__).resolve().parent.parent / "scenarios"


def list_scenarios() -> list[str]:
    """Names of the scenarios shipped with the package (``vnav_graph/scenarios/*.toml``)."""
    return sorted(p.stem for p in SCENARIO_DIR.glob("*.toml"))


def scenario_description(name: str) -> str:
    """The one-line ``description`` of a shipped scenario ("" when it has none)."""
    import tomllib

    return str(tomllib.loads((SCENARIO_DIR / f"{name}.toml").read_text()).get("description",
                                                                               ""))


def __getattr__(name: str) -> Any:
    if name in ("load_scenario", "simulate"):
        return getattr(importlib.import_module(".scenario", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = ["SCENARIO_DIR", "list_scenarios", "load_scenario", "simulate"]
