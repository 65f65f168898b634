"""vnav_graph — INS / GNSS / barometric-altimeter navigation.

A GTSAM factor-graph smoother (iSAM2 and batch), a reference error-state EKF (+ RTS) and the
classical baro-inertial loops and vertical filters of the seed papers, all on one set of
sensor models, compared on equal terms.

Conventions
-----------
- One clock, seconds. SI units, radians; non-SI only at I/O boundaries with a suffix
  (``_deg``, ``_hpa``).
- Frames: ``n`` local-level NED (tangent-plane NED at ``Drive.origin_lla`` for ``pos_n``),
  ``b`` body/IMU forward-right-down, ``e`` ECEF. Suffix = frame of resolution (``vel_n``,
  ``gyro_b``). ``q_nb`` (w, x, y, z) maps b into n.
- ``alt`` is ellipsoidal height, +up; ``down`` is +down.
- Barometer model (``vnav_graph.sensors.baro``):
  h_b − h0 = (1 + s)·(h(t − τd) − h0) + b(t) + v, b first-order Gauss-Markov,
  h0 = drive-origin height.

Python API
----------
``load_drive(path)`` (npz or real log) and ``simulate(scenario, seed)`` give a ``Drive``;
``create(name, config)`` builds an estimator (``available()`` lists the names, ``register``
adds one); ``estimator.run(drive)`` returns an ``Estimate`` (``Estimate.to_dataframe()``);
``evaluate(estimate, drive)`` scores it (the metric block of ``summary.json``). The names
are imported on first use, so ``import vnav_graph`` stays light (no scipy, numba or gtsam).
"""

import importlib as _importlib
from typing import Any as _Any

from .util.jit import configure_cache as _configure_cache  # noqa: E402
from .util.jit import configure_locator as _configure_locator  # noqa: E402
from .util.jit import configure_opt as _configure_opt  # noqa: E402
from .version import __version__

_configure_cache()  # numba's cache in the user cache dir, never inside the installed package
_configure_locator()  # kernels cached by content and package path, not install path
_configure_opt()  # LLVM level 2 unless NUMBA_OPT is set (jit.NUMBA_OPT_LEVEL: faster compile)

# The public API, imported on first access (PEP 562) so that ``import vnav_graph`` (and with it
# ``vnav-graph --help``) does not load numpy's heavy friends: scipy, numba, gtsam.
# name -> "module:attribute".
_LAZY: dict[str, str] = {
    # data in
    "load_drive": "vnav_graph.io:load_drive",
    "simulate": "vnav_graph.simulation:simulate",
    # estimators (the registry of docs/design.md names)
    "create": "vnav_graph.estimators.base:create",
    "available": "vnav_graph.estimators.base:available",
    "register": "vnav_graph.estimators.base:register",
    # scoring: the per-estimator metric block of summary.json
    "evaluate": "vnav_graph.evaluation.metrics:evaluate",
    # core types
    "ERROR_STATE": "vnav_graph.types:ERROR_STATE",
    "BaroStream": "vnav_graph.types.streams:BaroStream",
    "Drive": "vnav_graph.types:Drive",
    "Estimate": "vnav_graph.types:Estimate",
    "GnssStream": "vnav_graph.types.streams:GnssStream",
    "ImuStream": "vnav_graph.types.streams:ImuStream",
    "Trajectory": "vnav_graph.types:Trajectory",
}

__all__ = [*_LAZY, "__version__"]


def __getattr__(name: str) -> _Any:
    target = _LAZY.get(name)
    if target is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    mod, _, attr = target.partition(":")
    value = getattr(_importlib.import_module(mod), attr)
    globals()[name] = value  # cache: later accesses skip __getattr__
    return value


def __dir__() -> list[str]:
    return sorted({*(n for n in globals() if not n.startswith("_")), *_LAZY, "__version__"})
