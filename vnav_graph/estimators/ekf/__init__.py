"""The reference EKF family: ``ekf`` (forward, 21-state error-state filter) and ``ekf-rts``
(the same pass plus a Rauch-Tung-Striebel smoother).

Modules: ``filter`` (set-up from the shared sensor model, the estimators, RTS output),
``inputs`` (grids, process noise, event list), ``model`` (the compiled error-state model and
forward kernel), ``strapdown`` (mechanisation), ``alignment`` (static levelling window,
heading from the GNSS track). The public names are
imported on first use, so that ``import vnav_graph.estimators.ekf`` compiles nothing.
"""

from __future__ import annotations

from typing import Any

__all__ = ["EKF", "EKFRTS", "EkfConfig"]


def __getattr__(name: str) -> Any:
    if name in __all__:
        from . import filter as _filter

        return getattr(_filter, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
