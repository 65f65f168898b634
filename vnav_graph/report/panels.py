"""One error quantity drawn a panel per estimator, a row per family, with its ±3σ lines.

The altitude, horizontal and heading error figures share this layout
(:func:`plot_family_panels`): the families of :mod:`vnav_graph.report.groups` are the rows,
the y-scale is shared per row (``groups.robust_limits``), and the estimator's own ±3σ is drawn
as two thin dashed lines, never a filled band:

- a line is drawn only where it lies inside the axis (``sigma_inside``): a σ of tens of metres
  beside errors of one (a real log's filters) leaves the panel readable instead of filling it;
- the fraction of the time it is beyond the axis is given under the panel title when it exceeds
  ``SIGMA_NOTE_ABOVE``, and in full in the figure's notes (the caption);
- the lines are blue and dashed, the shading of the GNSS-outage / withheld windows grey and
  filled, so the two cannot be taken for one another.

A non-negative quantity (the horizontal error's norm) has the axis [0, L] and one +3σ line.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..types.streams import FloatArray
from . import canvas
from .errors import GIVEN, TRUTH, ErrorSeries, ErrorSet
from .groups import group_names, robust_limits

# the σ fraction beyond the axis above which the panel and the caption say so
SIGMA_NOTE_ABOVE = 0.05
SIGMA_COLOR = "tab:blue"
ERROR_COLOR = {TRUTH: "tab:red", GIVEN: "tab:purple"}


@dataclass(frozen=True)
class Plot:
    """PNG bytes of one figure and the notes its caption must carry (clipped series)."""

    png: bytes
    notes: tuple[str, ...] = ()


@dataclass(frozen=True)
class Quantity:
    """What a family-panel figure draws.

    ``pick(series)`` → (error, 1σ or None) on ``series.t``, or None when the estimator has no
    such error; ``signed``: the axis is ±L (else [0, L], a norm); ``k_sigma``: the σ multiple
    drawn; ``sigma_label``: its legend text.
    """

    title: str
    ylabel: str
    unit: str
    spec: str
    signed: bool
    pick: Callable[[ErrorSeries], tuple[FloatArray, FloatArray | None] | None]
    k_sigma: float = 3.0
    sigma_label: str = "±3σ"


def band_overflow(sd: FloatArray, lim: float, k: float = 3.0) -> float:
    """Fraction of the finite samples whose k·σ extends beyond ±``lim``."""
    ok = np.isfinite(sd)
    return float(np.mean(k * sd[ok] > lim)) if ok.any() else 0.0


def sigma_inside(sd: FloatArray, lim: float, k: float = 3.0) -> FloatArray:
    """k·σ where it lies inside the axis (k·σ ≤ ``lim``), NaN elsewhere: the line stops at
    the axis instead of being drawn along its edge, where it would look like a bound."""
    out = k * np.asarray(sd, dtype=float)
    out[~(out <= lim)] = np.nan
    return out


def value_text(values: Mapping[str, Any], name: str, spec: str, unit: str) -> str:
    v = values.get(name)
    return "not scored" if v is None else f"{format(v, spec)} {unit}"


def reference_name(es: ErrorSet) -> str:
    return {TRUTH: "truth", GIVEN: "the GNSS the estimator was given"}.get(
        es.basis, "withheld GNSS (holdout run)")


def time_axis(es: ErrorSet) -> canvas.TimeAxis | canvas.WindowAxis:
    cls = canvas.WindowAxis if es.windows_only else canvas.TimeAxis
    return cls(es.windows, es.shaded)


def _g(v: float) -> str:
    return f"{v:.3g}" if abs(v) < 100 else f"{v:.0f}"


def _legend(fig: Any, es: ErrorSet, q: Quantity, height: float, sigma: bool) -> None:
    """One legend for the figure, under its title: never over the data."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    shade = canvas.SHADE_LIGHT if es.windows_only else canvas.SHADE
    handles = [Line2D([], [], color=ERROR_COLOR.get(es.basis, "tab:green"), lw=0.8,
                      label="estimate − reference")]
    if sigma:
        handles.append(Line2D([], [], color=SIGMA_COLOR, lw=0.7, ls=(0, (4, 2)),
                              label=f"{q.sigma_label} of the estimate (drawn where inside "
                                    "the axis)"))
    if es.windows:
        handles.append(Patch(color=shade, label=es.shaded))
    fig.legend(handles=handles, loc="upper center", ncol=3, fontsize=7.5, frameon=False,
               bbox_to_anchor=(0.5, 1 - 0.3 / height))


