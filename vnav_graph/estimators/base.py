"""The estimator interface and the registry.

Every estimator is constructed from its config and has one call, ``run(drive) -> Estimate``.
The registry maps docs/design.md names to ``"module:factory"`` strings and imports lazily, so
a heavy dependency (gtsam) is only loaded when its estimator runs, and a research extension
can register its own estimator with ``register`` (from Python) or ``load_plugin`` (the CLI's
``--plugin module:Class``).
"""

from __future__ import annotations

import importlib
import importlib.util
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from ..types import Drive, Estimate, Trajectory
from ..util.failures import failure_message


class Estimator(Protocol):
    name: str

    def run(self, drive: Drive) -> Estimate: ...


# The three families of core estimators (report panels, headline): name, singular, members.
FAMILIES: tuple[tuple[str, str, tuple[str, ...]], ...] = (
    ("smoothers", "smoother", ("ekf-rts", "graph-batch", "graph-isam2")),
    ("filters", "filter", ("ekf", "vekf7", "vkf4")),
    ("loops and observers", "loop or observer",
     ("observer1d", "loop2", "loop3", "loop3-adaptive")),
)
OTHER_FAMILY = ("other", "other estimator")

# Estimators whose trajectory is causal (the state at t uses data up to t only): their
# ``Estimate.online`` is the trajectory itself (``with_online``). graph-isam2 returns its own
# online (and fixed-lag) estimate. The pure smoothers have no scored online estimate: ekf-rts's
# forward pass is the ekf row, and scoring it twice would rank one filter twice.
CAUSAL = frozenset({"observer1d", "loop2", "loop3", "loop3-adaptive", "vkf4", "vekf7", "ekf"})
PURE_SMOOTHERS = frozenset({"ekf-rts", "graph-batch"})


# one line per core estimator for ``vnav-graph list`` (the seed papers: README)
DESCRIPTIONS = {
    "observer1d": "1-DOF INS + GPS altitude observer, fixed gains (seed 003)",
    "loop2": "2nd-order baro-inertial damping loop, fixed gains",
    "loop3": "3rd-order baro-inertial damping loop, fixed gains",
    "loop3-adaptive": "3rd-order loop with adaptive gains (seed 000)",
    "vkf4": "4-state baro-inertial Kalman filter (seed 004)",
    "vekf7": "7-state vertical EKF with baro scale, latency and bias (seed 001)",
    "ekf": "full INS/GNSS/baro error-state EKF (forward filter, real time)",
    "ekf-rts": "the same EKF followed by a Rauch-Tung-Striebel smoother",
    "graph-isam2": "GTSAM factor graph, incremental (iSAM2)",
    "graph-batch": "GTSAM factor graph, full-batch smoothing of the whole drive",
}


def describe(name: str) -> str:
    """One line saying what the estimator is: the core ones from ``DESCRIPTIONS``, an
    extension from the first line of its class docstring ("extension estimator" without)."""
    if name in DESCRIPTIONS:
        return DESCRIPTIONS[name]
    try:
        doc = (type(create(name)).__doc__ or "").strip().splitlines()
    except Exception:  # a broken extension: list still lists it; run reports the error
        doc = []
    return f"extension: {doc[0]}" if doc else "extension estimator"


def family_order(names: list[str]) -> list[str]:
    """``names`` in the one row order of every table and figure: smoothers, filters, loops and
    observers (each in ``FAMILIES`` order), then any other estimator in the order given."""
    known = [n for _, _, members in FAMILIES for n in members if n in names]
    return known + [n for n in names if n not in known]


def family_of(name: str) -> tuple[str, str]:
    """(family, its singular) of an estimator name; ``OTHER_FAMILY`` for an extension."""
    return next(((f, one) for f, one, members in FAMILIES if name in members), OTHER_FAMILY)


# name -> "module:attribute" of a callable(config | None) -> Estimator, in report order.
_REGISTRY: dict[str, str | Callable[..., Estimator]] = {}
_CORE: dict[str, str] = {
    "observer1d": "vnav_graph.estimators.vertical.observer1d:Observer1D",
    "loop2": "vnav_graph.estimators.vertical.loops:Loop2",
    "loop3": "vnav_graph.estimators.vertical.loops:Loop3",
    "loop3-adaptive": "vnav_graph.estimators.vertical.adaptive:AdaptiveLoop3",
    "vkf4": "vnav_graph.estimators.vertical.vkf4:VKF4",
    "vekf7": "vnav_graph.estimators.vertical.vekf7:VEKF7",
    "ekf": "vnav_graph.estimators.ekf.filter:EKF",
    "ekf-rts": "vnav_graph.estimators.ekf.filter:EKFRTS",
    "graph-isam2": "vnav_graph.estimators.graph:GraphISAM2",
    "graph-batch": "vnav_graph.estimators.graph:GraphBatch",
}


def register(name: str, factory: str | Callable[..., Estimator]) -> None:
    """Register an estimator factory (``"pkg.module:Class"`` or a callable) under ``name``."""
    _REGISTRY[name] = factory


