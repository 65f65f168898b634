"""The estimator interface and the registry.

Every estimator is constructed from its config and has one call, ``run(drive) -> Estimate``.
The registry maps DESIGN.md names to ``"module:factory"`` strings and imports lazily, so a
heavy dependency (gtsam) is only loaded when its estimator runs, and a research extension
can register its own estimator with ``register``.
"""

from __future__ import annotations

import importlib
import importlib.util
from collections.abc import Callable
from typing import Any, Protocol

from ..types import Drive, Estimate


class Estimator(Protocol):
    name: str

    def run(self, drive: Drive) -> Estimate: ...


# name -> "module:attribute" of a callable(config | None) -> Estimator, in report order.
_REGISTRY: dict[str, str | Callable[..., Estimator]] = {}
_CORE: dict[str, str] = {
    "observer1d": "vnav_graph.estimators.observer1d:Observer1D",
    "loop2": "vnav_graph.estimators.loops:Loop2",
    "loop3": "vnav_graph.estimators.loops:Loop3",
    "loop3-adaptive": "vnav_graph.estimators.adaptive:AdaptiveLoop3",
    "vkf4": "vnav_graph.estimators.vkf4:VKF4",
    "vekf7": "vnav_graph.estimators.vekf7:VEKF7",
    "ekf": "vnav_graph.estimators.ekf:EKF",
    "ekf-rts": "vnav_graph.estimators.ekf:EKFRTS",
    "graph-isam2": "vnav_graph.estimators.graph:GraphISAM2",
    "graph-batch": "vnav_graph.estimators.graph:GraphBatch",
}


def register(name: str, factory: str | Callable[..., Estimator]) -> None:
    """Register an estimator factory (``"pkg.module:Class"`` or a callable) under ``name``."""
    _REGISTRY[name] = factory


def _resolve(spec: str | Callable[..., Estimator]) -> Callable[..., Estimator] | None:
    if callable(spec):
        return spec
    mod, _, attr = spec.partition(":")
    try:
        m = importlib.import_module(mod)
    except ModuleNotFoundError as exc:
        if exc.name == mod:  # the estimator's module does not exist yet in this build
            return None
        raise
    return getattr(m, attr, None)


def _present(spec: str | Callable[..., Estimator]) -> bool:
    """Whether a factory exists, without importing its module (``vnav-graph list`` stays fast:
    importing the graph would load gtsam)."""
    if callable(spec):
        return True
    mod = spec.partition(":")[0]
    try:
        return importlib.util.find_spec(mod) is not None
    except ModuleNotFoundError:  # a parent package is missing
        return False


def available() -> list[str]:
    """Names of the estimators implemented in this build, in report order."""
    return [name for name, spec in {**_CORE, **_REGISTRY}.items() if _present(spec)]


def create(name: str, config: Any = None) -> Estimator:
    """Instantiate the estimator registered as ``name`` (ValueError if unknown)."""
    spec = _REGISTRY.get(name, _CORE.get(name))
    factory = None if spec is None else _resolve(spec)
    if factory is None:
        raise ValueError(f"unknown estimator {name!r} (available: {', '.join(available())})")
    return factory(config) if config is not None else factory()
