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
"""

from __future__ import annotations

import importlib
from typing import Any

from .jit import configure_cache

__version__ = "0.1.0"

configure_cache()  # numba's cache in the user cache dir, never inside the package

# Public names, imported on first use so that ``import vnav_graph`` (and ``vnav-graph --help``)
# does not pull in scipy, numba or gtsam.
_LAZY = {
    "ERROR_STATE": "vnav_graph.types", "BaroStream": "vnav_graph.types",
    "Drive": "vnav_graph.types", "Estimate": "vnav_graph.types",
    "GnssStream": "vnav_graph.types", "ImuStream": "vnav_graph.types",
    "Trajectory": "vnav_graph.types",
    "simulate": "vnav_graph.simulation",
}
__all__ = [*_LAZY, "__version__"]


def __getattr__(name: str) -> Any:
    mod = _LAZY.get(name)
    if mod is None:
        raise AttributeError(f"module 'vnav_graph' has no attribute {name!r}")
    value = getattr(importlib.import_module(mod), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))