@contextmanager
def registry_snapshot() -> Iterator[None]:
    """Registrations (``register``, ``load_plugin``) made inside the block are undone when it
    ends: a test's or a notebook's temporary estimators leave the registry as it was."""
    saved = dict(_REGISTRY)
    try:
        yield
    finally:
        _REGISTRY.clear()
        _REGISTRY.update(saved)


def registered_factories() -> dict[str, str | Callable[..., Estimator]]:
    """The estimators registered at run time (``register``, ``load_plugin``): name → factory
    (a bench task carries its factory so that a worker process can register it again)."""
    return dict(_REGISTRY)


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
        from ..util.suggest import did_you_mean

        raise ValueError(f"unknown estimator {name!r}{did_you_mean(name, available())} "
                         f"(available: {', '.join(available())})")
    return factory(config) if config is not None else factory()


def load_plugin(spec: str) -> str:
    """Import an extension estimator and register it; returns the name it is registered under.

    ``spec`` is ``[NAME=]MODULE:ATTR``: ``MODULE`` an importable module or a ``.py`` file
    (its folder is put on ``sys.path`` and it is imported under its file name), ``ATTR`` a
    class or factory taking an optional config, as for ``register``. Without ``NAME=`` the
    name is ``ATTR.name``. The factory is registered as the ``"module:attr"`` string, so the
    bench's worker processes can import it again. A malformed spec, a module or attribute
    that does not import, or a name that is a built-in estimator is a one-line ValueError.
    """
    name, sep, target = spec.rpartition("=")
    mod, _, attr = target.rpartition(":")
    if (sep and not name) or not mod or not attr or not attr.isidentifier():
        raise ValueError(f"--plugin {spec!r}: expected [NAME=]MODULE:CLASS "
                         "(e.g. mypkg.estimators:MyEstimator)")
    path = Path(mod).resolve() if mod.endswith(".py") else None
    if path is not None:
        if not path.is_file():
            raise ValueError(f"--plugin {spec!r}: no such file: {mod}")
        if str(path.parent) not in sys.path:
            sys.path.append(str(path.parent))
        mod = path.stem
    try:
        module = importlib.import_module(mod)
    except Exception as exc:  # whatever the plugin raises on import: one line, exit 2
        raise ValueError(f"--plugin {spec!r}: cannot import {mod}: "
                         f"{failure_message(exc, typed=True)}") from None
    if path is not None and Path(getattr(module, "__file__", "") or "").resolve() != path:
        raise ValueError(f"--plugin {spec!r}: module name {mod!r} is taken by "
                         f"{module.__file__}; rename the file")
    factory = getattr(module, attr, None)
    if not callable(factory):
        raise ValueError(f"--plugin {spec!r}: {mod} has no class or factory {attr!r}")
    if not name:
        name = getattr(factory, "name", None)
        if not isinstance(name, str) or not name:
            raise ValueError(f"--plugin {spec!r}: {attr} has no string 'name' attribute; "
                             f"give one as NAME={target}")
    if name in _CORE:
        raise ValueError(f"--plugin {spec!r}: {name!r} is a built-in estimator; "
                         f"register it under another name (NAME={target})")
    register(name, f"{mod}:{attr}")
    return name


def _take(tr: Trajectory, idx: np.ndarray) -> Trajectory:
    def k(a: np.ndarray | None) -> np.ndarray | None:
        return None if a is None else a[idx]

    return Trajectory(tr.t[idx], tr.lla[idx], tr.vel_n[idx], k(tr.q_nb), k(tr.bias_gyro),
                      k(tr.bias_accel), k(tr.bias_baro))


def with_online(name: str, est: Estimate) -> Estimate:
    """``est`` with its causal estimate filled in for a ``CAUSAL`` estimator that left
    ``online`` empty (others are returned unchanged).

    - ``online`` is the trajectory from ``info["online_from_s"]`` on: the ekf's alignment reads
      the levelling window and its first fixes, so its states before the last of them are not
      causal (a real-time filter has no output before it is aligned); from the drive's start
      when the estimator does not say.
    - With a covariance, ``online`` is the trajectory at the covariance epochs (every one of
      them is a trajectory epoch: the states are taken, not interpolated) and ``online_cov``
      the covariance there; a covariance epoch that is not a trajectory epoch leaves
      ``online_cov`` None (the online block's NEES is then null).
    """
    if name not in CAUSAL or est.online is not None:
        return est
    tr = est.trajectory
    t_from = est.info.get("online_from_s")
    keep = np.ones(tr.t.size, dtype=bool) if t_from is None else tr.t >= float(t_from)
    cov = None
    if est.cov is not None and est.t_cov is not None:
        j = np.clip(np.searchsorted(tr.t, est.t_cov), 0, tr.t.size - 1)
        if np.all(tr.t[j] == est.t_cov):
            use = keep[j]
            keep = np.zeros(tr.t.size, dtype=bool)
            keep[j[use]] = True
            cov = est.cov[use]
    idx = np.flatnonzero(keep)
    if idx.size == 0:
        return est
    online = tr if idx.size == tr.t.size else _take(tr, idx)
    return est.replace(online=online, online_cov=cov)
