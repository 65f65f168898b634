"""One colour and line style per estimator, the same in every figure of the report (the
colour also in the KML export).

The core estimators have hand-picked pairs chosen so that no two members of one family (the
rows of the error figures: smoothers, filters, loops/observers) share a colour *or* a line
style, and no two estimators anywhere share both; an extension estimator gets a pair from
its name (stable across runs); truth is black and solid.
"""

from __future__ import annotations

import zlib
from typing import Any

TAB10 = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd",
         "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22", "#17becf")
TRUTH_COLOR = "#000000"
DASHES: dict[str, Any] = {"solid": "-", "dashed": (0, (6, 2)), "dashdot": (0, (7, 2, 1.5, 2)),
                          "dotted": (0, (1.5, 1.5))}

# name -> (colour, line style); family members differ in both
CORE_STYLES: dict[str, tuple[str, str]] = {
    "ekf-rts": ("#1f77b4", "solid"),         # blue
    "graph-batch": ("#2ca02c", "dashed"),    # green
    "graph-isam2": ("#ff7f0e", "dashdot"),   # orange
    "ekf": ("#d62728", "solid"),             # red
    "vekf7": ("#17becf", "dashed"),          # cyan
    "vkf4": ("#9467bd", "dashdot"),          # purple
    "observer1d": ("#8c564b", "solid"),      # brown
    "loop2": ("#e377c2", "dashed"),          # pink
    "loop3": ("#bcbd22", "dashdot"),         # olive
    "loop3-adaptive": ("#7f7f7f", "dotted"),  # grey
}


def _pair(name: str) -> tuple[str, str]:
    if name == "truth":
        return TRUTH_COLOR, "solid"
    if name in CORE_STYLES:
        return CORE_STYLES[name]
    h = zlib.crc32(name.encode())
    return TAB10[h % len(TAB10)], tuple(DASHES)[(h // len(TAB10)) % len(DASHES)]


def estimator_color(name: str) -> str:
    """The ``#rrggbb`` colour the report and the exports draw ``name`` in."""
    return _pair(name)[0]


def estimator_style(name: str) -> dict[str, Any]:
    """Matplotlib keyword arguments ``{"color", "ls"}`` of ``name``'s curves."""
    color, dash = _pair(name)
    return {"color": color, "ls": DASHES[dash]}
