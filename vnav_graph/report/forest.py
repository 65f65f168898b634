"""The forest plot of filter against graph: one panel per metric, one row per scenario and
comparison (real time: forward ekf vs online graph-isam2; offline: ekf-rts vs graph-batch),
each a paired gain g = 1 − mean(graph)/mean(filter) over the seeds with its 95 % CI
(``evaluation.gains.gain_rows``). Positive: the graph lower.

A filled marker is a win the win rule counts (the CI of the paired difference excludes 0 and
the winner is not bought by overconfidence); a hollow one is not resolved or vetoed. A dashed
interval is a gain CI (delta method) that excludes 0 on a paired difference whose CI (the
rule's test) does not: the two disagree there, and the verdict follows the rule. The x
axis spans −100 % … +100 %; a gain or an interval end beyond −100 % is drawn at the edge with
an arrow and its value written beside it, so one large loss does not squeeze the others.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from . import canvas

XMIN = -100.0  # [%]: gains below are drawn at the edge with their value
COMPARISON_COLORS = {"real time": "#d62728", "offline": "#1f77b4"}


def _row_label(r: dict[str, Any]) -> str:
    return f"{r['scenario']} · {r['comparison']} ({r['a']} → {r['b']}, {r['n']} seeds)"


def forest_png(rows: Sequence[dict[str, Any]], title: str = "") -> bytes | None:
    """The figure as PNG bytes (1650 px wide), None when no row has a gain."""
    rows = [r for r in rows if r.get("gain") is not None]
    if not rows:
        return None
    metrics = list(dict.fromkeys(r["label"] for r in rows))
    labels = list(dict.fromkeys(_row_label(r) for r in rows))
    h = 1.4 + 0.32 * len(labels)
    fig = canvas.figure(11.0, h, left=0.35, wspace=0.12, right=0.985, bottom_in=0.8,
                        top_in=0.6 if title else 0.35)
    axes = fig.subplots(1, len(metrics), sharey=True, squeeze=False)[0]
    ypos = {lab: len(labels) - 1 - i for i, lab in enumerate(labels)}
    for ax, metric in zip(axes, metrics, strict=True):
        ax.axvline(0.0, color="0.4", lw=0.8)
        for r in (r for r in rows if r["label"] == metric):
            _one(ax, r, ypos[_row_label(r)])
        ax.set_xlim(XMIN - 8.0, 100.0)
        ax.set_xticks([-100, -50, 0, 50])
        ax.set_title(metric, fontsize=10)
        ax.set_xlabel("gain of the graph [%]")
        ax.grid(axis="x", color="0.9")
        ax.set_ylim(-0.7, len(labels) - 0.3)
    axes[0].set_yticks(list(ypos.values()), list(ypos.keys()), fontsize=8)
    from matplotlib.lines import Line2D

    handles = [Line2D([], [], marker="o", ls="", color=c, label=k)
               for k, c in COMPARISON_COLORS.items()]
    handles += [Line2D([], [], marker="o", ls="", color="0.3", label="win counted"),
                Line2D([], [], marker="o", ls="", mfc="white", color="0.3",
                       label="not resolved / vetoed"),
                Line2D([], [], ls="--", color="0.3",
                       label="gain CI excludes 0, difference CI does not")]
    fig.legend(handles=handles, loc="lower center", ncol=5, fontsize=8, frameon=False,
               bbox_to_anchor=(0.5, 0.0))
    if title:
        fig.suptitle(title, fontsize=10)
    return canvas.png(fig)


def _one(ax: Any, r: dict[str, Any], y: float) -> None:
    """One row's marker, interval and clipped ends."""
    color = COMPARISON_COLORS.get(r["comparison"], "0.3")
    g = 100.0 * r["gain"]
    ci = [100.0 * v for v in r["gain_ci95"]] if r.get("gain_ci95") else None
    if ci is not None:
        lo, hi = max(ci[0], XMIN), min(ci[1], 100.0)
        if hi > XMIN:
            ax.plot([lo, hi], [y, y], color=color, lw=1.6,
                    ls="--" if r.get("ci_disagree") else "-")
    gx = max(g, XMIN)
    ax.plot([gx], [y], marker="<" if g < XMIN else "o", ms=6, color=color,
            mfc=color if r.get("counts") else "white", ls="")
    if g < XMIN:
        text = f"gain {g:+.0f} %"
    elif ci is not None and ci[0] < XMIN:
        text = f"CI from {ci[0]:+.0f} %"
    else:
        return
    ax.annotate(text, (XMIN, y), xytext=(4, 4), textcoords="offset points", fontsize=7,
                color=color)
