"""Error plots, grouped by family with a shared, robust y-scale per family.

- ``plot_altitude_errors``: one panel per estimator, a row per family (smoothers, filters,
  loops/observers), ±3σ lines where a covariance exists (:mod:`vnav_graph.report.panels`);
- ``plot_horizontal_errors`` / ``plot_heading_errors``: the same layout for the horizontal
  error's norm (+3σ_h line) and the heading error (±3σ_yaw);
- ``plot_vertical_velocity_errors``: one panel per family, its members overlaid;
- ``plot_holdout_errors``: ``holdout.png`` of ``vnav-graph holdout``, one panel per family.

Every series comes from :mod:`vnav_graph.report.errors` (truth, or the withheld GNSS of the
holdout run), and every number printed on a plot is read from the summary (or holdout
document) the table shows, so plot and table cannot disagree. Outliers are clipped with a
note on the panel and in the returned ``Plot.notes`` (see :mod:`vnav_graph.report.groups`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from ..types.streams import FloatArray
from . import canvas
from .errors import ErrorSeries, ErrorSet, from_holdout
from .groups import group_names, robust_limits
from .palette import estimator_style
from .panels import (
    Plot,
    Quantity,
    plot_family_panels,
    reference_name,
    time_axis,
    value_text,
)


def _clip_text(ax: Any, names_max: Mapping[str, float], unit: str) -> None:
    if names_max:
        txt = "; ".join(f"{n} clipped: max |err| {v:.3g} {unit}" for n, v in names_max.items())
        ax.text(0.01, 0.97, txt, transform=ax.transAxes, fontsize=7, color="darkred",
                va="top", ha="left", bbox={"fc": "white", "ec": "darkred", "lw": 0.5,
                                           "alpha": 0.85, "pad": 1.5})


def _alt_pick(s: ErrorSeries) -> tuple[FloatArray, FloatArray | None]:
    return s.alt, s.alt_sd


ALTITUDE = Quantity("Altitude error", "alt error [m]", "m", ".2f", True, _alt_pick)


def _horiz_pick(s: ErrorSeries) -> tuple[FloatArray, FloatArray | None] | None:
    return None if s.horiz is None else (s.horiz, s.horiz_sd)


def _heading_pick(s: ErrorSeries) -> tuple[FloatArray, FloatArray | None] | None:
    return None if s.heading is None else (s.heading, s.heading_sd)


HORIZONTAL = Quantity("Horizontal position error |ΔNE|", "horiz error [m]", "m", ".2f", False,
                      _horiz_pick, sigma_label="+3σ_h")
HEADING = Quantity("Heading (yaw) error", "heading error [deg]", "deg", ".2f", True,
                   _heading_pick, sigma_label="±3σ_yaw")


def plot_horizontal_errors(es: ErrorSet, values: Mapping[str, float | None],
                           title: str) -> Plot | None:
    """Horizontal error panels by family (``pos_h`` estimators); ``values``: the table's
    ``horiz_rmse_m``. None when no estimator provides a horizontal position."""
    return plot_family_panels(es, HORIZONTAL, values, title)


def plot_heading_errors(es: ErrorSet, values: Mapping[str, float | None],
                        title: str) -> Plot | None:
    """Heading error panels by family (``att`` estimators, against truth); ``values``: the
    table's ``heading_rmse_deg``. None without a heading error (no truth, or no attitude)."""
    return plot_family_panels(es, HEADING, values, title)


def plot_altitude_errors(es: ErrorSet, values: Mapping[str, float | None],
                         title: str) -> Plot | None:
    """Altitude error panels by family. ``values``: the RMSE per estimator printed in each
    panel title (the table's ``alt_rmse_m``; None prints "not scored")."""
    return plot_family_panels(es, ALTITUDE, values, title)


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
    xaxis = time_axis(es)
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
                                    **estimator_style(n),
                                    label=f"{n} ({value_text(values, n, spec, unit)})")
        ax.axhline(0.0, color="k", lw=0.5)
        ax.set_ylim(-lims.lim, lims.lim)
        _clip_text(ax, lims.clipped, unit)
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
                    f"Vertical velocity error vs {reference_name(es)} — {title} (legend: RMSE)")


def plot_holdout_errors(holdout: Any) -> Plot | None:
    """``holdout.png``: altitude error at the withheld fixes by family, legend = the
    ``alt_rmse_m`` of ``holdout.json``."""
    doc = holdout.doc
    values = {n: b.get("alt_rmse_m") for n, b in doc["estimators"].items()}
    return _overlay(from_holdout(holdout), _alt, values, ".2f", "m",
                    "estimate + offset − GNSS [m]",
                    f"GNSS-outage holdout: {doc['drive']['name']} — altitude error at the "
                    "withheld fixes (grey: GNSS withheld)")
