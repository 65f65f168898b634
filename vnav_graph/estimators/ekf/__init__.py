"""The reference EKF family: ``ekf`` (forward error-state filter; 27 error states with the
GNSS error state) and ``ekf-rts`` (the same pass plus a Rauch-Tung-Striebel smoother).

Modules: ``settings`` (``EkfConfig``), ``filter`` (set-up from the shared sensor model, the
estimators, outputs), ``inputs`` (grids, process noise, the merged event list),
``alignment`` (levelling, start position), ``model`` (the compiled error-state model;
the filter is specified in docs/ekf.md), ``kernel`` (the forward pass), ``steps`` (prediction,
heading reset, delayed rows, shared gating), ``updates`` (everything per measurement kind:
records, event stamps, rows, gated updates, innovations and their report; a sensor is added
there), ``heading`` (heading acquisition), ``magnetometer`` (compass set-up), ``rts`` (the
smoother), ``carry`` (the acquired heading carried back), ``regate`` (post-smoothing gate),
``backward`` (the filter run backward, forward/backward separation). The public names are
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
