"""Error plots, grouped by family with a shared, robust y-scale per family.

- ``plot_altitude_errors``: one panel per estimator, a row per family (smoothers, filters,
  loops/observers), ±3σ band where a covariance exists;
- ``plot_vertical_velocity_errors``: one panel per family, its members overlaid;
- ``plot_holdout_errors``: ``holdout.png`` of ``vnav-graph holdout``, one panel per family.

Every series comes from :mod:`vnav_graph.report.errors` (truth, or the withheld GNSS of the
holdout run), and every number printed on a plot is read from the summary (or holdout
document) the table shows, so plot and table cannot disagree. Outliers are clipped with a
note on the panel and in the returned ``Plot.notes`` (see :mod:`vnav_graph.report.groups`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..types import FloatArray
from . import canvas
from .errors import GIVEN, TRUTH, ErrorSeries, ErrorSet, from_holdout
from .groups import group_names, robust_limits
from .palette import estimator_color

_COLOR = {TRUTH: "tab:red", GIVEN: "tab:purple"}


@dataclass(frozen=True)
class Plot:
    """PNG bytes of one figure and the notes its caption must carry (clipped series)."""

    png: bytes
    notes: tuple[str, ...] = ()


def _axis(es: ErrorSet) -> canvas.TimeAxis | canvas.WindowAxis:
    cls = canvas.WindowAxis if es.windows_only else canvas.TimeAxis
    return cls(es.windows, es.shaded)


def _value(values: Mapping[str, Any], name: str, spec: str, unit: str) -> str:
    v = values.get(name)
    return "not scored" if v is None else f"{format(v, spec)} {unit}"


# the ±3σ band is drawn pale when it fills the panel more than this fraction of the time, and
# noted (in the panel and under the figure) above BAND_NOTE_ABOVE
BAND_PALE_ABOVE = 0.5
BAND_NOTE_ABOVE = 0.05


def band_overflow(sd: FloatArray, lim: float) -> float:
    """Fraction of the finite samples whose ±3σ extends beyond ±``lim``."""
    ok = np.isfinite(sd)
    return float(np.mean(3.0 * sd[ok] > lim)) if ok.any() else 0.0


def _clip_text(ax: Any, names_max: Mapping[str, float], unit: str, prefix: bool) -> None:
    if names_max:
        txt = "; ".join(f"{n + ' ' if prefix else ''}clipped: max |err| {v:.3g} {unit}"
                        for n, v in names_max.items())
        ax.text(0.01, 0.97, txt, transform=ax.transAxes, fontsize=7, color="darkred",
                va="top", ha="left", bbox={"fc": "white", "ec": "darkred", "lw": 0.5,
                                           "alpha": 0.85, "pad": 1.5})


def _ref(es: ErrorSet) -> str:
    return {TRUTH: "truth", GIVEN: "the GNSS the estimator was given"}.get(
        es.basis, "withheld GNSS (holdout run)")


def plot_altitude_errors(es: ErrorSet, values: Mapping[str, float | None],
                         title: str) -> Plot | None:
    """Altitude error panels by family. ``values``: the RMSE per estimator printed in each
    panel title (the table's ``alt_rmse_m``; None prints "not scored")."""
    if not es.series:
        return None
    by_name = {s.name: s for s in es.series}
    groups = group_names(by_name)
    ncol = max(len(m) for _, m in groups)
    nrow = len(groups)
    xaxis = _axis(es)
    height = 1.35 + 2.0 * nrow
    fig = canvas.figure(11.0, height, left=0.09, wspace=0.18,
                        bottom_in=0.75 if xaxis.broken else 0.55, top_in=1.0)
    axes = fig.subplots(nrow, ncol, sharex=True, squeeze=False)
    notes: list[str] = []
    first = True
    for row, (label, members) in enumerate(groups):
        lims = robust_limits({n: by_name[n].alt for n in members})
        notes += lims.notes("m")
        for col in range(ncol):
            ax = axes[row, col]
            if col >= len(members):
                ax.set_visible(False)
                continue
            s = by_name[members[col]]
            x, e, sd = xaxis.map(s.t, s.alt, s.alt_sd)
            xaxis.decorate(ax, legend=first)
            if sd is not None:
                over = band_overflow(sd, lims.lim)
                # clipped to the axis, and pale where it fills the panel, so that it never
                # hides the shaded windows or the error line
                band = np.minimum(3.0 * sd, lims.lim)
                ax.fill_between(x, -band, band, color="tab:blue", lw=0, label="±3σ",
                                alpha=0.18 if over < BAND_PALE_ABOVE else 0.07, zorder=0.5)
                if over > BAND_NOTE_ABOVE:
                    note = (f"±3σ beyond the axis {100 * over:.0f} % of the time (median "
                            f"3σ {np.nanmedian(3.0 * sd):.3g} m)")
                    notes.append(f"{s.name}: {note}")
                    ax.text(0.99, 0.03, note, transform=ax.transAxes, fontsize=6.5,
                            color="tab:blue", va="bottom", ha="right",
                            bbox={"fc": "white", "ec": "none", "alpha": 0.8, "pad": 1.0})
            ax.plot(x, e, color=_COLOR.get(es.basis, "tab:green"), lw=0.8,
                    label="estimate − reference")
            ax.axhline(0.0, color="k", lw=0.5)
            ax.set_ylim(-lims.lim, lims.lim)
            ax.set_title(f"{s.name}: RMSE {_value(values, s.name, '.2f', 'm')}", fontsize=9)
            _clip_text(ax, {s.name: lims.clipped[s.name]} if s.name in lims.clipped else {},
                       "m", prefix=False)
            ax.tick_params(labelsize=7)
            if col == 0:
                ax.set_ylabel(f"{label}\nalt error [m]", fontsize=8)
            if first:  # one legend for the figure, under the title: never over the data
                fig.legend(*ax.get_legend_handles_labels(), loc="upper center", ncol=4,
                           fontsize=7.5, frameon=False, bbox_to_anchor=(0.5, 1 - 0.3 / height))
                first = False
            if row == nrow - 1 or col >= len(groups[row + 1][1]):
                ax.set_xlabel(xaxis.xlabel(short=True), fontsize=7)
                ax.xaxis.set_tick_params(labelbottom=True)
    fig.suptitle(f"Altitude error vs {_ref(es)} — {title} (y-scale shared per row)",
                 fontsize=10)
    if xaxis.broken:
        fig.text(0.5, 0.005, xaxis.xlabel(), ha="center", va="bottom", fontsize=7.5)
    return Plot(canvas.png(fig), tuple(notes))


def _overlay(es: ErrorSet, pick: Any, values: Mapping[str, float | None], spec: str,
             unit: str, ylabel: str, title: str) -> Plot | None:
    """One panel per family with its members overlaid; ``pick(series)`` → error or None."""
    chosen = [s for s in es.series if pick(s) is not None and np.isfinite(pick(s)).any()]
    if not chosen:
        return None
    by_name = {s.name: s for s in chosen}
    groups = group_names(by_name)
    fig = canvas.figure(11.0, 0.95 + 2.1 * len(groups), left=0.08, right=0.79)
    axes = fig.subplots(len(groups), 1, sharex=True, squeeze=False).ravel()
    xaxis = _axis(es)
    notes: list[str] = []
    for k, (ax, (label, members)) in enumerate(zip(axes, groups, strict=True)):
        lims = robust_limits({n: pick(by_name[n]) for n in members})
        notes += lims.notes(unit)
        xaxis.decorate(ax, legend=k == 0)
        handles: dict[int, Any] = {}
        for i, n in sorted(enumerate(members), key=lambda c: c[1] not in lims.clipped):
            # clipped members first and faint, so the readable ones are drawn over them
            x, e = xaxis.map(by_name[n].t, pick(by_name[n]))
            clip = n in lims.clipped
            (handles[i],) = ax.plot(x, e, lw=0.6 if clip else 0.85, alpha=0.5 if clip else 1.0,
                                    color=estimator_color(n),
                                    label=f"{n} ({_value(values, n, spec, unit)})")
        ax.axhline(0.0, color="k", lw=0.5)
        ax.set_ylim(-lims.lim, lims.lim)
        _clip_text(ax, lims.clipped, unit, prefix=True)
        ax.set_ylabel(f"{label}\n{ylabel}", fontsize=8)
        ax.tick_params(labelsize=8)
        ax.legend(handles=[handles[i] for i in sorted(handles)], fontsize=7,
                  loc="center left", bbox_to_anchor=(1.01, 0.5), title="RMSE", title_fontsize=7)
    axes[-1].set_xlabel(xaxis.xlabel(), fontsize=8)
    fig.suptitle(title, fontsize=10)
    return Plot(canvas.png(fig), tuple(notes))


def _vd(s: ErrorSeries) -> Any:
    return s.vd


def _alt(s: ErrorSeries) -> Any:
    return s.alt


def plot_vertical_velocity_errors(es: ErrorSet, values: Mapping[str, float | None],
                                  title: str) -> Plot | None:
    """v_D error by family (overlaid); ``values``: the table's ``vel_down_rmse_mps``."""
    return _overlay(es, _vd, values, ".3f", "m/s", "v_D error [m/s]",
                    f"Vertical velocity error vs {_ref(es)} — {title} (legend: RMSE)")


def plot_holdout_errors(holdout: Any) -> Plot | None:
    """``holdout.png``: altitude error at the withheld fixes by family, legend = the
    ``alt_rmse_m`` of ``holdout.json``."""
    doc = holdout.doc
    values = {n: b.get("alt_rmse_m") for n, b in doc["estimators"].items()}
    return _overlay(from_holdout(holdout), _alt, values, ".2f", "m",
                    "estimate + offset − GNSS [m]",
                    f"GNSS-outage holdout: {doc['drive']['name']} — altitude error at the "
                    "withheld fixes (grey: GNSS withheld)")