def plot_family_panels(es: ErrorSet, q: Quantity, values: Mapping[str, float | None],
                       title: str) -> Plot | None:
    """The figure of ``q``: a panel per estimator that has it, a row per family; panel titles
    give ``values`` (the table's RMSE; None prints "not scored"). None when no estimator has
    ``q``."""
    picked = {}
    for s in es.series:
        got = q.pick(s)
        if got is not None and np.isfinite(got[0]).any():
            picked[s.name] = (s, *got)
    if not picked:
        return None
    groups = group_names(picked)
    ncol = max(len(m) for _, m in groups)
    nrow = len(groups)
    xaxis = time_axis(es)
    height = 1.35 + 2.3 * nrow
    fig = canvas.figure(11.0, height, left=0.08, wspace=0.18,
                        bottom_in=0.75 if xaxis.broken else 0.55, top_in=1.0)
    fig.subplots_adjust(hspace=0.62)
    axes = fig.subplots(nrow, ncol, sharex=True, squeeze=False)
    notes: list[str] = []
    for row, (label, members) in enumerate(groups):
        lims = robust_limits({n: picked[n][1] for n in members})
        notes += lims.notes(q.unit)
        for col in range(ncol):
            ax = axes[row, col]
            if col >= len(members):
                ax.set_visible(False)
                continue
            name = members[col]
            s, err, sd = picked[name]
            x, e, sdx = xaxis.map(s.t, err, sd)
            xaxis.decorate(ax)
            sub: list[str] = []
            if name in lims.clipped:
                sub.append(f"clipped, max |err| {_g(lims.clipped[name])} {q.unit}")
            if sdx is not None:
                over = band_overflow(sdx, lims.lim, q.k_sigma)
                line = sigma_inside(sdx, lims.lim, q.k_sigma)
                ax.plot(x, line, color=SIGMA_COLOR, lw=0.7, ls=(0, (4, 2)), label=q.sigma_label)
                if q.signed:
                    ax.plot(x, -line, color=SIGMA_COLOR, lw=0.7, ls=(0, (4, 2)))
                if over > SIGMA_NOTE_ABOVE:
                    med = float(np.nanmedian(q.k_sigma * sdx))
                    sub.append(f"{q.sigma_label} off-axis {100 * over:.0f} % "
                               f"(median {_g(med)} {q.unit})")
                    notes.append(f"{name}: {q.sigma_label} beyond the axis {100 * over:.0f} % "
                                 f"of the time (median {q.sigma_label.lstrip('±+')} "
                                 f"{_g(med)} {q.unit})")
            ax.plot(x, e, color=ERROR_COLOR.get(es.basis, "tab:green"), lw=0.8,
                    label="estimate − reference")
            ax.axhline(0.0, color="k", lw=0.5)
            ax.set_ylim(-lims.lim if q.signed else 0.0, lims.lim)
            head = f"{name}: RMSE {value_text(values, name, q.spec, q.unit)}"
            ax.set_title("\n".join([head, *sub]), fontsize=8.5,
                         color="black" if not sub else "#700000")
            ax.tick_params(labelsize=7)
            if col == 0:
                ax.set_ylabel(f"{label}\n{q.ylabel}", fontsize=8)
            if row == nrow - 1 or col >= len(groups[row + 1][1]):
                ax.set_xlabel(xaxis.xlabel(short=True), fontsize=7)
                ax.xaxis.set_tick_params(labelbottom=True)
    _legend(fig, es, q, height, any(v[2] is not None for v in picked.values()))
    fig.suptitle(f"{q.title} vs {reference_name(es)} — {title} (y-scale shared per row)",
                 fontsize=10)
    if xaxis.broken:
        fig.text(0.5, 0.005, xaxis.xlabel(), ha="center", va="bottom", fontsize=7.5)
    return Plot(canvas.png(fig), tuple(notes))
