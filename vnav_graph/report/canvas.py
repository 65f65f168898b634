"""Figure plumbing shared by the plots: Agg figure and PNG, decimation, shaded windows, and
the time axis (continuous, or broken to show only the withheld windows of a real log).

Matplotlib is imported inside the functions (``matplotlib.figure.Figure`` with the Agg canvas,
never pyplot), so importing this module costs nothing.
"""

from __future__ import annotations

import io
from collections.abc import Sequence
from typing import Any

import numpy as np

from ..types.streams import FloatArray

DPI = 150  # 11 in wide figures: 1650 px
MAX_POINTS = 1500
SHADE = "0.86"
SHADE_LIGHT = "0.93"  # the broken axis shows only windows: shading is everywhere, keep it pale
# gap drawn between two windows on a broken axis, as a fraction of the total window length
BREAK_FRACTION = 0.04


def figure(w: float, h: float, left: float = 0.08, wspace: float = 0.12,
           right: float = 0.98, bottom_in: float = 0.55, top_in: float = 0.75) -> Any:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    # fixed margins instead of constrained layout: the layout solver cost ~1 s per figure
    fig = Figure(figsize=(w, h), dpi=DPI)
    FigureCanvasAgg(fig)
    fig.subplots_adjust(left=left, right=right, bottom=bottom_in / h, top=1.0 - top_in / h,
                        hspace=0.55, wspace=wspace)
    return fig


def png(fig: Any) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI)
    return buf.getvalue()


def decimate(n: int, max_points: int = MAX_POINTS) -> slice:
    """Stride slice keeping at most ``max_points`` of ``n`` samples."""
    return slice(None, None, max(1, int(np.ceil(n / max_points))))


class TimeAxis:
    """x = time [s]; ``windows`` are shaded (simulated GNSS outages)."""

    broken = False

    def __init__(self, windows: Sequence[tuple[float, float]], label: str) -> None:
        self.windows = list(windows)
        self.label = label

    def map(self, t: FloatArray, *ys: FloatArray | None) -> tuple[FloatArray, ...]:
        s = decimate(t.size)
        return (t[s], *(None if y is None else y[s] for y in ys))

    def decorate(self, ax: Any, legend: bool = False) -> None:
        for k, (a, b) in enumerate(self.windows):
            ax.axvspan(a, b, color=SHADE, zorder=0,
                       label=self.label if legend and k == 0 else None)

    def xlabel(self, short: bool = False) -> str:
        return "time [s]"


class WindowAxis:
    """x = time inside the windows only, windows laid side by side with a short break between
    them (a real log's withheld windows: the only epochs with a score). Each window is shaded;
    a tick at each window's start gives its true time [s]."""

    broken = True

    def __init__(self, windows: Sequence[tuple[float, float]], label: str) -> None:
        self.windows = list(windows)
        self.label = label
        total = sum(b - a for a, b in self.windows) or 1.0
        self.gap = BREAK_FRACTION * total
        self.offsets = []
        x = 0.0
        for a, b in self.windows:
            self.offsets.append(x)
            x += (b - a) + self.gap

    def map(self, t: FloatArray, *ys: FloatArray | None) -> tuple[FloatArray, ...]:
        """Samples inside the windows, shifted onto the broken axis; a NaN between windows
        breaks the lines."""
        xs: list[FloatArray] = []
        cols: list[list[FloatArray]] = [[] for _ in ys]
        for (a, b), off in zip(self.windows, self.offsets, strict=True):
            m = (t >= a) & (t <= b)
            if not m.any():
                continue
            xs += [t[m] - a + off, np.array([np.nan])]
            for c, y in zip(cols, ys, strict=True):
                if y is not None:
                    c += [y[m], np.array([np.nan])]
        if not xs:
            return (np.empty(0), *(None if y is None else np.empty(0) for y in ys))
        x = np.concatenate(xs)
        s = decimate(x.size)
        return (x[s], *(None if y is None else np.concatenate(c)[s]
                        for c, y in zip(cols, ys, strict=True)))

    def decorate(self, ax: Any, legend: bool = False) -> None:
        ticks, labels = [], []
        for k, ((a, b), off) in enumerate(zip(self.windows, self.offsets, strict=True)):
            ax.axvspan(off, off + b - a, color=SHADE_LIGHT, zorder=0,
                       label=self.label if legend and k == 0 else None)
            if k:
                ax.axvline(off - self.gap / 2, color="0.3", lw=0.8, ls=(0, (2, 2)))
            ticks.append(off)
            labels.append(f"{a:.0f}")
        if ticks:
            ax.set_xticks(ticks, labels)
            ax.set_xlim(-self.gap / 2, self.offsets[-1] + self.windows[-1][1]
                        - self.windows[-1][0] + self.gap / 2)

    def xlabel(self, short: bool = False) -> str:
        if short:
            return "time [s] at window start"
        lengths = sorted({round(b - a) for a, b in self.windows})
        return (f"time [s] (tick: window start); only the withheld windows "
                f"({'/'.join(str(x) for x in lengths)} s each), axis broken between them")
