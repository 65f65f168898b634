"""Deterministic test-drive simulator."""

from .scenario import SCENARIO_DIR, list_scenarios, load_scenario, simulate

__all__ = ["SCENARIO_DIR", "list_scenarios", "load_scenario", "simulate"]
