"""Plots and the self-contained HTML report of one ``vnav-graph run``.

``write_report(out_dir, summary, results, drive)`` is called by ``pipeline.write_outputs``
(through ``cli.cmd_run``) with the temporary output directory; it writes

- ``plots/altitude_error.png`` — altitude error vs time per estimator, ±3σ, outages shaded;
- ``plots/vertical_velocity_error.png`` — vertical-velocity error of every estimator;
- ``plots/baro_parameters.png`` — final baro scale/latency/bias ± 1σ vs truth;
- ``plots/baro_convergence.png`` — baro parameter histories, when an estimator provides one;
- ``report.html`` — drive info, comparison table, baro table and the plots embedded (base64).

Matplotlib is imported only in ``vnav_graph.report.plots`` (Agg canvas, no pyplot).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from ..types import Drive

PLOTS = (
    ("altitude_error.png", "Altitude error vs time per estimator (±3σ band, GNSS outages shaded)",
     "plot_altitude_errors"),
    ("vertical_velocity_error.png", "Vertical velocity error vs time",
     "plot_vertical_velocity_errors"),
    ("baro_parameters.png", "Barometer parameters: final estimate ± 1σ vs truth",
     "plot_baro_parameters"),
    ("baro_convergence.png", "Barometer parameter convergence (±1σ)", "plot_baro_convergence"),
)


def write_report(out_dir: str | Path, summary: dict[str, Any], results: Sequence[Any],
                 drive: Drive) -> list[Path]:
    """Write the PNG plots under ``out_dir/plots`` and ``out_dir/report.html``.

    Parameters
    ----------
    out_dir : directory to write into (created if missing)
    summary : the ``summary.json`` document (``pipeline.summarize``)
    results : ``pipeline.RunResult`` list (estimate or error per estimator)
    drive : the drive the estimators ran on

    Returns the written paths. A plot that fails is skipped with its error noted in the HTML
    (a figure must never cost the user the rest of the report).
    """
    from .. import __version__
    from . import plots
    from .html import render_html

    out = Path(out_dir)
    (out / "plots").mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    images: list[tuple[str, bytes]] = []
    for fname, caption, fn in PLOTS:
        try:
            png = getattr(plots, fn)(drive, results)
        except Exception as exc:  # noted in the report instead of aborting it
            caption = f"{caption}: not drawn ({type(exc).__name__}: {exc})"
            images.append((caption, b""))
            continue
        if png is None:
            continue
        p = out / "plots" / fname
        p.write_bytes(png)
        written.append(p)
        images.append((caption, png))
    page = render_html(summary, drive, [i for i in images if i[1]], __version__)
    notes = [c for c, png in images if not png]
    if notes:
        page = page.replace("<h2>Plots</h2>", "<h2>Plots</h2>" + "".join(
            f'<p class="note">{_esc(n)}</p>' for n in notes))
    p = out / "report.html"
    p.write_text(page, encoding="utf-8")
    written.append(p)
    return written


def _esc(s: str) -> str:
    import html

    return html.escape(s)


__all__ = ["write_report"]
