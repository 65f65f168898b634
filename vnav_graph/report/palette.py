"""One colour per estimator, the same in every figure of the report and in the KML export.

Matplotlib's ``tab10`` colours, assigned by the estimator's place in the core registry; an
extension estimator gets a colour from its name (stable across runs), truth is black.
"""

from __future__ import annotations

import zlib

TAB10 = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd",
         "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22", "#17becf")
TRUTH_COLOR = "#000000"

_CORE_ORDER = ("observer1d", "loop2", "loop3", "loop3-adaptive", "vkf4", "vekf7", "ekf",
               "ekf-rts", "graph-isam2", "graph-batch")


def estimator_color(name: str) -> str:
    """The ``#rrggbb`` colour the report and the exports draw ``name`` in."""
    if name == "truth":
        return TRUTH_COLOR
    if name in _CORE_ORDER:
        return TAB10[_CORE_ORDER.index(name)]
    return TAB10[zlib.crc32(name.encode()) % len(TAB10)]
